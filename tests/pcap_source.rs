//! `source::pcap`: pcap / pcapng captures built in memory (every container variant and link type,
//! fragments, hostile files), an independent writer (`pcap-file`) as a cross-check, and the real
//! captures of `../shared/captures` with the counts their INVENTORY.md gives.
#![cfg(feature = "pcap")]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::collections::BTreeMap;
use std::io::Cursor;
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::{Path, PathBuf};

use ringscan::source::pcap::{
    FileFormat, PcapSource, SourceError, SourceStats, DEFAULT_RECORD_LIMIT, MAX_RECORD_LIMIT,
};
use ringscan::source::read_ahead::{ReadAhead, BLOCK};
use ringscan::source::reassembly::ReassemblyConfig;

// ----- allocation accounting (this thread only, so parallel tests do not disturb it) ---------

struct CountingAlloc;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

fn note_allocation(size: usize) {
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
    let _ = LARGEST.try_with(|c| c.set(c.get().max(size)));
}

// SAFETY: forwards every call to the system allocator unchanged; only counts.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation(new_size);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

/// (allocations, largest allocation in bytes) made on this thread by `f`.
fn allocations<T>(f: impl FnOnce() -> T) -> (T, u64, usize) {
    ALLOCATIONS.with(|c| c.set(0));
    LARGEST.with(|c| c.set(0));
    let out = f();
    (out, ALLOCATIONS.with(Cell::get), LARGEST.with(Cell::get))
}

// ----- packet builders ------------------------------------------------------------------------

const HOST: SocketAddrV4 = SocketAddrV4::new(Ipv4Addr::new(255, 255, 255, 255), 2368);

fn pattern(len: usize, seed: u8) -> Vec<u8> {
    (0..len)
        .map(|i| (i as u8).wrapping_mul(31).wrapping_add(seed) ^ (i >> 8) as u8)
        .collect()
}

/// An IPv4 header + `payload` (the IP payload).
fn ipv4(
    src: Ipv4Addr,
    dst: Ipv4Addr,
    protocol: u8,
    id: u16,
    more: bool,
    offset: usize,
    payload: &[u8],
) -> Vec<u8> {
    let total = 20 + payload.len();
    let flags = (if more { 0x2000 } else { 0 }) | (offset / 8) as u16;
    let mut p = Vec::with_capacity(total);
    p.extend_from_slice(&[0x45, 0]);
    p.extend_from_slice(&(total as u16).to_be_bytes());
    p.extend_from_slice(&id.to_be_bytes());
    p.extend_from_slice(&flags.to_be_bytes());
    p.extend_from_slice(&[64, protocol, 0xde, 0xad]); // checksum is never verified
    p.extend_from_slice(&src.octets());
    p.extend_from_slice(&dst.octets());
    p.extend_from_slice(payload);
    p
}

/// UDP header + payload.
fn udp(src_port: u16, dst_port: u16, payload: &[u8]) -> Vec<u8> {
    let mut u = Vec::with_capacity(8 + payload.len());
    u.extend_from_slice(&src_port.to_be_bytes());
    u.extend_from_slice(&dst_port.to_be_bytes());
    u.extend_from_slice(&((8 + payload.len()) as u16).to_be_bytes());
    u.extend_from_slice(&[0, 0]);
    u.extend_from_slice(payload);
    u
}

fn udp_ipv4(src: SocketAddrV4, dst: SocketAddrV4, id: u16, payload: &[u8]) -> Vec<u8> {
    ipv4(
        *src.ip(),
        *dst.ip(),
        17,
        id,
        false,
        0,
        &udp(src.port(), dst.port(), payload),
    )
}

/// IPv4 fragments of one UDP datagram, `mtu_payload` IP payload bytes each (a multiple of 8).
fn fragments(
    src: SocketAddrV4,
    dst: SocketAddrV4,
    id: u16,
    payload: &[u8],
    mtu_payload: usize,
) -> Vec<Vec<u8>> {
    let datagram = udp(src.port(), dst.port(), payload);
    let n = datagram.len().div_ceil(mtu_payload);
    datagram
        .chunks(mtu_payload)
        .enumerate()
        .map(|(i, c)| ipv4(*src.ip(), *dst.ip(), 17, id, i + 1 < n, i * mtu_payload, c))
        .collect()
}

fn ethernet(ip: &[u8], tags: &[u16]) -> Vec<u8> {
    let mut f = vec![0xff; 6];
    f.extend_from_slice(&[0x60, 0x76, 0x88, 0x10, 0x20, 0x30]);
    for (i, tpid) in tags.iter().enumerate() {
        f.extend_from_slice(&tpid.to_be_bytes());
        f.extend_from_slice(&(100 + i as u16).to_be_bytes());
    }
    f.extend_from_slice(&[0x08, 0x00]);
    f.extend_from_slice(ip);
    if f.len() < 60 {
        f.resize(60, 0xee); // Ethernet padding: must not end up in a payload
    }
    f
}

fn ethernet_type(ethertype: u16, body: &[u8]) -> Vec<u8> {
    let mut f = vec![0xff; 12];
    f.extend_from_slice(&ethertype.to_be_bytes());
    f.extend_from_slice(body);
    f
}

fn sll(ip: &[u8]) -> Vec<u8> {
    let mut f = vec![
        0, 0, 0, 1, 0, 6, 0x60, 0x76, 0x88, 0x10, 0x20, 0x30, 0, 0, 0x08, 0x00,
    ];
    f.extend_from_slice(ip);
    f
}

fn sll2(ip: &[u8]) -> Vec<u8> {
    let mut f = vec![0x08, 0x00, 0, 0, 0, 0, 0, 3, 0, 1, 0, 6];
    f.extend_from_slice(&[0x60, 0x76, 0x88, 0x10, 0x20, 0x30, 0, 0]);
    f.extend_from_slice(ip);
    f
}

fn null_loopback(ip: &[u8]) -> Vec<u8> {
    let mut f = vec![2, 0, 0, 0];
    f.extend_from_slice(ip);
    f
}

// ----- container writers ----------------------------------------------------------------------

struct Rec {
    time_ns: i64,
    data: Vec<u8>,
    /// Original length when it differs from the captured one.
    origlen: Option<u32>,
}

fn rec(time_ns: i64, data: Vec<u8>) -> Rec {
    Rec {
        time_ns,
        data,
        origlen: None,
    }
}

fn u16b(big: bool, v: u16) -> [u8; 2] {
    if big {
        v.to_be_bytes()
    } else {
        v.to_le_bytes()
    }
}
fn u32b(big: bool, v: u32) -> [u8; 4] {
    if big {
        v.to_be_bytes()
    } else {
        v.to_le_bytes()
    }
}
fn u64b(big: bool, v: u64) -> [u8; 8] {
    if big {
        v.to_be_bytes()
    } else {
        v.to_le_bytes()
    }
}

fn classic_header(big: bool, nanos: bool, linktype: u32, snaplen: u32) -> Vec<u8> {
    let mut f = Vec::new();
    f.extend_from_slice(&u32b(big, if nanos { 0xa1b2_3c4d } else { 0xa1b2_c3d4 }));
    f.extend_from_slice(&u16b(big, 2));
    f.extend_from_slice(&u16b(big, 4));
    f.extend_from_slice(&[0; 8]);
    f.extend_from_slice(&u32b(big, snaplen));
    f.extend_from_slice(&u32b(big, linktype));
    f
}

fn classic_record(big: bool, nanos: bool, r: &Rec) -> Vec<u8> {
    let secs = r.time_ns.div_euclid(1_000_000_000) as u32;
    let ns = r.time_ns.rem_euclid(1_000_000_000) as u32;
    let mut f = Vec::new();
    f.extend_from_slice(&u32b(big, secs));
    f.extend_from_slice(&u32b(big, if nanos { ns } else { ns / 1000 }));
    f.extend_from_slice(&u32b(big, r.data.len() as u32));
    f.extend_from_slice(&u32b(big, r.origlen.unwrap_or(r.data.len() as u32)));
    f.extend_from_slice(&r.data);
    f
}

fn classic(big: bool, nanos: bool, linktype: u32, recs: &[Rec]) -> Vec<u8> {
    let mut f = classic_header(big, nanos, linktype, 65_535);
    for r in recs {
        f.extend(classic_record(big, nanos, r));
    }
    f
}

