//! Livox packet → points: Cartesian records scaled to metres, spherical records through
//! sin / cos tables built once, the per-point time of each record, the laser line, the tag.
//!
//! Per-point time. SDK2: the timestamp is the first point's; the `N` points of a packet are
//! equally spaced and `time_interval` is the last one's time minus the first's (Mid360
//! protocol §2.2), so record `i` is at `timestamp + i · time_interval / (N − 1)` (integer ns,
//! rounded down). livox_ros_driver2 spaces them by `time_interval / N` instead, which puts the
//! last point up to one spacing early; ringscan follows the protocol text. SDK1: record `i` at
//! `timestamp + i · point_interval` of the model (livox_ros_driver's table). The returns of one
//! record (dual / triple) share its time.
//!
//! Line: record `i` of a packet is on line `i % lines` (livox_ros_driver / driver2 rule), and
//! that is the point's `ring`. For these scanners it is the laser line, not an elevation rank.
//! Tag: the record's tag byte goes into [`Point::pad`] (0 where the record has none).

use super::wire::{read_angles, read_return, Record};
use crate::point::Point;
use crate::sensor::DecodeOptions;

/// Decodes the point records of one packet.
#[derive(Clone, Debug)]
pub struct LivoxDecoder {
    lines: u16,
    range: DecodeOptions,
    /// sin and cos of k · 0.01°, k = 0..=36000.
    trig: Vec<(f32, f32)>,
}

/// What one packet gave.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PacketPoints {
    /// Points appended.
    pub points: usize,
    /// Time of the last record, ns (device clock).
    pub last_ns: i64,
}

impl LivoxDecoder {
    /// A decoder for a sensor with `lines` laser lines (at least 1).
    pub fn new(lines: u16, range: DecodeOptions) -> Self {
        let trig = (0..=36_000u32)
            .map(|k| {
                let a = (f64::from(k) * 0.01).to_radians();
                (a.sin() as f32, a.cos() as f32)
            })
            .collect();
        Self {
            lines: lines.max(1),
            range,
            trig,
        }
    }

    /// Laser lines.
    pub fn lines(&self) -> u16 {
        self.lines
    }

    #[inline]
    fn sc(&self, cdeg: u16) -> (f32, f32) {
        self.trig
            .get(usize::from(cdeg))
            .copied()
            .unwrap_or((0.0, 1.0))
    }

    /// Appends the points of `records` records read by `rec(i)` of layout `kind`; record `i`
    /// is at `first_ns + time(i)` (device ns), and `t` is measured from `sweep_start_ns`.
    #[allow(clippy::too_many_arguments)]
    pub fn decode<'a>(
        &self,
        kind: Record,
        records: usize,
        rec: impl Fn(usize) -> &'a [u8],
        first_ns: i64,
        time: impl Fn(usize) -> i64,
        sweep_start_ns: i64,
        out: &mut Vec<Point>,
    ) -> PacketPoints {
        let before = out.len();
        let (cm, spherical) = match kind {
            Record::Imu => return PacketPoints::default(),
            Record::CartesianCmTag => (true, false),
            Record::Spherical | Record::SphericalTag | Record::MultiSpherical(_) => (false, true),
            _ => (false, false),
        };
        let scale = if cm { 0.01f32 } else { 0.001f32 };
        let (min2, max2) = (
            self.range.min_range * self.range.min_range,
            self.range.max_range * self.range.max_range,
        );
        let mut last = first_ns;
        for i in 0..records {
            let r = rec(i);
            let at = first_ns.saturating_add(time(i));
            last = at;
            let t = u32::try_from(at.saturating_sub(sweep_start_ns).max(0)).unwrap_or(u32::MAX);
            let ring = (i % usize::from(self.lines)) as u16;
            let (st, ct, sp, cp) = if spherical {
                let (theta, phi) = read_angles(r, kind);
                let (st, ct) = self.sc(theta.min(18_000));
                let (sp, cp) = self.sc(phi.min(36_000));
                (st, ct, sp, cp)
            } else {
                (0.0, 0.0, 0.0, 0.0)
            };
            for k in 0..kind.returns() {
                let raw = read_return(r, kind, k);
                let (x, y, z) = if spherical {
                    if raw.xyz[0] == 0 {
                        continue;
                    }
                    let d = raw.xyz[0] as f32 * 0.001;
                    (d * st * cp, d * st * sp, d * ct)
                } else {
                    if raw.xyz == [0, 0, 0] {
                        continue;
                    }
                    (
                        raw.xyz[0] as f32 * scale,
                        raw.xyz[1] as f32 * scale,
                        raw.xyz[2] as f32 * scale,
                    )
                };
                let d2 = x * x + y * y + z * z;
                if d2 < min2 || d2 > max2 {
                    continue;
                }
                out.push(Point {
                    x,
                    y,
                    z,
                    intensity: f32::from(raw.reflectivity),
                    t,
                    ring,
                    ret: k as u8,
                    pad: raw.tag,
                });
            }
        }
        PacketPoints {
            points: out.len() - before,
            last_ns: last,
        }
    }
}

/// SDK2 time of record `i` of `n` after the first, ns.
#[inline]
pub fn sdk2_offset_ns(i: usize, n: usize, interval_ns: u64) -> i64 {
    if n < 2 {
        return 0;
    }
    ((i as u64).saturating_mul(interval_ns) / (n as u64 - 1)) as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sdk2_offsets_span_the_interval() {
        assert_eq!(sdk2_offset_ns(0, 96, 47_500), 0);
        assert_eq!(sdk2_offset_ns(95, 96, 47_500), 47_500);
        assert_eq!(sdk2_offset_ns(1, 96, 47_500), 500);
        assert_eq!(sdk2_offset_ns(0, 1, 47_500), 0);
    }
}
