//! Cutting the point stream into sweeps, with loss and gap accounting.
//!
//! Knows nothing of how bytes arrived: callers push datagrams with their host receive time.
//! A sweep's timestamp is its first firing, so every point's `t` ≥ 0. Missing packets between
//! two consecutive packets = round(Δ device time / packet period) − 1.

pub mod demux;
pub mod ledger;
pub mod seq;

use crate::point::Point;
use crate::time::ClockSource;

pub use demux::{Demux, DemuxStats, EarlyDatagram, SensorKey};
pub use seq::{RecentTimes, SeqStep, SeqWindow};

/// One sweep: the points of one revolution (or of the sensor's frame), with its times and
/// its packet accounting. Buffers are reused from sweep to sweep.
#[derive(Clone, Debug, Default)]
pub struct Sweep {
    /// Sequence number of the sweep in its stream, from 0.
    pub index: u64,
    /// The points, in the order the sensor measured them.
    pub points: Vec<Point>,
    /// Firing column of each point within the sweep (only when the stream keeps columns).
    pub columns: Vec<u32>,
    /// Extra values of each point (only when the stream keeps them: Ouster `--fields all`).
    pub extras: Vec<crate::point::PointExtra>,
    /// The sweep's timestamp (its first firing) in the clock named by `clock`, ns since the
    /// Unix epoch.
    pub timestamp_ns: i64,
    /// Which clock `timestamp_ns` is in.
    pub clock: ClockSource,
    /// The first firing in the sensor's own clock (top-of-hour completed), ns since the epoch.
    pub device_time_ns: i64,
    /// Host receive time of the first packet of the sweep, ns.
    pub first_host_ns: i64,
    /// Host receive time of the last packet of the sweep, ns (the MCAP log time).
    pub last_host_ns: i64,
    /// Packets that contributed points.
    pub packets: u32,
    /// Packets missing inside the sweep (device-time gaps; Ouster: missing columns of the
    /// column window, in packets, rounded up).
    pub missing_packets: u64,
    /// Ouster: columns of the column window that never arrived valid (0 for Velodyne).
    pub missing_columns: u64,
    /// Ouster: the sensor's frame id (0 for Velodyne).
    pub frame_id: u32,
    /// Firing columns in the sweep (including those of missing packets is not attempted).
    pub columns_count: u32,
    /// Azimuth of the first firing, 0.01°.
    pub first_azimuth: u16,
    /// Azimuth of the last firing, 0.01°.
    pub last_azimuth: u16,
}

impl Sweep {
    /// Empties the sweep, keeping its buffers.
    pub fn clear(&mut self) {
        self.points.clear();
        self.columns.clear();
        self.extras.clear();
        self.packets = 0;
        self.missing_packets = 0;
        self.missing_columns = 0;
        self.columns_count = 0;
    }

    /// This sweep's values with its point buffers moved out, leaving empty buffers of the same
    /// capacity in their place: what a consumer that keeps a sweep handed out by a stream takes
    /// instead of a clone (the stream's next sweep refills the fresh buffers without growing).
    pub fn take_buffers(&mut self) -> Sweep {
        self.take_buffers_with(Vec::new(), Vec::new())
    }

    /// [`Self::take_buffers`], the replacement buffers made from `points` and `columns`
    /// (vectors a consumer gave back, emptied here and grown only if smaller): a steady
    /// stream of handed-out sweeps then reuses the same memory instead of new pages.
    pub fn take_buffers_with(&mut self, mut points: Vec<Point>, mut columns: Vec<u32>) -> Sweep {
        let (np, nc, ne) = (self.points.len(), self.columns.len(), self.extras.len());
        points.clear();
        points.reserve(np);
        columns.clear();
        columns.reserve(nc);
        let points = std::mem::replace(&mut self.points, points);
        let columns = std::mem::replace(&mut self.columns, columns);
        let extras = std::mem::replace(&mut self.extras, Vec::with_capacity(ne));
        Sweep {
            points,
            columns,
            extras,
            ..self.clone()
        }
    }

    /// Whether the sweep holds no packet.
    pub fn is_empty(&self) -> bool {
        self.packets == 0
    }

    /// Duration from the first firing to the last point's firing, ns.
    pub fn span_ns(&self) -> u32 {
        self.points.iter().map(|p| p.t).max().unwrap_or(0)
    }
}

/// What the head did between two consecutive blocks of a spinning sensor, from their azimuth
/// step (see [`azimuth_step`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// A block out of azimuth order (the head did not turn back): no progress.
    Back,
    /// The head turned forward by the step.
    Forward {
        /// At least one whole turn more went by unseen (lost packets): the cut was passed
        /// whatever the two azimuths.
        full_turn: bool,
    },
}

/// Tells a forward turn from a block out of order. `span` is the azimuth step from the last
/// block, `0 ≤ span < turn` (any unit of which `turn` is one turn). Alone, a step of three
/// quarters of a turn or more is a step back. Across packets the caller also gives `turned`,
/// how far the motor turns in the time between them (same unit): lost packets can make a
/// forward step of any size, and the time tells it from a step back and counts the whole
/// turns lost with it.
pub fn azimuth_step(span: i64, turn: i64, turned: Option<i64>) -> Step {
    let Some(turned) = turned else {
        return if span < turn / 4 * 3 {
            Step::Forward { full_turn: false }
        } else {
            Step::Back
        };
    };
    // The rotation the time allows is nearer a step back (span − turn) than a step forward.
    if span >= turn / 4 * 3 && turned < span - turn / 2 {
        return Step::Back;
    }
    // Whole turns beyond the step: the nearest count to what the time allows.
    Step::Forward {
        full_turn: turned.saturating_sub(span) >= turn / 2,
    }
}

