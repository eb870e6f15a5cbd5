//! Link-layer, IPv4 and UDP slicing of captured frames.
//!
//! In: one captured frame and its link type. Out: offsets and header fields of the IPv4 packet and
//! the UDP datagram inside it. Pure functions over byte slices: no I/O, no allocation, no panics
//! (every access is bounds-checked through `get`).
//!
//! Only what ringscan needs is understood: Ethernet II with any number (up to
//! [`MAX_VLAN_TAGS`]) of 802.1Q / 802.1ad tags, Linux cooked captures v1 and v2, raw IP, and BSD
//! loopback. Everything that is not IPv4 (ARP, IPv6, LLC, …) is reported as
//! [`Link::NotIpv4`]. IPv4 and UDP checksums are deliberately not verified: captures made on the
//! sending host carry checksums offloaded to the NIC (garbage in the capture), and LiDAR payloads
//! are checked by the decoders where the sensor provides a check.
//!
//! This belongs to the `wire` layer by the module map (DESIGN.md); it lives here until
//! `wire/net.rs` is declared by that module's owner.

use std::net::Ipv4Addr;

/// `LINKTYPE_NULL`: BSD loopback, 4-byte address family in the capturing host's byte order.
pub const LINKTYPE_NULL: u32 = 0;
/// `LINKTYPE_ETHERNET`: Ethernet II / IEEE 802.3.
pub const LINKTYPE_ETHERNET: u32 = 1;
/// `LINKTYPE_RAW`: raw IP, version given by the first nibble (4 or 6).
pub const LINKTYPE_RAW: u32 = 101;
/// `LINKTYPE_LOOP`: OpenBSD loopback, 4-byte address family, big-endian.
pub const LINKTYPE_LOOP: u32 = 108;
/// `LINKTYPE_LINUX_SLL`: Linux cooked capture v1 (16-byte header).
pub const LINKTYPE_LINUX_SLL: u32 = 113;
/// `LINKTYPE_IPV4`: raw IPv4.
pub const LINKTYPE_IPV4: u32 = 228;
/// `LINKTYPE_LINUX_SLL2`: Linux cooked capture v2 (20-byte header).
pub const LINKTYPE_LINUX_SLL2: u32 = 276;

/// EtherType of IPv4.
pub const ETHERTYPE_IPV4: u16 = 0x0800;
/// EtherType (TPID) of an IEEE 802.1Q VLAN tag.
pub const ETHERTYPE_VLAN: u16 = 0x8100;
/// EtherType (TPID) of an IEEE 802.1ad service tag (QinQ outer tag).
pub const ETHERTYPE_QINQ: u16 = 0x88a8;
/// Pre-standard QinQ TPID still emitted by some switches.
pub const ETHERTYPE_QINQ_OLD: u16 = 0x9100;
/// VLAN tags followed at most; more is treated as malformed (a loop guard, not a real limit).
pub const MAX_VLAN_TAGS: usize = 8;

/// IP protocol number of UDP.
pub const IPPROTO_UDP: u8 = 17;
/// Length of an IPv4 header without options.
pub const IPV4_MIN_HEADER_LEN: usize = 20;
/// Length of a UDP header.
pub const UDP_HEADER_LEN: usize = 8;

const ETHERNET_HEADER_LEN: usize = 14;
const VLAN_TAG_LEN: usize = 4;
const SLL_HEADER_LEN: usize = 16;
const SLL2_HEADER_LEN: usize = 20;
const NULL_HEADER_LEN: usize = 4;
/// Address family of IPv4 in a BSD loopback header (`AF_INET` is 2 on every system).
const AF_INET: u32 = 2;

/// Whether [`ipv4_in_frame`] understands this link type.
pub fn is_supported_linktype(linktype: u32) -> bool {
    matches!(
        linktype,
        LINKTYPE_NULL
            | LINKTYPE_ETHERNET
            | LINKTYPE_RAW
            | LINKTYPE_LOOP
            | LINKTYPE_LINUX_SLL
            | LINKTYPE_IPV4
            | LINKTYPE_LINUX_SLL2
    )
}

