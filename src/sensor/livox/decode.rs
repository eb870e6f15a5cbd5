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
    /// Records timed inside the window ([`LivoxDecoder::decode_within`]; without one, every
    /// record).
    pub in_window: usize,
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
    /// is at `first_ns + spacing`'s `i`-th offset (device ns), and `t` is measured from
    /// `sweep_start_ns` (clamped to `0..=u32::MAX`).
    #[allow(clippy::too_many_arguments)]
    pub fn decode<'a>(
        &self,
        kind: Record,
        records: usize,
        rec: impl Fn(usize) -> &'a [u8],
        first_ns: i64,
        spacing: Spacing,
        sweep_start_ns: i64,
        out: &mut Vec<Point>,
    ) -> PacketPoints {
        let run = Run::new(records, first_ns, spacing, sweep_start_ns, None);
        self.decode_run(kind, run, rec, out)
    }

    /// As [`Self::decode`], but only the records timed `0..=max_t_ns` after `sweep_start_ns`
    /// give points: a late packet joins a sweep already begun only where its time falls inside
    /// it (a clamped time would put a point at the sweep's start or at `u32::MAX`).
    #[allow(clippy::too_many_arguments)]
    pub fn decode_within<'a>(
        &self,
        kind: Record,
        records: usize,
        rec: impl Fn(usize) -> &'a [u8],
        first_ns: i64,
        spacing: Spacing,
        sweep_start_ns: i64,
        max_t_ns: i64,
        out: &mut Vec<Point>,
    ) -> PacketPoints {
        let run = Run::new(records, first_ns, spacing, sweep_start_ns, Some(max_t_ns));
        self.decode_run(kind, run, rec, out)
    }

    fn decode_run<'a>(
        &self,
        kind: Record,
        run: Run,
        rec: impl Fn(usize) -> &'a [u8],
        out: &mut Vec<Point>,
    ) -> PacketPoints {
        // The Cartesian single-return layouts (every MID-360 / HAP / Avia default) get loops of
        // their own: fixed offsets, no per-record dispatch on the layout.
        match kind {
            Record::CartesianMmTag => self.cartesian(run, rec, out, |r| {
                Some((
                    [i32_le(r, 0)?, i32_le(r, 4)?, i32_le(r, 8)?],
                    0.001,
                    *r.get(12)?,
                    *r.get(13)?,
                ))
            }),
            Record::CartesianCmTag => self.cartesian(run, rec, out, |r| {
                let c = |o| Some(i32::from(i16::from_le_bytes([*r.get(o)?, *r.get(o + 1)?])));
                Some(([c(0)?, c(2)?, c(4)?], 0.01, *r.get(6)?, *r.get(7)?))
            }),
            _ => self.general(kind, run, rec, out),
        }
    }

    /// Single-return Cartesian records: `read` gives (xyz in units, metres per unit,
    /// reflectivity, tag), `None` for a record cut short.
    #[inline(always)]
    fn cartesian<'a>(
        &self,
        run: Run,
        rec: impl Fn(usize) -> &'a [u8],
        out: &mut Vec<Point>,
        read: impl Fn(&[u8]) -> Option<([i32; 3], f32, u8, u8)>,
    ) -> PacketPoints {
        let before = out.len();
        out.reserve(run.records);
        let (min2, max2) = self.range2();
        let mut times = run.spacing.offsets();
        let mut ring = 0u16;
        let mut last = run.first_ns;
        let mut in_window = 0;
        for i in 0..run.records {
            let at = run.first_ns.saturating_add(times.next_offset());
            last = at;
            let this_ring = ring;
            ring += 1;
            if ring == self.lines {
                ring = 0;
            }
            if !run.in_window(at) {
                continue;
            }
            in_window += 1;
            let Some((xyz, scale, reflectivity, tag)) = read(rec(i)) else {
                continue;
            };
            if xyz == [0, 0, 0] {
                continue;
            }
            let (x, y, z) = (
                xyz[0] as f32 * scale,
                xyz[1] as f32 * scale,
                xyz[2] as f32 * scale,
            );
            let d2 = x * x + y * y + z * z;
            if d2 < min2 || d2 > max2 {
                continue;
            }
            out.push(Point {
                x,
                y,
                z,
                intensity: f32::from(reflectivity),
                t: rel_t(at, run.sweep_start_ns),
                ring: this_ring,
                ret: 0,
                pad: tag,
            });
        }
        PacketPoints {
            points: out.len() - before,
            last_ns: last,
            in_window,
        }
    }

    fn range2(&self) -> (f32, f32) {
        (
            self.range.min_range * self.range.min_range,
            self.range.max_range * self.range.max_range,
        )
    }

    /// Every other layout: spherical (through the tables), multi-return, SDK1 type 0.
    fn general<'a>(
        &self,
        kind: Record,
        run: Run,
        rec: impl Fn(usize) -> &'a [u8],
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
        let (min2, max2) = self.range2();
        let mut times = run.spacing.offsets();
        let mut last = run.first_ns;
        let mut in_window = 0;
        for i in 0..run.records {
            let r = rec(i);
            let at = run.first_ns.saturating_add(times.next_offset());
            last = at;
            if !run.in_window(at) {
                continue;
            }
            in_window += 1;
            let t = rel_t(at, run.sweep_start_ns);
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
            in_window,
        }
    }
}