enum Ng {
    Shb {
        big: bool,
    },
    Idb {
        linktype: u16,
        snaplen: u32,
        tsresol: Option<u8>,
        tsoffset_s: Option<i64>,
    },
    Epb {
        iface: u32,
        ts: u64,
        data: Vec<u8>,
        origlen: Option<u32>,
    },
    Opb {
        iface: u16,
        ts: u64,
        data: Vec<u8>,
    },
    Spb {
        data: Vec<u8>,
    },
    Raw {
        block_type: u32,
        body: Vec<u8>,
    },
}

fn idb(linktype: u16) -> Ng {
    Ng::Idb {
        linktype,
        snaplen: 0,
        tsresol: None,
        tsoffset_s: None,
    }
}

fn epb(iface: u32, ts: u64, data: Vec<u8>) -> Ng {
    Ng::Epb {
        iface,
        ts,
        data,
        origlen: None,
    }
}

fn padded(data: &[u8]) -> Vec<u8> {
    let mut v = data.to_vec();
    v.resize(data.len().div_ceil(4) * 4, 0);
    v
}

fn ng_block(big: bool, block_type: u32, body: &[u8]) -> Vec<u8> {
    let len = 12 + body.len() as u32;
    let mut f = Vec::new();
    f.extend_from_slice(&u32b(big, block_type));
    f.extend_from_slice(&u32b(big, len));
    f.extend_from_slice(body);
    f.extend_from_slice(&u32b(big, len));
    f
}

/// A pcapng file; an `Shb` sets the byte order of the blocks after it. Starts with an SHB.
fn pcapng(blocks: &[Ng]) -> Vec<u8> {
    let mut f = Vec::new();
    let mut big = false;
    for b in blocks {
        let (block_type, body) = match b {
            Ng::Shb { big: b } => {
                big = *b;
                let mut body = u32b(big, 0x1a2b_3c4d).to_vec();
                body.extend_from_slice(&u16b(big, 1));
                body.extend_from_slice(&u16b(big, 0));
                body.extend_from_slice(&u64b(big, u64::MAX)); // section length unknown
                (0x0a0d_0d0a, body)
            }
            Ng::Idb {
                linktype,
                snaplen,
                tsresol,
                tsoffset_s,
            } => {
                let mut body = u16b(big, *linktype).to_vec();
                body.extend_from_slice(&[0, 0]);
                body.extend_from_slice(&u32b(big, *snaplen));
                // An option ringscan ignores (if_name), then the timestamp options.
                body.extend_from_slice(&u16b(big, 2));
                body.extend_from_slice(&u16b(big, 4));
                body.extend_from_slice(&padded(b"eth0"));
                if let Some(r) = tsresol {
                    body.extend_from_slice(&u16b(big, 9));
                    body.extend_from_slice(&u16b(big, 1));
                    body.extend_from_slice(&[*r, 0, 0, 0]);
                }
                if let Some(o) = tsoffset_s {
                    body.extend_from_slice(&u16b(big, 14));
                    body.extend_from_slice(&u16b(big, 8));
                    body.extend_from_slice(&u64b(big, *o as u64));
                }
                body.extend_from_slice(&[0; 4]); // opt_endofopt
                (1, body)
            }
            Ng::Epb {
                iface,
                ts,
                data,
                origlen,
            } => {
                let mut body = u32b(big, *iface).to_vec();
                body.extend_from_slice(&u32b(big, (ts >> 32) as u32));
                body.extend_from_slice(&u32b(big, *ts as u32));
                body.extend_from_slice(&u32b(big, data.len() as u32));
                body.extend_from_slice(&u32b(big, origlen.unwrap_or(data.len() as u32)));
                body.extend_from_slice(&padded(data));
                // epb_flags option, then end of options.
                body.extend_from_slice(&u16b(big, 2));
                body.extend_from_slice(&u16b(big, 4));
                body.extend_from_slice(&u32b(big, 1));
                body.extend_from_slice(&[0; 4]);
                (6, body)
            }
            Ng::Opb { iface, ts, data } => {
                let mut body = u16b(big, *iface).to_vec();
                body.extend_from_slice(&u16b(big, 0));
                body.extend_from_slice(&u32b(big, (ts >> 32) as u32));
                body.extend_from_slice(&u32b(big, *ts as u32));
                body.extend_from_slice(&u32b(big, data.len() as u32));
                body.extend_from_slice(&u32b(big, data.len() as u32));
                body.extend_from_slice(&padded(data));
                (2, body)
            }
            Ng::Spb { data } => {
                let mut body = u32b(big, data.len() as u32).to_vec();
                body.extend_from_slice(&padded(data));
                (3, body)
            }
            Ng::Raw { block_type, body } => (*block_type, body.clone()),
        };
        f.extend(ng_block(big, block_type, &body));
    }
    f
}

// ----- reading helpers ------------------------------------------------------------------------

#[derive(Debug, Clone, PartialEq, Eq)]
struct Got {
    time_ns: i64,
    src: SocketAddrV4,
    dst: SocketAddrV4,
    payload: Vec<u8>,
}

fn read_all<R: std::io::Read>(mut source: PcapSource<R>) -> (Vec<Got>, SourceStats) {
    let mut out = Vec::new();
    while let Some(d) = source.next_datagram().expect("no error") {
        out.push(Got {
            time_ns: d.time_ns,
            src: d.src,
            dst: d.dst,
            payload: d.payload.to_vec(),
        });
    }
    (out, source.stats().clone())
}

fn read_bytes(file: &[u8]) -> (Vec<Got>, SourceStats) {
    read_all(PcapSource::new(Cursor::new(file)).expect("valid header"))
}

/// Reads until the first error; returns the datagrams before it and the error.
fn read_until_error(file: &[u8]) -> (usize, SourceError, SourceStats) {
    let mut source = PcapSource::new(Cursor::new(file)).expect("valid header");
    let mut n = 0;
    loop {
        match source.next_datagram() {
            Ok(Some(_)) => n += 1,
            Ok(None) => panic!("expected an error, got the end after {n} datagrams"),
            Err(e) => {
                // Fused afterwards.
                assert!(matches!(source.next_datagram(), Ok(None)));
                return (n, e, source.stats().clone());
            }
        }
    }
}

fn header_error(file: &[u8]) -> SourceError {
    match PcapSource::new(Cursor::new(file)) {
        Ok(_) => panic!("header accepted"),
        Err(e) => e,
    }
}

/// Records = datagrams not from fragments + fragments + everything skipped.
fn assert_accounted(s: &SourceStats) {
    assert_eq!(
        s.records,
        s.datagrams - s.reassembled + s.fragments + s.non_udp + s.malformed + s.truncated_records,
        "{s:?}"
    );
}

fn sample(i: usize) -> (SocketAddrV4, SocketAddrV4, Vec<u8>) {
    let src = SocketAddrV4::new(
        Ipv4Addr::new(192, 168, 1, 201 + (i % 2) as u8),
        2368 + i as u16,
    );
    let dst = SocketAddrV4::new(Ipv4Addr::new(10, 0, 0, 1), 7502 + i as u16);
    (src, dst, pattern(1 + 37 * i, i as u8))
}

// ----- classic pcap ---------------------------------------------------------------------------

#[test]
fn classic_all_byte_orders_resolutions_and_link_types() {
    type Wrap = fn(&[u8]) -> Vec<u8>;
    let links: [(u32, Wrap); 9] = [
        (1, |ip| ethernet(ip, &[])),
        (1, |ip| ethernet(ip, &[0x8100])),
        (1, |ip| ethernet(ip, &[0x88a8, 0x8100])),
        (113, sll),
        (276, sll2),
        (101, |ip| ip.to_vec()),
        (228, |ip| ip.to_vec()),
        (0, null_loopback),
        (108, |ip| [&[0, 0, 0, 2][..], ip].concat()),
    ];
    for big in [false, true] {
        for nanos in [false, true] {
            for (linktype, wrap) in links {
                let recs: Vec<Rec> = (0..5)
                    .map(|i| {
                        let (src, dst, payload) = sample(i);
                        let t = 1_700_000_000_123_456_000 + i as i64 * 1_000_789;
                        rec(t, wrap(&udp_ipv4(src, dst, i as u16, &payload)))
                    })
                    .collect();
                let file = classic(big, nanos, linktype, &recs);
                let source = PcapSource::new(Cursor::new(&file)).unwrap();
                assert_eq!(
                    source.format(),
                    FileFormat::Pcap {
                        nanosecond: nanos,
                        big_endian: big,
                        snaplen: 65_535,
                        linktype
                    }
                );
                let (got, stats) = read_all(source);
                let what = format!("big {big} nanos {nanos} linktype {linktype}");
                assert_eq!(got.len(), 5, "{what}");
                for (i, g) in got.iter().enumerate() {
                    let (src, dst, payload) = sample(i);
                    let t = 1_700_000_000_123_456_000 + i as i64 * 1_000_789;
                    let t = if nanos { t } else { t / 1000 * 1000 };
                    assert_eq!(
                        g,
                        &Got {
                            time_ns: t,
                            src,
                            dst,
                            payload
                        },
                        "{what}"
                    );
                }
                assert_eq!(stats.records, 5);
                assert_eq!(stats.datagrams, 5);
                assert_eq!(stats.bytes, file.len() as u64);
                assert_eq!(stats.first_time_ns, Some(got[0].time_ns));
                assert_eq!(stats.last_time_ns, Some(got[4].time_ns));
                assert_accounted(&stats);
            }
        }
    }
}