/// What a frame carries, as far as the link layer tells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    /// An IPv4 packet starts at this byte offset of the frame.
    Ipv4 {
        /// Offset of the IPv4 header within the frame.
        offset: usize,
    },
    /// Something else: ARP, IPv6, LLC, an unsupported link type, …
    NotIpv4,
    /// The frame is shorter than its link-layer header (or has too many VLAN tags).
    Short {
        /// Bytes the link layer needed.
        needed: usize,
        /// Bytes the frame has.
        available: usize,
    },
}

fn be16(bytes: &[u8], at: usize) -> Option<u16> {
    match bytes.get(at..at.checked_add(2)?)? {
        &[a, b] => Some(u16::from_be_bytes([a, b])),
        _ => None,
    }
}

fn be32(bytes: &[u8], at: usize) -> Option<u32> {
    match bytes.get(at..at.checked_add(4)?)? {
        &[a, b, c, d] => Some(u32::from_be_bytes([a, b, c, d])),
        _ => None,
    }
}

fn short(needed: usize, frame: &[u8]) -> Link {
    Link::Short {
        needed,
        available: frame.len(),
    }
}

/// Follows an EtherType (after optional VLAN tags) whose 2 bytes sit at `at` in `frame`.
fn after_ethertype(frame: &[u8], mut at: usize) -> Link {
    for _ in 0..=MAX_VLAN_TAGS {
        let Some(ethertype) = be16(frame, at) else {
            return short(at + 2, frame);
        };
        match ethertype {
            ETHERTYPE_IPV4 => {
                return if frame.len() > at + 2 {
                    Link::Ipv4 { offset: at + 2 }
                } else {
                    short(at + 2 + IPV4_MIN_HEADER_LEN, frame)
                };
            }
            // A tag: 2 bytes TCI, then the inner EtherType.
            ETHERTYPE_VLAN | ETHERTYPE_QINQ | ETHERTYPE_QINQ_OLD => at += VLAN_TAG_LEN,
            _ => return Link::NotIpv4,
        }
    }
    short(at + 2, frame)
}

/// Finds the IPv4 packet in a captured frame of the given link type.
///
/// Link-layer padding and trailers (Ethernet minimum-size padding, FCS) stay in the returned
/// tail; [`Ipv4Header::parse`] cuts them off by the IPv4 total length.
pub fn ipv4_in_frame(linktype: u32, frame: &[u8]) -> Link {
    match linktype {
        // dst MAC, src MAC, EtherType.
        LINKTYPE_ETHERNET => {
            if frame.len() < ETHERNET_HEADER_LEN {
                return short(ETHERNET_HEADER_LEN, frame);
            }
            after_ethertype(frame, 12)
        }
        // packet type, ARPHRD, address length, 8 address bytes, protocol (an EtherType).
        LINKTYPE_LINUX_SLL => {
            if frame.len() < SLL_HEADER_LEN {
                return short(SLL_HEADER_LEN, frame);
            }
            after_ethertype(frame, 14)
        }
        // protocol (an EtherType), reserved, interface index, ARPHRD, packet type, address
        // length, 8 address bytes.
        LINKTYPE_LINUX_SLL2 => {
            if frame.len() < SLL2_HEADER_LEN {
                return short(SLL2_HEADER_LEN, frame);
            }
            match be16(frame, 0) {
                Some(ETHERTYPE_IPV4) => Link::Ipv4 {
                    offset: SLL2_HEADER_LEN,
                },
                Some(ETHERTYPE_VLAN | ETHERTYPE_QINQ | ETHERTYPE_QINQ_OLD) => {
                    // The tag follows the header: TCI, then the inner EtherType.
                    after_ethertype(frame, SLL2_HEADER_LEN + 2)
                }
                _ => Link::NotIpv4,
            }
        }
        LINKTYPE_RAW | LINKTYPE_IPV4 => match frame.first() {
            Some(b) if b >> 4 == 4 => Link::Ipv4 { offset: 0 },
            // LINKTYPE_IPV4 promises IPv4: another version nibble is a bad packet, which the
            // IPv4 parser reports as such.
            Some(_) if linktype == LINKTYPE_IPV4 => Link::Ipv4 { offset: 0 },
            Some(_) => Link::NotIpv4,
            None => short(IPV4_MIN_HEADER_LEN, frame),
        },
        LINKTYPE_NULL | LINKTYPE_LOOP => {
            let Some(family) = be32(frame, 0) else {
                return short(NULL_HEADER_LEN, frame);
            };
            // NULL stores the family in the capturing host's byte order: accept both.
            let inet =
                family == AF_INET || (linktype == LINKTYPE_NULL && family == AF_INET.swap_bytes());
            if inet {
                Link::Ipv4 {
                    offset: NULL_HEADER_LEN,
                }
            } else {
                Link::NotIpv4
            }
        }
        _ => Link::NotIpv4,
    }
}

