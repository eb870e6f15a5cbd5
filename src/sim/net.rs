//! Ethernet / IPv4 / UDP framing and a classic pcap writer, for fixtures and the simulator.

use std::io::{self, Write};
use std::net::SocketAddrV4;

/// An Ethernet II + IPv4 + UDP frame around `payload` (no fragmentation; payload ≤ 65507 B).
/// The IPv4 header checksum is valid; the UDP checksum is 0 (optional in IPv4).
pub fn udp_frame(src: SocketAddrV4, dst: SocketAddrV4, ip_id: u16, payload: &[u8]) -> Vec<u8> {
    let udp_len = (8 + payload.len()).min(usize::from(u16::MAX)) as u16;
    let ip_len = 20u16.saturating_add(udp_len);
    let mut f = Vec::with_capacity(14 + usize::from(ip_len));
    f.extend_from_slice(&[0x60, 0x76, 0x88, 0x00, 0x00, 0x01]); // dst MAC
    f.extend_from_slice(&[0x60, 0x76, 0x88, 0x10, 0x20, 0x30]); // src MAC (Velodyne OUI)
    f.extend_from_slice(&[0x08, 0x00]);
    let mut ip = [0u8; 20];
    ip[0] = 0x45;
    ip[2..4].copy_from_slice(&ip_len.to_be_bytes());
    ip[4..6].copy_from_slice(&ip_id.to_be_bytes());
    ip[6] = 0x40; // don't fragment
    ip[8] = 64;
    ip[9] = 17;
    ip[12..16].copy_from_slice(&src.ip().octets());
    ip[16..20].copy_from_slice(&dst.ip().octets());
    let mut sum: u32 = ip
        .chunks_exact(2)
        .map(|w| u32::from(u16::from_be_bytes([w[0], w[1]])))
        .sum();
    while sum > 0xFFFF {
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    ip[10..12].copy_from_slice(&(!(sum as u16)).to_be_bytes());
    f.extend_from_slice(&ip);
    f.extend_from_slice(&src.port().to_be_bytes());
    f.extend_from_slice(&dst.port().to_be_bytes());
    f.extend_from_slice(&udp_len.to_be_bytes());
    f.extend_from_slice(&[0, 0]);
    f.extend_from_slice(payload);
    f
}

/// Writes a classic little-endian pcap with nanosecond timestamps and Ethernet link type.
#[derive(Debug)]
pub struct PcapWriter<W: Write> {
    w: W,
}

impl<W: Write> PcapWriter<W> {
    /// Writes the file header.
    pub fn new(mut w: W) -> io::Result<Self> {
        w.write_all(&0xa1b2_3c4du32.to_le_bytes())?;
        w.write_all(&2u16.to_le_bytes())?;
        w.write_all(&4u16.to_le_bytes())?;
        w.write_all(&0i32.to_le_bytes())?;
        w.write_all(&0u32.to_le_bytes())?;
        w.write_all(&65_535u32.to_le_bytes())?;
        w.write_all(&1u32.to_le_bytes())?;
        Ok(Self { w })
    }

    /// Writes one record with capture time `time_ns` (ns since the epoch).
    pub fn write(&mut self, time_ns: i64, frame: &[u8]) -> io::Result<()> {
        let t = time_ns.max(0);
        let secs = (t / 1_000_000_000) as u32;
        let ns = (t % 1_000_000_000) as u32;
        let len = frame.len() as u32;
        self.w.write_all(&secs.to_le_bytes())?;
        self.w.write_all(&ns.to_le_bytes())?;
        self.w.write_all(&len.to_le_bytes())?;
        self.w.write_all(&len.to_le_bytes())?;
        self.w.write_all(frame)
    }

    /// Flushes and returns the writer.
    pub fn into_inner(mut self) -> io::Result<W> {
        self.w.flush()?;
        Ok(self.w)
    }
}