#[test]
fn non_udp_records_are_counted_and_skipped() {
    let (src, dst, payload) = sample(3);
    let tcp = ipv4(*src.ip(), *dst.ip(), 6, 1, false, 0, &[0; 20]);
    let ipv6 = ethernet_type(0x86dd, &[0x60; 60]);
    let arp = ethernet_type(0x0806, &[0; 28]);
    let llc = ethernet_type(0x0026, &[0x42; 38]);
    let tcp_fragment = ipv4(*src.ip(), *dst.ip(), 6, 2, true, 0, &[0; 16]);
    let recs = vec![
        rec(1, ethernet(&tcp, &[])),
        rec(2, ipv6),
        rec(3, arp),
        rec(4, llc),
        rec(5, ethernet(&tcp_fragment, &[])),
        rec(6, ethernet(&udp_ipv4(src, dst, 9, &payload), &[])),
    ];
    let (got, stats) = read_bytes(&classic(false, false, 1, &recs));
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].payload, payload);
    assert_eq!(stats.non_udp, 5);
    assert_eq!(stats.fragments, 0);
    assert_accounted(&stats);
    // Raw IP (101) with an IPv6 packet.
    let (got, stats) = read_bytes(&classic(true, true, 101, &[rec(1, vec![0x60; 48])]));
    assert!(got.is_empty());
    assert_eq!(stats.non_udp, 1);
}

#[test]
fn malformed_and_truncated_records() {
    let (src, dst, payload) = sample(4);
    let good = udp_ipv4(src, dst, 1, &payload);
    // UDP length beyond the IP payload.
    let mut long_udp = good.clone();
    long_udp[24..26].copy_from_slice(&((payload.len() + 9) as u16).to_be_bytes());
    // IP total length beyond the frame, frame not truncated, UDP length right: accepted and
    // counted (the early VLP-16 position packet quirk) ...
    let mut long_ip = good.clone();
    long_ip[2..4].copy_from_slice(&1234_u16.to_be_bytes());
    // ... but not with a UDP length beyond the frame too, nor for a fragment.
    let mut long_ip_udp = long_udp.clone();
    long_ip_udp[2..4].copy_from_slice(&1234_u16.to_be_bytes());
    let mut long_ip_fragment = long_ip.clone();
    long_ip_fragment[6] = 0x20;
    // IHL 4.
    let mut bad_ihl = good.clone();
    bad_ihl[0] = 0x44;
    // IPv4 EtherType but version 6.
    let mut bad_version = good.clone();
    bad_version[0] = 0x65;
    // UDP length below 8.
    let mut tiny_udp = good.clone();
    tiny_udp[24..26].copy_from_slice(&7_u16.to_be_bytes());
    // A truncated capture (snaplen): origlen says more.
    let cut = ethernet(&good, &[]);
    let truncated = Rec {
        time_ns: 7,
        data: cut[..40].to_vec(),
        origlen: Some(cut.len() as u32),
    };
    // Truncated but the datagram is complete (only the Ethernet FCS was not captured).
    let mut fcs = ethernet(&good, &[]);
    let full_len = fcs.len() as u32 + 4;
    fcs.truncate(14 + good.len());
    let fcs_cut = Rec {
        time_ns: 8,
        data: fcs,
        origlen: Some(full_len),
    };
    let recs = vec![
        rec(1, ethernet(&long_udp, &[])),
        rec(2, ethernet(&long_ip, &[])),
        rec(2, ethernet(&long_ip_udp, &[])),
        rec(2, ethernet(&long_ip_fragment, &[])),
        rec(3, ethernet(&bad_ihl, &[])),
        rec(4, ethernet(&bad_version, &[])),
        rec(5, ethernet(&tiny_udp, &[])),
        rec(6, vec![0xff; 10]), // shorter than an Ethernet header
        truncated,
        fcs_cut,
        rec(9, ethernet(&good, &[])),
    ];
    let (got, stats) = read_bytes(&classic(false, false, 1, &recs));
    assert_eq!(got.len(), 3);
    assert!(got.iter().all(|g| g.payload == payload));
    assert_eq!(stats.ip_length_overruns, 1);
    assert_eq!(stats.malformed, 7);
    assert_eq!(stats.truncated_records, 1);
    assert_eq!(stats.truncated_tail, None);
    assert_accounted(&stats);
}

#[test]
fn udp_length_shorter_than_ip_payload_wins() {
    let (src, dst, payload) = sample(2);
    let mut ip = udp_ipv4(src, dst, 1, &payload);
    ip.extend_from_slice(&[0xAB; 5]);
    let total = ip.len() as u16;
    ip[2..4].copy_from_slice(&total.to_be_bytes());
    let (got, _) = read_bytes(&classic(false, false, 101, &[rec(1, ip)]));
    assert_eq!(got[0].payload, payload);
}

#[test]
fn record_longer_than_snaplen_is_counted_malformed() {
    let (src, dst, payload) = sample(9);
    let frame = ethernet(&udp_ipv4(src, dst, 1, &payload), &[]);
    assert!(frame.len() > 100);
    let (small_src, small_dst, small) = sample(1);
    let mut file = classic_header(false, false, 1, 100);
    // Longer than the snaplen: no conforming writer makes this.
    file.extend(classic_record(false, false, &rec(1, frame.clone())));
    // Cut at the snaplen, as a capture does: truncated, not malformed.
    let cut = Rec {
        time_ns: 2,
        data: frame[..100].to_vec(),
        origlen: Some(frame.len() as u32),
    };
    file.extend(classic_record(false, false, &cut));
    file.extend(classic_record(
        false,
        false,
        &rec(3, ethernet(&udp_ipv4(small_src, small_dst, 2, &small), &[])),
    ));
    let (got, stats) = read_bytes(&file);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].payload, small);
    assert_eq!(stats.records, 3);
    assert_eq!(stats.malformed, 1);
    assert_eq!(stats.truncated_records, 1);
    assert_accounted(&stats);
}

// ----- pcapng ---------------------------------------------------------------------------------

#[test]
fn pcapng_interfaces_resolutions_and_block_kinds() {
    for big in [false, true] {
        let p: Vec<_> = (0..6).map(sample).collect();
        let ip = |i: usize| udp_ipv4(p[i].0, p[i].1, i as u16, &p[i].2);
        let blocks = vec![
            Ng::Shb { big },
            idb(1), // Ethernet, default resolution µs
            Ng::Idb {
                linktype: 276,
                snaplen: 65_535,
                tsresol: Some(9),
                tsoffset_s: None,
            },
            Ng::Idb {
                linktype: 101,
                snaplen: 0,
                tsresol: Some(0x8a),
                tsoffset_s: Some(1_000),
            },
            Ng::Raw {
                block_type: 4,
                body: vec![0; 8],
            }, // name resolution: skipped
            Ng::Raw {
                block_type: 0x0bad,
                body: vec![1; 20],
            }, // unknown: skipped
            epb(0, 1_700_000_000_000_001, ethernet(&ip(0), &[0x8100])),
            epb(1, 1_700_000_000_000_000_002, sll2(&ip(1))),
            epb(2, 1024 * 5 + 256, ip(2)), // 5.25 s after the 1000 s offset
            Ng::Opb {
                iface: 0,
                ts: 7_000_000,
                data: ethernet(&ip(3), &[]),
            },
            Ng::Spb {
                data: ethernet(&ip(4), &[]),
            },
            Ng::Raw {
                block_type: 5,
                body: vec![0; 12],
            }, // interface statistics: skipped
        ];
        let file = pcapng(&blocks);
        let source = PcapSource::new(Cursor::new(&file)).unwrap();
        let (got, stats) = read_all(source);
        let expect_times = [
            1_700_000_000_000_001_000,
            1_700_000_000_000_000_002,
            1_005_250_000_000,
            7_000_000_000,
            7_000_000_000, // SPB: time of the previous record
        ];
        assert_eq!(got.len(), 5, "big {big}");
        for (i, g) in got.iter().enumerate() {
            assert_eq!(
                g,
                &Got {
                    time_ns: expect_times[i],
                    src: p[i].0,
                    dst: p[i].1,
                    payload: p[i].2.clone()
                }
            );
        }
        assert_eq!(stats.records, 5);
        assert_eq!(stats.bytes, file.len() as u64);
        assert_accounted(&stats);
    }
}