/// One packet's records: how many, the first one's time, their spacing, the sweep's start,
/// and the latest `t` a record may have (`None`: any, clamped).
#[derive(Clone, Copy)]
struct Run {
    records: usize,
    first_ns: i64,
    spacing: Spacing,
    sweep_start_ns: i64,
    max_t_ns: Option<i64>,
}

impl Run {
    fn new(
        records: usize,
        first_ns: i64,
        spacing: Spacing,
        sweep_start_ns: i64,
        max_t_ns: Option<i64>,
    ) -> Self {
        Self {
            records,
            first_ns,
            spacing,
            sweep_start_ns,
            max_t_ns,
        }
    }

    /// Whether a record at device time `at` gives a point.
    #[inline(always)]
    fn in_window(&self, at: i64) -> bool {
        self.max_t_ns
            .is_none_or(|max| (0..=max).contains(&at.saturating_sub(self.sweep_start_ns)))
    }
}

/// `t` of a point at device time `at` in a sweep that started at `start` (clamped to u32).
#[inline]
fn rel_t(at: i64, start: i64) -> u32 {
    u32::try_from(at.saturating_sub(start).max(0)).unwrap_or(u32::MAX)
}

#[inline]
fn i32_le(r: &[u8], o: usize) -> Option<i32> {
    Some(i32::from_le_bytes(r.get(o..o + 4)?.try_into().ok()?))
}

/// The times of a packet's records after its first: record `i` at `⌊i · num / den⌋` ns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Spacing {
    num: u64,
    den: u64,
}

impl Spacing {
    /// SDK2: `n` records spread over `interval_ns` from the first to the last
    /// ([`sdk2_offset_ns`]).
    pub fn sdk2(n: usize, interval_ns: u64) -> Self {
        if n < 2 {
            return Self { num: 0, den: 1 };
        }
        Self {
            num: interval_ns,
            den: n as u64 - 1,
        }
    }

    /// A fixed step between records (SDK1), ns.
    pub fn step(step_ns: u64) -> Self {
        Self {
            num: step_ns,
            den: 1,
        }
    }

    /// The offsets 0, ⌊num/den⌋, ⌊2·num/den⌋, … computed by steps, without a division per
    /// record.
    fn offsets(self) -> Offsets {
        let den = self.den.max(1);
        Offsets {
            q: self.num / den,
            r: self.num % den,
            den,
            acc_q: 0,
            acc_r: 0,
        }
    }
}

struct Offsets {
    q: u64,
    r: u64,
    den: u64,
    acc_q: u64,
    acc_r: u64,
}

impl Offsets {
    /// This record's offset, then step to the next.
    #[inline(always)]
    fn next_offset(&mut self) -> i64 {
        let v = self.acc_q;
        self.acc_q = self.acc_q.saturating_add(self.q);
        self.acc_r += self.r;
        if self.acc_r >= self.den {
            self.acc_r -= self.den;
            self.acc_q = self.acc_q.saturating_add(1);
        }
        i64::try_from(v).unwrap_or(i64::MAX)
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
    fn stepped_offsets_equal_the_division() {
        for (n, iv) in [
            (96usize, 47_500u64),
            (100, 6_553_500),
            (2, 1),
            (1, 5),
            (97, 0),
            (1440, 99_999),
        ] {
            let mut o = Spacing::sdk2(n, iv).offsets();
            for i in 0..n {
                assert_eq!(
                    o.next_offset(),
                    sdk2_offset_ns(i, n, iv),
                    "record {i} of {n}"
                );
            }
        }
        let mut o = Spacing::step(4_167).offsets();
        for i in 0..100 {
            assert_eq!(o.next_offset(), 4_167 * i);
        }
    }

    #[test]
    fn a_window_keeps_the_records_timed_inside_it() {
        // Five records 10 ns apart, the first 15 ns before the sweep's start: at -15, -5, 5,
        // 15, 25 ns after it.
        let rec: Vec<u8> = [1000i32, 0, 0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .chain([7, 0])
            .collect();
        let d = LivoxDecoder::new(1, DecodeOptions::default());
        let mut out = Vec::new();
        let (kind, step) = (Record::CartesianMmTag, Spacing::step(10));
        let got = d.decode_within(kind, 5, |_| &rec, 100, step, 115, 20, &mut out);
        assert_eq!((got.points, got.in_window, got.last_ns), (2, 2, 140));
        assert_eq!(out.iter().map(|p| p.t).collect::<Vec<_>>(), [5, 15]);
        // Without a window: every record, times clamped at the sweep's start.
        out.clear();
        let got = d.decode(kind, 5, |_| &rec, 100, step, 115, &mut out);
        assert_eq!((got.points, got.in_window), (5, 5));
        assert_eq!(
            out.iter().map(|p| p.t).collect::<Vec<_>>(),
            [0, 0, 5, 15, 25]
        );
    }

    #[test]
    fn sdk2_offsets_span_the_interval() {
        assert_eq!(sdk2_offset_ns(0, 96, 47_500), 0);
        assert_eq!(sdk2_offset_ns(95, 96, 47_500), 47_500);
        assert_eq!(sdk2_offset_ns(1, 96, 47_500), 500);
        assert_eq!(sdk2_offset_ns(0, 1, 47_500), 0);
    }
}
