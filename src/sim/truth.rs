//! The simulator's per-point truth file: a 16-byte header and fixed 40-byte little-endian
//! records, one per simulated return, in the order the packets carry them.
//!
//! ```text
//! header  0  8  magic "RSTRUTH1"
//!         8  4  u32 record size (40)
//!        12  4  u32 reserved (0)
//! record  0 12  sensor-frame x, y, z, f32 m — the point in the sensor frame at its firing
//!               time (what a decoder must reproduce, before range quantisation)
//!        12 12  world x, y, z, f32 m — the same point in the world frame
//!        24  8  i64 firing time, ns on the simulator's clock (the pose is the trajectory's
//!               at this time; `--poses-out` of `tools/simulate.rs` writes it)
//!        32  4  u32 label: 0 = ground, else the object id
//!        36  2  u16 channel: Velodyne laser id / Ouster pixel row (0 = top beam)
//!        38  1  u8 ring (0 = lowest beam, as ringscan numbers rings)
//!        39  1  u8 return (0 = strongest / first, 1 = last / second)
//! ```
//!
//! ```
//! use ringscan::sim::truth::{TruthReader, TruthRecord, TruthWriter};
//! let r = TruthRecord { sensor: [1.0, 2.0, 3.0], world: [4.0, 5.0, 6.0], time_ns: 7,
//!     label: 0, channel: 3, ring: 9, ret: 0 };
//! let mut w = TruthWriter::new(Vec::new()).unwrap();
//! w.write(&r).unwrap();
//! let bytes = w.into_inner().unwrap();
//! let back: Vec<TruthRecord> = TruthReader::new(&bytes[..]).unwrap()
//!     .collect::<Result<_, _>>().unwrap();
//! assert_eq!(back, vec![r]);
//! ```

use std::io::{self, Read, Write};

/// File magic.
pub const MAGIC: &[u8; 8] = b"RSTRUTH1";
/// Bytes per record.
pub const RECORD_BYTES: usize = 40;
/// Bytes of the header.
pub const HEADER_BYTES: usize = 16;

/// One simulated return.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruthRecord {
    /// Sensor-frame point at the firing time, metres.
    pub sensor: [f32; 3],
    /// World point, metres.
    pub world: [f32; 3],
    /// Firing time, ns on the simulator's clock.
    pub time_ns: i64,
    /// 0 = ground, else the object id.
    pub label: u32,
    /// Velodyne laser id / Ouster pixel row.
    pub channel: u16,
    /// Ring (0 = lowest beam).
    pub ring: u8,
    /// Return (0 first / strongest, 1 second / last).
    pub ret: u8,
}

fn f32s(v: [f64; 3]) -> [f32; 3] {
    v.map(|x| x as f32)
}

impl TruthRecord {
    /// The record of a Velodyne measurement (`ring` from `calib.rings()[laser]`).
    pub fn from_velodyne(t: &crate::sensor::velodyne::sim::Truth, ring: u16) -> Self {
        Self {
            sensor: f32s(t.xyz),
            world: f32s(t.world),
            time_ns: t.time_ns,
            label: t.label,
            channel: t.laser as u16,
            ring: ring.min(255) as u8,
            ret: t.ret,
        }
    }

    /// The record of an Ouster return (`ring` from the decoder's `rings()[row]`).
    pub fn from_ouster(t: &crate::sensor::ouster::sim::OusterTruth, ring: u16) -> Self {
        Self {
            sensor: f32s(t.xyz),
            world: f32s(t.world),
            time_ns: t.time_ns,
            label: t.label,
            channel: t.row,
            ring: ring.min(255) as u8,
            ret: t.ret,
        }
    }