#[test]
fn pcapng_sections_switch_byte_order_and_reset_interfaces() {
    let (src, dst, payload) = sample(5);
    let ip = udp_ipv4(src, dst, 1, &payload);
    let blocks = vec![
        Ng::Shb { big: false },
        idb(1),
        epb(0, 1, ethernet(&ip, &[])),
        Ng::Shb { big: true },
        idb(228),
        epb(0, 2, ip.clone()),
    ];
    let (got, stats) = read_bytes(&pcapng(&blocks));
    assert_eq!(got.len(), 2);
    assert_eq!((got[0].time_ns, got[1].time_ns), (1_000, 2_000));
    assert_accounted(&stats);

    // Interface 1 of the first section does not exist in the second.
    let mut blocks = blocks;
    blocks.insert(2, idb(1));
    let frame = ethernet(&ip, &[]);
    let last_block_len = 12 + 20 + frame.len().div_ceil(4) * 4 + 12;
    blocks.push(epb(1, 3, frame));
    let file = pcapng(&blocks);
    let offset = (file.len() - last_block_len) as u64;
    let (n, err, _) = read_until_error(&file);
    assert_eq!(n, 2);
    assert!(
        matches!(err, SourceError::UnknownInterface { offset: o, interface: 1, interfaces: 1 } if o == offset),
        "{err:?}"
    );
}

#[test]
fn pcapng_unknown_link_type_counts_non_udp() {
    let (src, dst, payload) = sample(1);
    let ip = udp_ipv4(src, dst, 1, &payload);
    let blocks = vec![
        Ng::Shb { big: false },
        idb(127),
        idb(1),
        epb(0, 1, vec![0; 40]),
        epb(1, 2, ethernet(&ip, &[])),
    ];
    let (got, stats) = read_bytes(&pcapng(&blocks));
    assert_eq!(got.len(), 1);
    assert_eq!(stats.non_udp, 1);
}

#[test]
fn independent_writer_pcap_file_crate() {
    use pcap_file::pcap::{PcapHeader, PcapPacket, PcapWriter};
    use pcap_file::pcapng::blocks::enhanced_packet::EnhancedPacketBlock;
    use pcap_file::pcapng::blocks::interface_description::{
        InterfaceDescriptionBlock, InterfaceDescriptionOption,
    };
    use pcap_file::pcapng::PcapNgWriter;
    use pcap_file::{DataLink, TsResolution};
    use std::borrow::Cow;
    use std::time::Duration;

    let packets: Vec<_> = (0..20).map(sample).collect();
    let frame = |i: usize| {
        ethernet(
            &udp_ipv4(packets[i].0, packets[i].1, i as u16, &packets[i].2),
            &[],
        )
    };
    let time = |i: usize| Duration::new(1_600_000_000 + i as u64, 123_456_789);

    for resolution in [TsResolution::MicroSecond, TsResolution::NanoSecond] {
        let header = PcapHeader {
            ts_resolution: resolution,
            ..Default::default()
        };
        let mut writer = PcapWriter::with_header(Vec::new(), header).unwrap();
        for i in 0..20 {
            let data = frame(i);
            writer
                .write_packet(&PcapPacket::new(time(i), data.len() as u32, &data))
                .unwrap();
        }
        let (got, _) = read_bytes(&writer.into_writer());
        assert_eq!(got.len(), 20);
        for (i, g) in got.iter().enumerate() {
            let t = time(i).as_nanos() as i64;
            let t = if resolution == TsResolution::MicroSecond {
                t / 1000 * 1000
            } else {
                t
            };
            assert_eq!(
                g,
                &Got {
                    time_ns: t,
                    src: packets[i].0,
                    dst: packets[i].1,
                    payload: packets[i].2.clone()
                }
            );
        }
    }

    // pcap-file writes EPB timestamps in ns, so the IDB declares if_tsresol = 9.
    let mut writer = PcapNgWriter::new(Vec::new()).unwrap();
    writer
        .write_pcapng_block(InterfaceDescriptionBlock {
            linktype: DataLink::ETHERNET,
            snaplen: 0,
            options: vec![InterfaceDescriptionOption::IfTsResol(9)],
        })
        .unwrap();
    for i in 0..20 {
        let data = frame(i);
        writer
            .write_pcapng_block(EnhancedPacketBlock {
                interface_id: 0,
                timestamp: time(i),
                original_len: data.len() as u32,
                data: Cow::Owned(data),
                options: vec![],
            })
            .unwrap();
    }
    let (got, _) = read_bytes(&writer.into_inner());
    assert_eq!(got.len(), 20);
    for (i, g) in got.iter().enumerate() {
        assert_eq!(g.time_ns, time(i).as_nanos() as i64);
        assert_eq!(g.payload, packets[i].2);
    }
}

// ----- fragments ------------------------------------------------------------------------------

fn shuffle<T>(items: &mut [T], mut seed: u64) {
    for i in (1..items.len()).rev() {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        items.swap(i, (seed % (i as u64 + 1)) as usize);
    }
}

#[test]
fn fragments_in_any_order_with_duplicates_and_overlaps() {
    let src = SocketAddrV4::new(Ipv4Addr::new(169, 254, 92, 158), 7502);
    let dst = SocketAddrV4::new(Ipv4Addr::new(169, 254, 0, 1), 7502);
    let payload = pattern(16640, 3);
    let in_order = fragments(src, dst, 4242, &payload, 1480);
    assert_eq!(in_order.len(), 12);

    let mut reversed = in_order.clone();
    reversed.reverse();
    let mut duplicated = in_order.clone();
    duplicated.insert(3, in_order[2].clone());
    duplicated.insert(0, in_order[5].clone());
    // Overlapping: the same datagram also cut at 1000-byte boundaries (non-final pieces only).
    let mut overlapping = in_order.clone();
    overlapping.extend(
        fragments(src, dst, 4242, &payload, 1000)
            .into_iter()
            .filter(|f| f[6] & 0x20 != 0),
    );
    shuffle(&mut overlapping, 7);

    let mut orders = vec![
        ("in order", in_order.clone()),
        ("reversed", reversed),
        ("duplicated", duplicated),
        ("overlapping", overlapping),
    ];
    for seed in 1..20 {
        let mut shuffled = in_order.clone();
        shuffle(&mut shuffled, seed);
        orders.push(("shuffled", shuffled));
    }
    for (name, frags) in orders {
        let n = frags.len() as u64;
        let recs: Vec<Rec> = frags
            .into_iter()
            .enumerate()
            .map(|(i, ip)| rec(1_000 + i as i64, ethernet(&ip, &[])))
            .collect();
        let (got, stats) = read_bytes(&classic(false, true, 1, &recs));
        assert_eq!(got.len(), 1, "{name}");
        assert_eq!(got[0].payload, payload, "{name}");
        assert_eq!((got[0].src, got[0].dst), (src, dst), "{name}");
        assert_eq!(stats.fragments, n, "{name}");
        assert_eq!(stats.reassembled, 1, "{name}");
        if name == "overlapping" {
            // Pieces arriving after completion open a new set, which expires at the end.
            assert!(got[0].time_ns < 1_000 + n as i64);
            assert!(stats.fragments_expired > 0);
        } else {
            assert_eq!(
                got[0].time_ns,
                1_000 + n as i64 - 1,
                "{name}: time of the completing fragment"
            );
            assert_eq!(stats.fragments_expired, 0, "{name}");
        }
        assert_accounted(&stats);
    }
}