/// Why bytes are not a usable IPv4 packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum IpError {
    /// Fewer bytes than a header needs (20, or the header length the IHL field gives).
    #[error("IPv4: expected a header of {needed} bytes, found {available}")]
    TooShort {
        /// Bytes the header needs.
        needed: usize,
        /// Bytes present.
        available: usize,
    },
    /// The version nibble is not 4.
    #[error("IPv4: expected version 4, found {found}")]
    Version {
        /// Version found.
        found: u8,
    },
    /// The IHL field is below 5 words.
    #[error("IPv4: expected a header length of at least 5 words, found {ihl}")]
    HeaderLength {
        /// IHL found (32-bit words).
        ihl: u8,
    },
    /// The total-length field is smaller than the header.
    #[error("IPv4: total length {total} is smaller than the header length {header}")]
    TotalLength {
        /// Total length field.
        total: usize,
        /// Header length.
        header: usize,
    },
    /// The total-length field claims more bytes than are present.
    #[error("IPv4: total length {total} exceeds the {available} bytes present")]
    Truncated {
        /// Total length field.
        total: usize,
        /// Bytes present.
        available: usize,
    },
}

impl IpError {
    /// Whether the bytes simply stop early (a truncated capture), rather than contradict themselves.
    pub fn is_short(&self) -> bool {
        matches!(self, Self::TooShort { .. } | Self::Truncated { .. })
    }
}

/// The fields ringscan uses from an IPv4 header, checked against the bytes present.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ipv4Header {
    /// Source address.
    pub src: Ipv4Addr,
    /// Destination address.
    pub dst: Ipv4Addr,
    /// Protocol number (17 = UDP).
    pub protocol: u8,
    /// Identification field (the reassembly key together with addresses and protocol).
    pub id: u16,
    /// More-fragments flag.
    pub more_fragments: bool,
    /// Fragment offset in bytes (the field × 8).
    pub fragment_offset: usize,
    /// Header length in bytes (IHL × 4), options included.
    pub header_len: usize,
    /// Total length in bytes (header + payload); bytes beyond it are link padding.
    pub total_len: usize,
}

impl Ipv4Header {
    /// Parses and checks an IPv4 header: version 4, IHL ≥ 5, header and total length within
    /// `bytes`, total length ≥ header length. Checksum not verified.
    pub fn parse(bytes: &[u8]) -> Result<Self, IpError> {
        Self::parse_with(bytes, false)
    }

    /// As [`parse`](Self::parse), but a total length beyond the bytes present is cut to them
    /// instead of being an error ([`total_len`](Self::total_len) is then `bytes.len()`).
    ///
    /// For complete frames whose header lies: early VLP-16 firmware (2014) writes a total
    /// length of 1234 in its 554-byte position packets, whose UDP length is right
    /// (`Kitware__VeloView/Testing/Data/vlp-16-test-90deg-1-50-frames.pcap`). The caller decides
    /// when that is acceptable (ringscan: untruncated records that are not fragments, with the
    /// UDP length inside the bytes present).
    pub fn parse_overrun(bytes: &[u8]) -> Result<Self, IpError> {
        Self::parse_with(bytes, true)
    }

