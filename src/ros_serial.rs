#![cfg_attr(not(all(feature = "bag", feature = "mcap")), allow(dead_code))]
//! ROS message bytes read back field by field, for the bag reader (`source::bag::messages`:
//! packets out of recorded messages) and for `render` (`sink::read`: the clouds and markers of
//! a `--format ros2` file). One reader, so that both apply the same alignment and the same
//! bounds.
//!
//! ROS 1 serialization: little-endian, no padding, `time` = u32 sec + u32 nsec, Header = u32
//! seq + time + string, strings and sequences prefixed by a u32 count. CDR (ROS 2): a 4-byte
//! encapsulation header (`00 01` little-endian, `00 00` big-endian), then every primitive
//! aligned to its size counted from the end of that header; `builtin_interfaces/Time` = i32 sec
//! + u32 nanosec; Header = Time + string; strings carry their NUL in the count.
//!
//! Every read is bounded by the message: a field past its end is a [`Fault`], never a panic,
//! and a sequence count is checked against the bytes left before a caller allocates for it.

/// Why a message could not be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Fault {
    /// The message ends before a field.
    Short {
        /// Offset of the field.
        offset: usize,
        /// Bytes the field needs.
        need: usize,
        /// Message length.
        len: usize,
    },
    /// A CDR encapsulation header other than plain CDR (big or little endian).
    Encapsulation(u16),
    /// A sequence count that its elements could not fit in the bytes left, or above the
    /// caller's limit.
    Count(u64),
    /// Bytes left over after the last field (a layout that does not fit the type).
    Trailing {
        /// Bytes left.
        extra: usize,
    },
}

/// A `std_msgs/Header`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Header<'a> {
    /// The stamp, ns since the Unix epoch.
    pub stamp_ns: i64,
    /// `frame_id`'s bytes, without CDR's NUL.
    pub frame_id: &'a [u8],
}

/// A cursor over one message's bytes (rustls' `Reader` pattern: every read checked).
pub(crate) struct Cursor<'a> {
    buf: &'a [u8],
    at: usize,
    /// CDR: offsets are aligned relative to this (the end of the encapsulation header).
    origin: usize,
    /// CDR (alignment on, signed seconds, NUL-terminated strings) rather than ROS 1.
    cdr: bool,
    big_endian: bool,
}

impl<'a> Cursor<'a> {
    /// A ROS 1 message.
    pub fn ros1(buf: &'a [u8]) -> Self {
        Self {
            buf,
            at: 0,
            origin: 0,
            cdr: false,
            big_endian: false,
        }
    }

    /// A CDR message, from its encapsulation header.
    pub fn cdr(buf: &'a [u8]) -> Result<Self, Fault> {
        let head = buf.get(..4).ok_or(Fault::Short {
            offset: 0,
            need: 4,
            len: buf.len(),
        })?;
        let big_endian = match u16::from_be_bytes([head[0], head[1]]) {
            0x0000 => true,
            0x0001 => false,
            k => return Err(Fault::Encapsulation(k)),
        };
        Ok(Self {
            buf,
            at: 4,
            origin: 4,
            cdr: true,
            big_endian,
        })
    }

    /// The offset of the next byte to read.
    pub fn at(&self) -> usize {
        self.at
    }

    fn align_to(&mut self, n: usize) {
        if self.cdr {
            let rel = self.at - self.origin;
            self.at = self.at.saturating_add((n - rel % n) % n);
        }
    }