#[test]
fn interleaved_fragments_of_two_sensors_with_the_same_id() {
    let a = SocketAddrV4::new(Ipv4Addr::new(169, 254, 92, 158), 7502);
    let b = SocketAddrV4::new(Ipv4Addr::new(169, 254, 238, 111), 7502);
    let dst = SocketAddrV4::new(Ipv4Addr::new(169, 254, 0, 1), 7502);
    let (pa, pb) = (pattern(16640, 1), pattern(12608, 2));
    let fa = fragments(a, dst, 77, &pa, 1480);
    let fb = fragments(b, dst, 77, &pb, 1480);
    let mut recs = Vec::new();
    for i in 0..fa.len().max(fb.len()) {
        for f in [fa.get(i), fb.get(i)].into_iter().flatten() {
            recs.push(rec(recs.len() as i64, sll(f)));
        }
    }
    let (got, stats) = read_bytes(&classic(false, false, 113, &recs));
    let mut got: Vec<_> = got.into_iter().map(|g| (g.src, g.payload)).collect();
    got.sort();
    assert_eq!(got, vec![(a, pa), (b, pb)]);
    assert_eq!(stats.reassembled, 2);
}

#[test]
fn stale_orphan_fragment_is_not_glued_to_a_later_datagram() {
    let src = SocketAddrV4::new(Ipv4Addr::new(10, 5, 6, 101), 7502);
    let dst = SocketAddrV4::new(Ipv4Addr::new(10, 5, 6, 1), 34636);
    let stale = pattern(8448, 9);
    let fresh = pattern(8448, 10);
    let orphan = fragments(src, dst, 21723, &stale, 1480).remove(0);
    let mut recs = vec![rec(1_000_000_000, ethernet(&orphan, &[]))];
    for (i, f) in fragments(src, dst, 21723, &fresh, 1480)
        .into_iter()
        .enumerate()
    {
        recs.push(rec(89_000_000_000 + i as i64, ethernet(&f, &[])));
    }
    let (got, stats) = read_bytes(&classic(false, false, 1, &recs));
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].payload, fresh);
    assert_eq!(stats.fragments, 7);
    assert_eq!(stats.fragments_expired, 1);
    assert_accounted(&stats);

    // With a timeout longer than the gap the orphan is glued and the result is wrong: the
    // timeout is what separates them.
    let config = ReassemblyConfig {
        timeout_ns: 100_000_000_000,
        ..Default::default()
    };
    let file = classic(false, false, 1, &recs);
    let (got, _) = read_all(PcapSource::with_reassembly(Cursor::new(&file), config).unwrap());
    assert_ne!(got.first().map(|g| &g.payload), Some(&fresh));
}

#[test]
fn incomplete_sets_at_the_end_of_the_file_are_expired() {
    let (src, dst, payload) = sample(30);
    let frags = fragments(src, dst, 5, &pattern(3000, 1), 1480);
    let recs = vec![
        rec(0, ethernet(&frags[0], &[])),
        rec(1, ethernet(&frags[2], &[])),
        rec(2, ethernet(&udp_ipv4(src, dst, 6, &payload), &[])),
    ];
    let (got, stats) = read_bytes(&classic(false, false, 1, &recs));
    assert_eq!(got.len(), 1);
    assert_eq!(stats.fragments, 2);
    assert_eq!(stats.fragments_expired, 2);
    assert_accounted(&stats);
}

#[test]
fn lone_first_fragments_keep_memory_bounded() {
    // 10^5 first fragments, each of a different datagram that never completes, with a small
    // complete datagram every 1000 records so that the bound can be checked along the way.
    let dst = SocketAddrV4::new(Ipv4Addr::new(10, 0, 0, 1), 7502);
    let mut file = classic_header(false, false, 228, 0);
    for i in 0..100_000_u32 {
        let src = SocketAddrV4::new(Ipv4Addr::from(0x0a00_0000 | i), 7502);
        let ip = ipv4(
            *src.ip(),
            *dst.ip(),
            17,
            i as u16,
            true,
            0,
            &udp(7502, 7502, &[0; 16])[..24],
        );
        file.extend(classic_record(false, false, &rec(i64::from(i), ip)));
        if i % 1000 == 999 {
            file.extend(classic_record(
                false,
                false,
                &rec(i64::from(i), udp_ipv4(src, dst, 0, b"tick")),
            ));
        }
    }
    let limit = ReassemblyConfig::default();
    let mut source = PcapSource::new(Cursor::new(&file)).unwrap();
    let mut ticks = 0;
    while source.next_datagram().unwrap().is_some() {
        ticks += 1;
        let r = source.reassembler();
        assert_eq!(r.pending_sets(), limit.max_pending);
        assert_eq!(r.pending_bytes(), limit.max_pending * 24);
        assert!(r.pending_bytes() <= limit.max_bytes);
    }
    assert_eq!(ticks, 100);
    let stats = source.stats();
    assert_eq!(stats.records, 100_100);
    assert_eq!(stats.fragments, 100_000);
    assert_eq!(stats.fragments_expired, 100_000); // every set dropped, at the latest at the end
    assert_eq!(source.reassembly_stats().expired_sets, 100_000);
    assert_eq!(source.reassembler().pending_bytes(), 0);
    assert_accounted(stats);
}

// ----- hostile input --------------------------------------------------------------------------

#[test]
fn empty_short_and_foreign_files() {
    assert!(matches!(header_error(b""), SourceError::Empty));
    assert!(matches!(
        header_error(&[0xd4, 0xc3]),
        SourceError::ShortHeader {
            expected: 24,
            found: 2
        }
    ));
    assert!(matches!(
        header_error(&classic_header(false, false, 1, 0)[..10]),
        SourceError::ShortHeader {
            expected: 24,
            found: 10
        }
    ));
    let err = header_error(b"GIF89a........................");
    assert!(matches!(
        err,
        SourceError::BadMagic {
            found: [b'G', b'I', b'F', b'8']
        }
    ));
    assert!(err.to_string().contains("47494638"), "{err}");
    let mut v3 = classic_header(false, false, 1, 0);
    v3[4] = 3;
    assert!(matches!(
        header_error(&v3),
        SourceError::UnsupportedVersion {
            offset: 4,
            major: 3,
            minor: 4
        }
    ));
    assert!(matches!(
        header_error(&classic_header(true, false, 127, 0)),
        SourceError::UnsupportedLinkType {
            offset: 20,
            linktype: 127
        }
    ));
    // pcapng cut inside its section header.
    let ng = pcapng(&[Ng::Shb { big: false }]);
    assert!(matches!(
        header_error(&ng[..6]),
        SourceError::ShortHeader { .. }
    ));
    assert!(matches!(
        header_error(&ng[..20]),
        SourceError::ShortHeader { .. }
    ));
    // A header alone is a valid, empty capture.
    for file in [classic_header(false, false, 1, 65_535), ng.clone()] {
        let (got, stats) = read_bytes(&file);
        assert!(got.is_empty());
        assert_eq!(stats.records, 0);
        assert_eq!(stats.truncated_tail, None);
    }
}

#[test]
fn huge_record_claims_fail_before_allocating() {
    let (src, dst, payload) = sample(3);
    let good = rec(1, ethernet(&udp_ipv4(src, dst, 1, &payload), &[]));
    for snaplen in [65_535, 0, u32::MAX] {
        let mut file = classic_header(false, false, 1, snaplen);
        file.extend(classic_record(false, false, &good));
        let offset = file.len() as u64;
        file.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0, 0]);
        file.extend_from_slice(&(1_u32 << 30).to_le_bytes()); // 1 GiB
        file.extend_from_slice(&(1_u32 << 30).to_le_bytes());
        file.extend_from_slice(&[0; 100]);
        let ((n, err, _), _, largest) = allocations(|| read_until_error(&file));
        assert_eq!(n, 1);
        let limit = if snaplen == u32::MAX {
            MAX_RECORD_LIMIT
        } else {
            DEFAULT_RECORD_LIMIT
        } as u64;
        assert!(
            matches!(err, SourceError::RecordTooLarge { offset: o, len, limit: l } if o == offset && len == 1 << 30 && l == limit),
            "{err:?}"
        );
        assert!(err.to_string().contains(&offset.to_string()));
        assert!(largest < 1 << 20, "largest allocation {largest}");
    }
}