    fn parse_with(bytes: &[u8], clamp_total: bool) -> Result<Self, IpError> {
        let too_short = |needed| IpError::TooShort {
            needed,
            available: bytes.len(),
        };
        let Some(&[ver_ihl, _tos, l0, l1, i0, i1, f0, f1, _ttl, protocol]) = bytes.get(..10) else {
            return Err(too_short(IPV4_MIN_HEADER_LEN));
        };
        let version = ver_ihl >> 4;
        if version != 4 {
            return Err(IpError::Version { found: version });
        }
        let ihl = ver_ihl & 0x0f;
        if ihl < 5 {
            return Err(IpError::HeaderLength { ihl });
        }
        let header_len = usize::from(ihl) * 4;
        let (Some(src), Some(dst)) = (be32(bytes, 12), be32(bytes, 16)) else {
            return Err(too_short(IPV4_MIN_HEADER_LEN));
        };
        if bytes.len() < header_len {
            return Err(too_short(header_len));
        }
        let total_len = usize::from(u16::from_be_bytes([l0, l1]));
        if total_len < header_len {
            return Err(IpError::TotalLength {
                total: total_len,
                header: header_len,
            });
        }
        let total_len = match total_len > bytes.len() {
            true if clamp_total => bytes.len(),
            true => {
                return Err(IpError::Truncated {
                    total: total_len,
                    available: bytes.len(),
                })
            }
            false => total_len,
        };
        let flags_offset = u16::from_be_bytes([f0, f1]);
        Ok(Self {
            src: Ipv4Addr::from(src),
            dst: Ipv4Addr::from(dst),
            protocol,
            id: u16::from_be_bytes([i0, i1]),
            more_fragments: flags_offset & 0x2000 != 0,
            fragment_offset: usize::from(flags_offset & 0x1fff) * 8,
            header_len,
            total_len,
        })
    }

    /// Whether this packet is one fragment of a larger datagram.
    pub fn is_fragment(&self) -> bool {
        self.more_fragments || self.fragment_offset != 0
    }

    /// The payload (bytes after the header, up to the total length) of the `bytes` this header
    /// was parsed from.
    pub fn payload<'a>(&self, bytes: &'a [u8]) -> &'a [u8] {
        bytes.get(self.header_len..self.total_len).unwrap_or(&[])
    }
}

/// Why bytes are not a usable UDP datagram.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum UdpError {
    /// Fewer than 8 bytes.
    #[error("UDP: expected an 8-byte header, found {available} bytes")]
    TooShort {
        /// Bytes present.
        available: usize,
    },
    /// The length field is below 8.
    #[error("UDP: length field {length} is smaller than the 8-byte header")]
    Length {
        /// Length field.
        length: usize,
    },
    /// The length field claims more bytes than are present.
    #[error("UDP: length field {length} exceeds the {available} bytes present")]
    Truncated {
        /// Length field.
        length: usize,
        /// Bytes present.
        available: usize,
    },
}

impl UdpError {
    /// Whether the bytes simply stop early (a truncated capture), rather than contradict themselves.
    pub fn is_short(&self) -> bool {
        matches!(self, Self::TooShort { .. } | Self::Truncated { .. })
    }
}

/// A UDP header checked against the bytes present.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UdpHeader {
    /// Source port.
    pub src_port: u16,
    /// Destination port.
    pub dst_port: u16,
    /// Length field: header + payload, ≤ the bytes present.
    pub len: usize,
}

impl UdpHeader {
    /// Parses a UDP header and checks its length field against `bytes` (the IP payload). The
    /// datagram ends where the length field says, even if the IP payload is longer.
    pub fn parse(bytes: &[u8]) -> Result<Self, UdpError> {
        let Some(&[s0, s1, d0, d1, l0, l1, _c0, _c1]) = bytes.get(..UDP_HEADER_LEN) else {
            return Err(UdpError::TooShort {
                available: bytes.len(),
            });
        };
        let len = usize::from(u16::from_be_bytes([l0, l1]));
        if len < UDP_HEADER_LEN {
            return Err(UdpError::Length { length: len });
        }
        if len > bytes.len() {
            return Err(UdpError::Truncated {
                length: len,
                available: bytes.len(),
            });
        }
        Ok(Self {
            src_port: u16::from_be_bytes([s0, s1]),
            dst_port: u16::from_be_bytes([d0, d1]),
            len,
        })
    }