/// How far a motor at `rpm` turns in `ns`, in units of which `turn` is one turn (saturating).
pub fn rotation_in(ns: i64, rpm: f64, turn: i64) -> i64 {
    (ns as f64 * rpm / 60e9 * turn as f64) as i64
}

/// The motor speed a sensor reports, if plausible (60 – 3000 rpm), else the usual 600 rpm: a
/// corrupt or missing field must not make [`rotation_in`] read every step as a turn lost.
pub fn motor_rpm_or_nominal(rpm: Option<u16>) -> f64 {
    match rpm {
        Some(r @ 60..=3_000) => f64::from(r),
        _ => 600.0,
    }
}

/// A packet at most this many packets behind the latest is a late one (reordered on the way),
/// not a loss or a new stretch: the window every family's loss counting shares.
pub const REORDER_PACKETS: u16 = 10;

/// A sweep laid out as channel (ring) × column, with a validity mask.
///
/// Row `r` is ring `r` (0 = lowest elevation, the ROS convention); column `c` is the firing
/// column within the sweep. Dual-return sweeps have two layers: `layer 0` = return 0
/// (strongest / only), `layer 1` = return 1 (last).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Organized {
    /// Rings (rows).
    pub rows: usize,
    /// Firing columns.
    pub cols: usize,
    /// Layers (1, or 2 for dual return).
    pub layers: usize,
    /// `layers × rows × cols` points, index `(layer · rows + row) · cols + col`.
    pub points: Vec<Point>,
    /// Whether each cell holds a measured point.
    pub valid: Vec<bool>,
}

impl Organized {
    /// Builds the image of a sweep that kept its columns; `rows` = the sensor's channel count.
    /// Returns `None` when the sweep has no column indices.
    pub fn from_sweep(sweep: &Sweep, rows: usize) -> Option<Self> {
        if sweep.columns.len() != sweep.points.len() {
            return None;
        }
        let cols = sweep
            .columns
            .iter()
            .map(|&c| c as usize + 1)
            .max()
            .unwrap_or(0);
        let layers = if sweep.points.iter().any(|p| p.ret > 0) {
            2
        } else {
            1
        };
        let n = layers * rows * cols;
        let mut out = Self {
            rows,
            cols,
            layers,
            points: vec![Point::default(); n],
            valid: vec![false; n],
        };
        for (p, &c) in sweep.points.iter().zip(&sweep.columns) {
            let (layer, row) = (usize::from(p.ret.min(1)), usize::from(p.ring));
            if row >= rows || layer >= layers {
                continue;
            }
            let i = (layer * rows + row) * cols + c as usize;
            out.points[i] = *p;
            out.valid[i] = true;
        }
        Some(out)
    }

    /// The cell at (layer, row, col), if valid.
    pub fn get(&self, layer: usize, row: usize, col: usize) -> Option<&Point> {
        if layer >= self.layers || row >= self.rows || col >= self.cols {
            return None;
        }
        let i = (layer * self.rows + row) * self.cols + col;
        self.valid[i].then(|| &self.points[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TURN: i64 = 36_000; // 0.01°

    #[test]
    fn azimuth_steps_without_time_follow_the_three_quarter_rule() {
        assert_eq!(
            azimuth_step(100, TURN, None),
            Step::Forward { full_turn: false }
        );
        assert_eq!(
            azimuth_step(26_999, TURN, None),
            Step::Forward { full_turn: false }
        );
        assert_eq!(azimuth_step(27_000, TURN, None), Step::Back);
        assert_eq!(azimuth_step(35_990, TURN, None), Step::Back);
    }

    #[test]
    fn the_time_between_packets_tells_a_lost_stretch_from_a_step_back() {
        // 600 rpm: a turn per 100 ms.
        let turned = |ms: i64| Some(rotation_in(ms * 1_000_000, 600.0, TURN));
        assert_eq!(turned(80), Some(28_800));
        // A packet 0.05 ms after the last, 0.1° behind: out of order.
        assert_eq!(azimuth_step(35_990, TURN, turned(0)), Step::Back);
        assert_eq!(
            azimuth_step(35_990, TURN, Some(rotation_in(50_000, 600.0, TURN))),
            Step::Back
        );
        // 9° then 300° 80 ms later: 291° forward, packets lost (without the time: a step back).
        assert_eq!(azimuth_step(29_100, TURN, None), Step::Back);
        assert_eq!(
            azimuth_step(29_100, TURN, turned(80)),
            Step::Forward { full_turn: false }
        );
        // 100° then 208° 130 ms later: 108° and a whole turn.
        assert_eq!(
            azimuth_step(10_800, TURN, turned(130)),
            Step::Forward { full_turn: true }
        );
        // 100° then 208° 30 ms later: 108°, no turn lost.
        assert_eq!(
            azimuth_step(10_800, TURN, turned(30)),
            Step::Forward { full_turn: false }
        );
        // Consecutive packets 1.44° apart.
        assert_eq!(
            azimuth_step(144, TURN, Some(rotation_in(400_000, 600.0, TURN))),
            Step::Forward { full_turn: false }
        );
    }
}