    /// The 40 bytes of the record.
    pub fn to_bytes(&self) -> [u8; RECORD_BYTES] {
        let mut b = [0u8; RECORD_BYTES];
        for (i, v) in self.sensor.iter().chain(&self.world).enumerate() {
            b[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
        }
        b[24..32].copy_from_slice(&self.time_ns.to_le_bytes());
        b[32..36].copy_from_slice(&self.label.to_le_bytes());
        b[36..38].copy_from_slice(&self.channel.to_le_bytes());
        b[38] = self.ring;
        b[39] = self.ret;
        b
    }

    /// A record from its 40 bytes.
    pub fn from_bytes(b: &[u8; RECORD_BYTES]) -> Self {
        let f = |i: usize| f32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        let mut t = [0u8; 8];
        t.copy_from_slice(&b[24..32]);
        Self {
            sensor: [f(0), f(4), f(8)],
            world: [f(12), f(16), f(20)],
            time_ns: i64::from_le_bytes(t),
            label: u32::from_le_bytes([b[32], b[33], b[34], b[35]]),
            channel: u16::from_le_bytes([b[36], b[37]]),
            ring: b[38],
            ret: b[39],
        }
    }
}

/// Writes a truth file.
#[derive(Debug)]
pub struct TruthWriter<W: Write> {
    w: W,
}

impl<W: Write> TruthWriter<W> {
    /// Writes the header.
    pub fn new(mut w: W) -> io::Result<Self> {
        w.write_all(MAGIC)?;
        w.write_all(&(RECORD_BYTES as u32).to_le_bytes())?;
        w.write_all(&0u32.to_le_bytes())?;
        Ok(Self { w })
    }

    /// Appends a record.
    pub fn write(&mut self, r: &TruthRecord) -> io::Result<()> {
        self.w.write_all(&r.to_bytes())
    }

    /// Flushes and returns the writer.
    pub fn into_inner(mut self) -> io::Result<W> {
        self.w.flush()?;
        Ok(self.w)
    }
}

/// Reads a truth file record by record (memory stays bounded); an iterator of records.
#[derive(Debug)]
pub struct TruthReader<R: Read> {
    r: R,
    done: bool,
}

impl<R: Read> TruthReader<R> {
    /// Reads and checks the header.
    pub fn new(mut r: R) -> io::Result<Self> {
        let mut h = [0u8; HEADER_BYTES];
        r.read_exact(&mut h)?;
        let size = u32::from_le_bytes([h[8], h[9], h[10], h[11]]);
        if &h[..8] != MAGIC || size as usize != RECORD_BYTES {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                "not a ringscan truth file (magic RSTRUTH1, 40-byte records)",
            ));
        }
        Ok(Self { r, done: false })
    }
}

impl<R: Read> Iterator for TruthReader<R> {
    type Item = io::Result<TruthRecord>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let mut b = [0u8; RECORD_BYTES];
        let mut got = 0;
        while got < RECORD_BYTES {
            match self.r.read(&mut b[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => {
                    self.done = true;
                    return Some(Err(e));
                }
            }
        }
        if got == 0 {
            self.done = true;
            return None;
        }
        if got < RECORD_BYTES {
            self.done = true;
            return Some(Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "truncated truth record",
            )));
        }
        Some(Ok(TruthRecord::from_bytes(&b)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_files_are_errors_not_panics() {
        assert!(TruthReader::new(&b"RSTRUTH1"[..]).is_err());
        assert!(TruthReader::new(&b"XXXXXXXX\x28\0\0\0\0\0\0\0"[..]).is_err());
        let mut f = b"RSTRUTH1\x28\0\0\0\0\0\0\0".to_vec();
        f.extend_from_slice(&[0u8; 41]);
        let recs: Vec<_> = TruthReader::new(&f[..]).unwrap().collect();
        assert_eq!(recs.len(), 2);
        assert!(recs[0].is_ok() && recs[1].is_err());
    }

    #[test]
    fn layout_is_the_documented_one() {
        let r = TruthRecord {
            sensor: [1.0, 0.0, 0.0],
            world: [0.0; 3],
            time_ns: -2,
            label: 0x0102_0304,
            channel: 0x0506,
            ring: 7,
            ret: 1,
        };
        let b = r.to_bytes();
        assert_eq!(&b[0..4], &1f32.to_le_bytes());
        assert_eq!(&b[24..32], &(-2i64).to_le_bytes());
        assert_eq!(&b[32..40], &[4, 3, 2, 1, 6, 5, 7, 1]);
    }
}