#[test]
fn a_claim_within_the_limit_allocates_only_what_arrives() {
    // snaplen 16 MiB, a record claiming 15 MiB, file ends after 1000 bytes of it.
    let mut file = classic_header(false, false, 1, 16 << 20);
    let offset = file.len() as u64;
    file.extend_from_slice(&[0; 8]);
    file.extend_from_slice(&(15_u32 << 20).to_le_bytes());
    file.extend_from_slice(&(15_u32 << 20).to_le_bytes());
    file.extend_from_slice(&[0; 1000]);
    let ((got, stats), _, largest) = allocations(|| read_bytes(&file));
    assert!(got.is_empty());
    assert_eq!(stats.truncated_tail, Some(offset));
    assert!(largest <= 256 << 10, "largest allocation {largest}");
}

#[test]
fn truncated_last_record_is_reported_not_fatal() {
    let recs: Vec<Rec> = (0..3)
        .map(|i| {
            let (src, dst, payload) = sample(i);
            rec(i as i64, ethernet(&udp_ipv4(src, dst, 1, &payload), &[]))
        })
        .collect();
    let full = classic(false, false, 1, &recs);
    let last = (full.len() - 16 - recs[2].data.len()) as u64;
    for cut in [1, 10, 16, 17, 40] {
        let file = &full[..last as usize + cut];
        let (got, stats) = read_bytes(file);
        assert_eq!(got.len(), 2, "cut {cut}");
        assert_eq!(stats.truncated_tail, Some(last), "cut {cut}");
        assert_eq!(stats.records, 2);
    }
    // pcapng: a block cut short.
    let (src, dst, payload) = sample(7);
    let ip = udp_ipv4(src, dst, 1, &payload);
    let full = pcapng(&[
        Ng::Shb { big: true },
        idb(228),
        epb(0, 1, ip.clone()),
        epb(0, 2, ip),
    ]);
    let block_len = 12 + 20 + payload.len().div_ceil(4) * 4 + 28 + 12;
    let last = full.len() - block_len;
    for cut in [3, 8, 30, block_len - 1] {
        let (got, stats) = read_bytes(&full[..last + cut]);
        assert_eq!(got.len(), 1, "cut {cut}");
        assert_eq!(stats.truncated_tail, Some(last as u64), "cut {cut}");
    }
}

#[test]
fn garbage_after_a_valid_header_is_an_error_with_offset() {
    let mut file = classic_header(false, false, 1, 65_535);
    file.extend_from_slice(&[0xff; 100]);
    let (n, err, _) = read_until_error(&file);
    assert_eq!(n, 0);
    assert!(
        matches!(
            err,
            SourceError::RecordTooLarge {
                offset: 24,
                len: 0xffff_ffff,
                ..
            }
        ),
        "{err:?}"
    );

    let mut file = pcapng(&[Ng::Shb { big: false }]);
    let offset = file.len() as u64;
    file.extend_from_slice(b"this is not a pcapng block at all, just text");
    let (_, err, _) = read_until_error(&file);
    assert!(
        matches!(err, SourceError::BadBlockLength { offset: o, .. } | SourceError::RecordTooLarge { offset: o, .. } if o == offset),
        "{err:?}"
    );
}