    /// The next `n` bytes, unaligned.
    pub fn take(&mut self, n: usize) -> Result<&'a [u8], Fault> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.buf.len());
        match end {
            Some(end) => {
                let s = &self.buf[self.at..end];
                self.at = end;
                Ok(s)
            }
            None => Err(Fault::Short {
                offset: self.at,
                need: n,
                len: self.buf.len(),
            }),
        }
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], Fault> {
        self.align_to(N);
        let mut a = [0; N];
        a.copy_from_slice(self.take(N)?);
        if self.big_endian {
            a.reverse();
        }
        Ok(a)
    }

    pub fn u8(&mut self) -> Result<u8, Fault> {
        Ok(self.take(1)?[0])
    }

    pub fn u32(&mut self) -> Result<u32, Fault> {
        self.array().map(u32::from_le_bytes)
    }

    pub fn u64(&mut self) -> Result<u64, Fault> {
        self.array().map(u64::from_le_bytes)
    }

    pub fn f32(&mut self) -> Result<f32, Fault> {
        self.u32().map(f32::from_bits)
    }

    pub fn f64(&mut self) -> Result<f64, Fault> {
        self.u64().map(f64::from_bits)
    }

    /// `N` consecutive `float64`s (a `Vector3`, a `Pose`, a covariance).
    pub fn f64s<const N: usize>(&mut self) -> Result<[f64; N], Fault> {
        let mut v = [0.0; N];
        for x in &mut v {
            *x = self.f64()?;
        }
        Ok(v)
    }

    /// `time` (ROS 1: u32 sec) / `builtin_interfaces/Time` (CDR: i32 sec), as ns.
    pub fn time(&mut self) -> Result<i64, Fault> {
        let sec = self.u32()?;
        let nsec = self.u32()?;
        let sec = if self.cdr {
            i64::from(sec as i32)
        } else {
            i64::from(sec)
        };
        Ok(sec
            .saturating_mul(1_000_000_000)
            .saturating_add(i64::from(nsec)))
    }

    /// A `uint8[]` (or a string with its NUL): its byte range in the message, (start, len).
    pub fn bytes(&mut self) -> Result<(usize, usize), Fault> {
        let n = self.u32()? as usize;
        let start = self.at;
        self.take(n)?;
        Ok((start, n))
    }

    /// A string's bytes, without CDR's terminating NUL.
    pub fn string(&mut self) -> Result<&'a [u8], Fault> {
        let (start, len) = self.bytes()?;
        let s = &self.buf[start..start + len];
        Ok(match s.split_last() {
            Some((0, head)) if self.cdr => head,
            _ => s,
        })
    }

    /// A `std_msgs/Header` (ROS 1's `seq` read past).
    pub fn header(&mut self) -> Result<Header<'a>, Fault> {
        if !self.cdr {
            self.u32()?; // seq
        }
        let stamp_ns = self.time()?;
        let frame_id = self.string()?;
        Ok(Header { stamp_ns, frame_id })
    }

    /// The element count of a sequence whose elements take at least `min_elem` bytes, at most
    /// `max`: a count the message cannot hold is refused before anything is allocated for it.
    pub fn count(&mut self, min_elem: usize, max: usize) -> Result<usize, Fault> {
        let n = u64::from(self.u32()?);
        let left = self.buf.len().saturating_sub(self.at) as u64;
        if n > max as u64 || n.saturating_mul(min_elem.max(1) as u64) > left {
            return Err(Fault::Count(n));
        }
        Ok(n as usize)
    }

    /// Whether the message was read to its end. CDR writers may pad the end to a multiple of 4
    /// (rosbag2's serializers do not, but some DDS ones do): up to 3 zero bytes are accepted.
    pub fn end(&self) -> Result<(), Fault> {
        let rest = self.buf.get(self.at..).unwrap_or_default();
        let pad_ok = self.cdr && rest.len() < 4 && rest.iter().all(|&b| b == 0);
        if rest.is_empty() || pad_ok {
            Ok(())
        } else {
            Err(Fault::Trailing { extra: rest.len() })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-laid bytes: alignment counts from the end of the encapsulation header, and a
    /// big-endian message reads the same values as its little-endian twin.
    #[test]
    fn cdr_alignment_and_both_byte_orders() {
        for big in [false, true] {
            let mut m = vec![0, u8::from(!big), 0, 0];
            m.push(7); // u8 at body offset 0
            m.extend([0; 3]); // pad to 4
            let w32 = |v: u32| {
                if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                }
            };
            m.extend(w32(0xdead_beef)); // u32 at 4
            let f = 2.5f64.to_bits();
            m.extend(if big {
                f.to_be_bytes()
            } else {
                f.to_le_bytes()
            }); // f64 at 8
            m.extend(w32(3));
            m.extend(b"ab\0");
            let mut c = Cursor::cdr(&m).unwrap();
            assert_eq!(c.u8(), Ok(7));
            assert_eq!(c.u32(), Ok(0xdead_beef));
            assert_eq!(c.f64(), Ok(2.5));
            assert_eq!(c.string(), Ok(&b"ab"[..]));
            assert_eq!(c.end(), Ok(()));
        }
    }

    #[test]
    fn ros1_has_no_padding_and_keeps_the_whole_string() {
        let mut m = vec![7u8];
        m.extend(0x0102_0304u32.to_le_bytes());
        m.extend(2u32.to_le_bytes());
        m.extend(b"a\0");
        let mut c = Cursor::ros1(&m);
        assert_eq!(c.u8(), Ok(7));
        assert_eq!(c.u32(), Ok(0x0102_0304));
        assert_eq!(c.string(), Ok(&b"a\0"[..]));
        assert_eq!(c.end(), Ok(()));
    }

    #[test]
    fn faults_not_panics() {
        assert_eq!(
            Cursor::cdr(&[0, 2, 0, 0]).err(),
            Some(Fault::Encapsulation(2))
        );
        assert!(matches!(Cursor::cdr(&[0, 1]), Err(Fault::Short { .. })));
        let m = [0, 1, 0, 0, 0xff, 0xff, 0xff, 0xff];
        assert_eq!(
            Cursor::cdr(&m).unwrap().count(1, usize::MAX),
            Err(Fault::Count(u32::MAX.into()))
        );
        assert!(matches!(
            Cursor::cdr(&m).unwrap().bytes(),
            Err(Fault::Short { .. })
        ));
        let mut c = Cursor::cdr(&m).unwrap();
        c.u8().unwrap();
        assert_eq!(c.end(), Err(Fault::Trailing { extra: 3 }));
        let mut c = Cursor::cdr(&[0, 1, 0, 0, 1, 0, 0]).unwrap();
        c.u8().unwrap();
        assert_eq!(c.end(), Ok(()), "CDR's zero padding at the end");
    }
}