    /// Byte range of the payload within the bytes this header was parsed from.
    pub fn payload_range(&self) -> std::ops::Range<usize> {
        UDP_HEADER_LEN..self.len
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ipv4_udp(payload: &[u8]) -> Vec<u8> {
        let total = 20 + 8 + payload.len();
        let mut p = vec![
            0x45,
            0,
            (total >> 8) as u8,
            total as u8,
            0x12,
            0x34,
            0,
            0,
            64,
            17,
            0,
            0,
        ];
        p.extend_from_slice(&[10, 0, 0, 1, 10, 0, 0, 2]);
        let ulen = 8 + payload.len();
        p.extend_from_slice(&[0x09, 0x40, 0x1d, 0x4c, (ulen >> 8) as u8, ulen as u8, 0, 0]);
        p.extend_from_slice(payload);
        p
    }

    #[test]
    fn ethernet_with_padding_is_cut_by_total_length() {
        let ip = ipv4_udp(b"hi");
        let mut frame = vec![0xff; 12];
        frame.extend_from_slice(&[0x08, 0x00]);
        frame.extend_from_slice(&ip);
        frame.resize(60, 0xAA); // minimum Ethernet frame: padding after the IP packet
        let Link::Ipv4 { offset } = ipv4_in_frame(LINKTYPE_ETHERNET, &frame) else {
            panic!("not IPv4")
        };
        assert_eq!(offset, 14);
        let ip_bytes = &frame[offset..];
        let h = Ipv4Header::parse(ip_bytes).unwrap();
        assert_eq!(h.total_len, 30);
        assert_eq!(
            (h.src, h.dst),
            (Ipv4Addr::new(10, 0, 0, 1), Ipv4Addr::new(10, 0, 0, 2))
        );
        assert!(!h.is_fragment());
        let payload = h.payload(ip_bytes);
        let u = UdpHeader::parse(payload).unwrap();
        assert_eq!((u.src_port, u.dst_port), (2368, 7500));
        assert_eq!(&payload[u.payload_range()], b"hi");
    }

    #[test]
    fn vlan_and_qinq_tags_are_followed() {
        let ip = ipv4_udp(b"x");
        let mut frame = vec![0; 12];
        frame.extend_from_slice(&[0x88, 0xa8, 0x00, 0x64, 0x81, 0x00, 0x00, 0x0a, 0x08, 0x00]);
        frame.extend_from_slice(&ip);
        assert_eq!(
            ipv4_in_frame(LINKTYPE_ETHERNET, &frame),
            Link::Ipv4 { offset: 22 }
        );
    }

    #[test]
    fn endless_vlan_tags_do_not_loop() {
        let mut frame = vec![0; 12];
        for _ in 0..100 {
            frame.extend_from_slice(&[0x81, 0x00, 0x00, 0x01]);
        }
        assert!(matches!(
            ipv4_in_frame(LINKTYPE_ETHERNET, &frame),
            Link::Short { .. }
        ));
    }

    #[test]
    fn other_ethertypes_are_not_ipv4() {
        let mut frame = vec![0; 12];
        frame.extend_from_slice(&[0x86, 0xdd]); // IPv6
        frame.extend_from_slice(&[0x60; 40]);
        assert_eq!(ipv4_in_frame(LINKTYPE_ETHERNET, &frame), Link::NotIpv4);
        frame[12..14].copy_from_slice(&[0x08, 0x06]); // ARP
        assert_eq!(ipv4_in_frame(LINKTYPE_ETHERNET, &frame), Link::NotIpv4);
    }

    #[test]
    fn raw_linktype_uses_the_version_nibble() {
        assert_eq!(
            ipv4_in_frame(LINKTYPE_RAW, &[0x45, 0]),
            Link::Ipv4 { offset: 0 }
        );
        assert_eq!(ipv4_in_frame(LINKTYPE_RAW, &[0x60, 0]), Link::NotIpv4);
        assert_eq!(
            ipv4_in_frame(LINKTYPE_IPV4, &[0x60, 0]),
            Link::Ipv4 { offset: 0 }
        );
        assert!(matches!(
            ipv4_in_frame(LINKTYPE_RAW, &[]),
            Link::Short { .. }
        ));
    }

    #[test]
    fn null_loopback_in_both_byte_orders() {
        assert_eq!(
            ipv4_in_frame(LINKTYPE_NULL, &[2, 0, 0, 0, 0x45]),
            Link::Ipv4 { offset: 4 }
        );
        assert_eq!(
            ipv4_in_frame(LINKTYPE_NULL, &[0, 0, 0, 2, 0x45]),
            Link::Ipv4 { offset: 4 }
        );
        assert_eq!(
            ipv4_in_frame(LINKTYPE_NULL, &[30, 0, 0, 0, 0x60]),
            Link::NotIpv4
        );
        assert_eq!(
            ipv4_in_frame(LINKTYPE_LOOP, &[2, 0, 0, 0, 0x45]),
            Link::NotIpv4
        );
    }

    #[test]
    fn ipv4_header_checks() {
        let ip = ipv4_udp(b"abcd");
        assert_eq!(
            Ipv4Header::parse(&ip[..10]),
            Err(IpError::TooShort {
                needed: 20,
                available: 10
            })
        );
        let mut bad = ip.clone();
        bad[0] = 0x65;
        assert_eq!(Ipv4Header::parse(&bad), Err(IpError::Version { found: 6 }));
        bad[0] = 0x44;
        assert_eq!(
            Ipv4Header::parse(&bad),
            Err(IpError::HeaderLength { ihl: 4 })
        );
        bad[0] = 0x4f; // 60-byte header, only 32 bytes present
        assert_eq!(
            Ipv4Header::parse(&bad),
            Err(IpError::TooShort {
                needed: 60,
                available: 32
            })
        );
        let mut bad = ip.clone();
        bad[3] = 19;
        assert_eq!(
            Ipv4Header::parse(&bad),
            Err(IpError::TotalLength {
                total: 19,
                header: 20
            })
        );
        assert_eq!(
            Ipv4Header::parse(&ip[..31]),
            Err(IpError::Truncated {
                total: 32,
                available: 31
            })
        );
        let mut frag = ip.clone();
        frag[6] = 0x20; // MF
        frag[7] = 3; // offset 3 × 8
        let h = Ipv4Header::parse(&frag).unwrap();
        assert!(h.more_fragments && h.is_fragment());
        assert_eq!(h.fragment_offset, 24);
    }

    #[test]
    fn overrunning_total_length_is_cut_on_request() {
        let ip = ipv4_udp(b"abcd");
        let mut lying = ip.clone();
        lying[2..4].copy_from_slice(&1234_u16.to_be_bytes());
        assert_eq!(
            Ipv4Header::parse(&lying),
            Err(IpError::Truncated {
                total: 1234,
                available: 32
            })
        );
        let h = Ipv4Header::parse_overrun(&lying).unwrap();
        assert_eq!(h.total_len, 32);
        assert_eq!(h.payload(&lying), &ip[20..]);
        assert_eq!(
            Ipv4Header::parse_overrun(&ip[..10]),
            Ipv4Header::parse(&ip[..10])
        );
    }

    #[test]
    fn udp_length_checks() {
        assert_eq!(
            UdpHeader::parse(&[0; 7]),
            Err(UdpError::TooShort { available: 7 })
        );
        assert_eq!(
            UdpHeader::parse(&[0, 1, 0, 2, 0, 4, 0, 0]),
            Err(UdpError::Length { length: 4 })
        );
        assert_eq!(
            UdpHeader::parse(&[0, 1, 0, 2, 0, 9, 0, 0]),
            Err(UdpError::Truncated {
                length: 9,
                available: 8
            })
        );
        // Shorter than the IP payload: the UDP length wins.
        let u = UdpHeader::parse(&[0, 1, 0, 2, 0, 9, 0, 0, 7, 8, 9]).unwrap();
        assert_eq!(u.payload_range(), 8..9);
    }
}