#[test]
fn bad_pcapng_blocks() {
    let (src, dst, payload) = sample(2);
    let ip = udp_ipv4(src, dst, 1, &payload);
    let base = pcapng(&[Ng::Shb { big: false }, idb(228)]);
    let at = base.len() as u64;
    let with = |tail: &[u8]| [&base[..], tail].concat();

    // Length not a multiple of 4; below the minimum.
    let (_, err, _) = read_until_error(&with(&[6, 0, 0, 0, 33, 0, 0, 0]));
    assert!(
        matches!(err, SourceError::BadBlockLength { offset, block_type: 6, len: 33, .. } if offset == at),
        "{err:?}"
    );
    let (_, err, _) = read_until_error(&with(&[6, 0, 0, 0, 12, 0, 0, 0, 12, 0, 0, 0]));
    assert!(
        matches!(
            err,
            SourceError::BadBlockLength {
                len: 12,
                min: 32,
                ..
            }
        ),
        "{err:?}"
    );
    // 1 GiB packet block; 1 GiB unknown block.
    for block_type in [6_u8, 0x42] {
        let (_, err, _) = read_until_error(&with(&[block_type, 0, 0, 0, 0, 0, 0, 0x40]));
        assert!(
            matches!(err, SourceError::RecordTooLarge { offset, len: 0x4000_0000, .. } if offset == at),
            "{err:?}"
        );
    }
    // Trailing length differs (packet block and skipped block).
    let mut block = pcapng(&[Ng::Shb { big: false }, idb(228), epb(0, 1, ip.clone())]);
    let n = block.len();
    block[n - 4] ^= 4;
    let (_, err, _) = read_until_error(&block);
    assert!(
        matches!(err, SourceError::BlockLengthMismatch { offset, block_type: 6, .. } if offset == at),
        "{err:?}"
    );
    let mut skipped = pcapng(&[
        Ng::Shb { big: false },
        Ng::Raw {
            block_type: 0x99,
            body: vec![0; 16],
        },
    ]);
    let n = skipped.len();
    skipped[n - 4] = 0;
    let (_, err, _) = read_until_error(&skipped);
    assert!(
        matches!(
            err,
            SourceError::BlockLengthMismatch {
                block_type: 0x99,
                trailing: 0,
                leading: 28,
                ..
            }
        ),
        "{err:?}"
    );
    // Captured length overruns the block.
    let mut overrun = pcapng(&[Ng::Shb { big: false }, idb(228), epb(0, 1, ip.clone())]);
    let caplen_at = at as usize + 8 + 12;
    overrun[caplen_at..caplen_at + 4].copy_from_slice(&5000_u32.to_le_bytes());
    let (_, err, _) = read_until_error(&overrun);
    assert!(
        matches!(err, SourceError::BadBlock { offset, block_type: 6, .. } if offset == at),
        "{err:?}"
    );
    // Packet before any interface.
    let (_, err, _) = read_until_error(&pcapng(&[Ng::Shb { big: false }, epb(0, 1, ip.clone())]));
    assert!(
        matches!(
            err,
            SourceError::UnknownInterface {
                offset: 28,
                interface: 0,
                interfaces: 0
            }
        ),
        "{err:?}"
    );
    // Bad byte-order magic; unsupported version.
    let mut bom = base.clone();
    bom[8] = 0x11;
    assert!(matches!(
        header_error(&bom),
        SourceError::BadBlock {
            offset: 0,
            block_type: 0x0a0d_0d0a,
            ..
        }
    ));
    let mut v2 = base.clone();
    v2[12] = 2;
    assert!(matches!(
        header_error(&v2),
        SourceError::UnsupportedVersion {
            offset: 12,
            major: 2,
            minor: 0
        }
    ));
    // IDB option overrunning its block.
    let mut idb_bad = base.clone();
    idb_bad[28 + 8 + 8 + 2] = 200; // if_name length
    let (_, err, _) =
        read_until_error(&[&idb_bad[..], &pcapng(&[Ng::Shb { big: false }])[..]].concat());
    assert!(
        matches!(
            err,
            SourceError::BadBlock {
                offset: 28,
                block_type: 1,
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn random_bytes_never_panic_or_loop() {
    let (src, dst, payload) = sample(6);
    let ip = udp_ipv4(src, dst, 1, &payload);
    let seeds = [
        classic(
            false,
            false,
            1,
            &[rec(1, ethernet(&ip, &[])), rec(2, ethernet(&ip, &[0x8100]))],
        ),
        classic(true, true, 228, &[rec(1, ip.clone())]),
        pcapng(&[
            Ng::Shb { big: false },
            idb(1),
            idb(276),
            epb(0, 1, ethernet(&ip, &[])),
            epb(1, 2, sll2(&ip)),
            Ng::Spb {
                data: ethernet(&ip, &[]),
            },
        ]),
        classic(
            false,
            false,
            1,
            &fragments(src, dst, 3, &pattern(4000, 1), 1480)
                .iter()
                .enumerate()
                .map(|(i, f)| rec(i as i64, ethernet(f, &[])))
                .collect::<Vec<_>>(),
        ),
    ];
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    // RINGSCAN_FUZZ_ROUNDS=1000000 for a longer run by hand.
    let rounds = std::env::var("RINGSCAN_FUZZ_ROUNDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20_000);
    for round in 0..rounds {
        let mut file = seeds[round % seeds.len()].clone();
        // Flip a few bytes (header included) and sometimes cut the file.
        for _ in 0..1 + next() % 6 {
            let at = (next() % file.len() as u64) as usize;
            file[at] = next() as u8;
        }
        if next() % 3 == 0 {
            let keep = (next() % file.len() as u64) as usize;
            file.truncate(keep);
        }
        let Ok(mut source) = PcapSource::new(Cursor::new(&file)) else {
            continue;
        };
        let mut calls = 0;
        while let Ok(Some(d)) = source.next_datagram() {
            assert!(d.payload.len() <= 65_535);
            calls += 1;
            assert!(
                calls <= file.len(),
                "round {round}: more datagrams than bytes"
            );
        }
        assert!(source.stats().bytes <= file.len() as u64);
    }
}

// ----- allocation -----------------------------------------------------------------------------

#[test]
fn no_allocation_per_packet_in_steady_state() {
    let mut recs = Vec::new();
    for i in 0..400 {
        let (src, dst, payload) = sample(i % 40);
        recs.push(rec(
            i as i64 * 1000,
            ethernet(&udp_ipv4(src, dst, i as u16, &payload), &[0x8100]),
        ));
    }
    // Fragmented datagrams too.
    let src = SocketAddrV4::new(Ipv4Addr::new(169, 254, 1, 2), 7502);
    for i in 0..200 {
        let payload = pattern(8448 + (i % 3) * 1000, i as u8);
        for f in fragments(src, HOST, i as u16, &payload, 1480) {
            recs.push(rec(1_000_000 + i as i64 * 1000, ethernet(&f, &[])));
        }
    }
    for file in [
        classic(false, false, 1, &recs),
        pcapng(
            &[Ng::Shb { big: false }, idb(1)]
                .into_iter()
                .chain(
                    recs.iter()
                        .map(|r| epb(0, r.time_ns as u64, r.data.clone())),
                )
                .collect::<Vec<_>>(),
        ),
    ] {
        let mut source = PcapSource::new(Cursor::new(&file)).unwrap();
        // Warm-up: the 40 sizes of plain datagrams and a few fragmented ones.
        let mut seen = 0;
        while seen < 410 {
            source.next_datagram().unwrap().unwrap();
            seen += 1;
        }
        let (count, allocs, _) = allocations(|| {
            let mut n = 0;
            let mut bytes = 0;
            while let Some(d) = source.next_datagram().unwrap() {
                n += 1;
                bytes += d.payload.len();
            }
            (n, bytes)
        });
        assert_eq!(count.0, 600 - 410);
        assert_eq!(allocs, 0, "allocations while reading {} datagrams", count.0);
        assert_eq!(source.stats().reassembled, 200);
    }
}

// ----- real captures --------------------------------------------------------------------------

fn captures() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/captures");
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "SKIP: {} is absent; real-capture tests not run",
            dir.display()
        );
        None
    }
}

/// (payload length, destination port) → count, source addresses, and the stats.
fn census(path: &Path) -> (BTreeMap<(usize, u16), usize>, Vec<Ipv4Addr>, SourceStats) {
    let mut source = PcapSource::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut counts = BTreeMap::new();
    let mut sources = Vec::new();
    let mut last_time = i64::MIN;
    while let Some(d) = source
        .next_datagram()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    {
        *counts.entry((d.payload.len(), d.dst.port())).or_insert(0) += 1;
        if !sources.contains(d.src.ip()) {
            sources.push(*d.src.ip());
        }
        assert!(
            d.time_ns >= 946_684_800_000_000_000,
            "time before 2000: {}",
            d.time_ns
        );
        last_time = last_time.max(d.time_ns);
    }
    let stats = source.stats().clone();
    assert_eq!(stats.truncated_tail, None, "{}", path.display());
    assert_eq!(
        stats.bytes,
        std::fs::metadata(path).unwrap().len(),
        "{}",
        path.display()
    );
    assert_accounted(&stats);
    (counts, sources, stats)
}

/// ((payload length, destination port), count) pairs.
type Census = [((usize, u16), usize)];

fn expect(pairs: &Census) -> BTreeMap<(usize, u16), usize> {
    pairs.iter().copied().collect()
}

#[test]
fn real_velodyne_captures() {
    let Some(dir) = captures() else { return };
    let ip = |d: u8| Ipv4Addr::new(192, 168, 1, d);
    // (file, data packets, position packets, source) from INVENTORY.md.
    let cases = [
        (
            "Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap",
            2702,
            299,
            Some(ip(201)),
        ),
        (
            "Kitware__VeloView/Testing/Data/vlp-16-test-90deg-1-50-frames.pcap",
            1902,
            367,
            None,
        ),
        (
            "jerry73204__rust-lidar-utils/test_files/hdl32_example.pcap",
            876,
            100,
            None,
        ),
        (
            "jerry73204__rust-lidar-utils/test_files/velodyne_example.pcap",
            84,
            0,
            Some(ip(200)),
        ),
        (
            "jerry73204__rust-lidar-utils/velodyne-test/test_files/velodyne_vlp16.pcap",
            84,
            16,
            None,
        ),
        (
            "jerry73204__rust-lidar-utils/velodyne-test/test_files/velodyne_vlp32.pcap",
            91,
            9,
            None,
        ),
    ];
    for (file, data, position, src) in cases {
        let (counts, sources, stats) = census(&dir.join(file));
        let mut want = vec![((1206, 2368), data)];
        if position > 0 {
            want.push(((512, 8308), position));
        }
        assert_eq!(counts, expect(&want), "{file}");
        if let Some(src) = src {
            assert_eq!(sources, vec![src], "{file}");
        }
        assert_eq!(stats.fragments, 0);
        assert_eq!(stats.malformed, 0);
        // The two early-firmware VLP-16s (INVENTORY.md: product byte 0x21): total length 1234
        // in every 554-byte position packet.
        let early_vlp16 = file.contains("vlp-16-test") || file.contains("velodyne_vlp16");
        let overruns = if early_vlp16 { position } else { 0 };
        assert_eq!(stats.ip_length_overruns, overruns as u64, "{file}");
    }
}

#[test]
fn real_nebula_nanosecond_captures() {
    let Some(dir) = captures() else { return };
    let base =
        "tier4__nebula/src/nebula_velodyne/nebula_velodyne/test_resources/decoder_ground_truth";
    for (file, n) in [
        ("vlp16/1673400471837873222/1673400471837873222_0.pcap", 603),
        ("vlp32/1713492677464078412/1713492677464078412_0.pcap", 379),
    ] {
        let path = dir.join(base).join(file);
        let source = PcapSource::open(&path).unwrap();
        assert!(matches!(
            source.format(),
            FileFormat::Pcap {
                nanosecond: true,
                ..
            }
        ));
        let (counts, _, stats) = census(&path);
        assert_eq!(counts.values().sum::<usize>(), n, "{file}");
        assert!(
            counts.keys().all(|&(len, _)| len == 1206),
            "{file}: {counts:?}"
        );
        // Nanosecond stamps: the file name is the bag's start time in ns.
        let first = stats.first_time_ns.unwrap();
        assert!(
            first % 1000 != 0 || stats.last_time_ns.unwrap() % 1000 != 0,
            "{file}: only µs precision?"
        );
    }
}

#[test]
fn real_ouster_captures() {
    let Some(dir) = captures() else { return };
    let dir = dir.join("ouster-lidar__ouster-sdk/tests/pcaps");
    // (file, [((payload length, dst port), count)]) from INVENTORY.md; port 0 = port not stated.
    let cases: &[(&str, &Census)] = &[
        (
            "OS-0-32-U1_v2.2.0_1024x10.pcap",
            &[((8448, 7502), 64), ((48, 7503), 10)],
        ),
        (
            "OS-0-32-U1_v2.2.0_1024x10-single-packet.pcap",
            &[((8448, 7502), 1)],
        ),
        (
            "OS-1-128_767798045_1024x10_20230712_120049.pcap",
            &[((16640, 0), 8), ((48, 0), 2)],
        ),
        (
            "OS-1-128_v2.3.0_1024x10_lb_n3.pcap",
            &[((8448, 0), 192), ((48, 0), 30)],
        ),
        ("OS-1-32-G_v2.1.1_1024x10.pcap", &[((6464, 0), 64)]),
        (
            "OS-1-64_1024x10_fw20.pcap",
            &[((12608, 0), 64), ((48, 0), 11)],
        ),
        (
            "OS-2-128-U1_v2.3.0_1024x10.pcap",
            &[((24832, 0), 64), ((48, 0), 10)],
        ),
        ("OS-2-32-U0_v2.0.0_1024x10.pcap", &[((6464, 0), 64)]),
        ("crc_test.pcap", &[((8448, 0), 34), ((48, 0), 10)]),
        (
            "imu_zm_no_lidar.pcap",
            &[((452, 7513), 8), ((680, 7514), 1)],
        ),
        ("shot_limiting_test.pcap", &[((24832, 7702), 1)]),
        (
            "windowed_frame1.pcap",
            &[((8448, 53750), 17), ((48, 0), 10)],
        ),
        (
            "same_ports.pcap",
            &[((16640, 7502), 1), ((12608, 7502), 1), ((48, 7502), 2)],
        ),
        (
            "same_ports_nonlegacy.pcap",
            &[((16640, 7502), 2), ((48, 7502), 2)],
        ),
        ("duplicate_id.pcap", &[((8448, 34636), 1)]),
        ("VLI-16-one-packet.pcap", &[((1212, 0), 1)]),
        ("empty_pcap.pcap", &[]),
    ];
    for (file, want) in cases {
        let (counts, sources, stats) = census(&dir.join(file));
        // Compare with the port where INVENTORY.md states it.
        let mut got = BTreeMap::new();
        for (&(len, port), &n) in &counts {
            let stated = want.iter().any(|&((l, p), _)| l == len && p == port);
            *got.entry((len, if stated { port } else { 0 })).or_insert(0) += n;
        }
        assert_eq!(got, expect(want), "{file}");
        assert_eq!(stats.malformed, 0, "{file}");
        match *file {
            "same_ports.pcap" | "same_ports_nonlegacy.pcap" => {
                let mut s = sources.clone();
                s.sort();
                assert_eq!(
                    s,
                    vec![
                        Ipv4Addr::new(169, 254, 92, 158),
                        Ipv4Addr::new(169, 254, 238, 111)
                    ],
                    "{file}"
                );
                assert!(stats.reassembled >= 2, "{file}: {stats:?}");
                assert_eq!(stats.fragments_expired, 0, "{file}");
            }
            "duplicate_id.pcap" => {
                assert_eq!(stats.fragments, 7);
                assert_eq!(stats.reassembled, 1);
                assert_eq!(stats.fragments_expired, 1, "the stale orphan");
                assert_eq!(sources, vec![Ipv4Addr::new(10, 5, 6, 101)]);
            }
            "VLI-16-one-packet.pcap" => {
                assert_eq!(sources, vec![Ipv4Addr::new(192, 168, 1, 200)]);
                // "one 1212-byte payload from 192.168.1.200:2369"
                let mut source = PcapSource::open(&dir.join(file)).unwrap();
                let d = source.next_datagram().unwrap().unwrap();
                assert_eq!(
                    d.src,
                    SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 200), 2369)
                );
            }
            "empty_pcap.pcap" => assert_eq!(stats.records, 0),
            _ => {}
        }
    }
    // The fragment counts INVENTORY.md gives for the raw captures.
    for (file, fragments) in [("same_ports.pcap", 21), ("same_ports_nonlegacy.pcap", 24)] {
        let (_, _, stats) = census(&dir.join(file));
        assert_eq!(stats.fragments, fragments, "{file}");
    }
}

// ----- read ahead -----------------------------------------------------------------------------

/// The same file through [`PcapSource::read_ahead`]: records parsed inside the reading
/// thread's blocks, the ones that straddle two blocks copied.
fn read_ahead_bytes(file: Vec<u8>) -> (Vec<Got>, SourceStats) {
    let ahead = ReadAhead::spawn(Cursor::new(file), "test-read-ahead").expect("thread");
    read_all(PcapSource::<Cursor<Vec<u8>>>::read_ahead(ahead).expect("valid header"))
}

/// Over three blocks of records of every size (whole, fragmented, not UDP, cut short by the
/// snaplen), so that records straddle each block boundary at varied offsets.
fn many_records() -> Vec<u8> {
    let mut recs = Vec::new();
    let mut bytes = 0;
    let mut i = 0usize;
    while bytes < 3 * BLOCK + 100_000 {
        let (src, dst, _) = sample(i);
        let payload = pattern(1 + (i * 7919) % 9000, i as u8);
        let t = 1_700_000_000_000_000_000 + i as i64 * 1000;
        match i % 11 {
            3 => {
                for f in fragments(src, dst, i as u16, &payload, 1480) {
                    recs.push(rec(t, ethernet(&f, &[])));
                }
            }
            7 => recs.push(rec(t, ethernet_type(0x0806, &pattern(28, 1)))),
            9 => {
                let mut r = rec(t, ethernet(&udp_ipv4(src, dst, i as u16, &payload), &[]));
                let keep = r.data.len() / 2;
                r.origlen = Some(r.data.len() as u32);
                r.data.truncate(keep);
                recs.push(r);
            }
            _ => recs.push(rec(
                t,
                ethernet(&udp_ipv4(src, dst, i as u16, &payload), &[]),
            )),
        }
        bytes = recs.iter().map(|r| r.data.len() + 16).sum::<usize>();
        i += 1;
    }
    classic(false, true, 1, &recs)
}

#[test]
fn read_ahead_gives_the_datagrams_and_counts_of_the_record_buffer() {
    let file = many_records();
    let (want, want_stats) = read_bytes(&file);
    assert!(want.len() > 500 && want_stats.reassembled > 0 && want_stats.non_udp > 0);
    assert!(want_stats.truncated_records > 0, "{want_stats:?}");
    let (got, got_stats) = read_ahead_bytes(file.clone());
    assert_eq!(got_stats, want_stats);
    assert!(got == want, "datagrams differ");
    // A file cut anywhere (inside a record header, a body, at a block boundary) ends the same
    // way: the same datagrams, the same truncated tail.
    for cut in [
        BLOCK - 7,
        BLOCK,
        BLOCK + 9,
        2 * BLOCK + 3333,
        file.len() - 1,
        30,
    ] {
        let part = file[..cut].to_vec();
        let (want, want_stats) = read_bytes(&part);
        let (got, got_stats) = read_ahead_bytes(part);
        assert_eq!(got_stats, want_stats, "cut at {cut}");
        assert!(got == want, "cut at {cut}: datagrams differ");
    }
}

#[test]
fn read_ahead_reads_pcapng_through_its_copies() {
    let (src, dst, payload) = sample(3);
    let mut blocks = vec![Ng::Shb { big: false }, idb(1)];
    for i in 0..400u64 {
        let data = ethernet(
            &udp_ipv4(src, dst, i as u16, &payload[..(i as usize % 100) + 1]),
            &[],
        );
        blocks.push(epb(0, 1_000_000 + i, data));
    }
    let file = pcapng(&blocks);
    let (want, want_stats) = read_bytes(&file);
    assert_eq!(want.len(), 400);
    let (got, got_stats) = read_ahead_bytes(file);
    assert_eq!(got_stats, want_stats);
    assert!(got == want);
}

#[test]
fn read_ahead_equals_the_record_buffer_on_every_real_capture() {
    let Some(dir) = captures() else { return };
    let mut files = Vec::new();
    let mut stack = vec![dir];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "pcap" || x == "pcapng") {
                files.push(p);
            }
        }
    }
    files.sort();
    assert!(files.len() >= 20, "{} captures", files.len());
    for p in &files {
        let Ok(source) = PcapSource::open(p) else {
            continue; // the hostile ones are refused at the header either way
        };
        let (want, want_stats) = read_all(source);
        let file = std::fs::File::open(p).unwrap();
        let ahead = ReadAhead::spawn(file, "test-read-ahead").unwrap();
        let (got, got_stats) = read_all(PcapSource::<std::fs::File>::read_ahead(ahead).unwrap());
        assert_eq!(got_stats, want_stats, "{}", p.display());
        assert!(got == want, "{}: datagrams differ", p.display());
    }
}
