//! A table of timed poses (`world_from_sensor`), interpolated on SE(3), and its TUM text form.
//!
//! TUM trajectory format (TUM RGB-D benchmark): one pose per line,
//! `timestamp tx ty tz qx qy qz qw` — seconds, metres, a unit quaternion (Hamilton, scalar
//! last); blank lines and lines starting with `#` are ignored. The text is parsed here; reading
//! the file is the caller's business.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use super::se3;

/// Why a pose table could not be made or used.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PosesError {
    /// A line does not hold 8 numbers.
    #[error("line {line}: expected 8 values `t x y z qx qy qz qw`, found {found}")]
    FieldCount {
        /// 1-based line number.
        line: usize,
        /// Values found.
        found: usize,
    },
    /// A value is not a finite number.
    #[error("line {line}: value {column} ({text:?}) is not a finite number")]
    Number {
        /// 1-based line number.
        line: usize,
        /// 1-based column.
        column: usize,
        /// The text found.
        text: String,
    },
    /// The quaternion is far from unit length (more than 1 % off) or zero.
    #[error("line {line}: quaternion norm {norm} is not 1")]
    Quaternion {
        /// 1-based line number.
        line: usize,
        /// Its norm.
        norm: f64,
    },
    /// Timestamps must increase strictly.
    #[error(
        "line {line}: timestamp {t_ns} ns does not follow the previous one ({previous_ns} ns)"
    )]
    NotIncreasing {
        /// 1-based line number.
        line: usize,
        /// This timestamp, ns.
        t_ns: i64,
        /// The previous one, ns.
        previous_ns: i64,
    },
    /// Fewer than two poses.
    #[error("a pose table needs at least 2 poses, found {found}")]
    TooFew {
        /// Poses found.
        found: usize,
    },
    /// A time asked for lies outside the table.
    #[error("time {t_ns} ns lies outside the poses [{first_ns}, {last_ns}] ns")]
    OutOfRange {
        /// The time asked for, ns.
        t_ns: i64,
        /// First pose time, ns.
        first_ns: i64,
        /// Last pose time, ns.
        last_ns: i64,
    },
}

/// Timed `world_from_sensor` poses, strictly increasing in time.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseTable {
    times_ns: Vec<i64>,
    poses: Vec<Isometry3<f64>>,
}

/// Parses a decimal number of seconds (`1700000000.123456789`, `-0.5`, `12`, `1e-3`) into ns,
/// exactly for plain decimals (an `f64` would lose ~240 ns at today's epoch seconds).
fn parse_seconds_ns(s: &str) -> Option<i64> {
    let plain = s
        .bytes()
        .all(|b| b.is_ascii_digit() || b == b'.' || b == b'-' || b == b'+');
    if !plain {
        let v: f64 = s.parse().ok()?;
        return (v.is_finite() && v.abs() < 9.0e9).then(|| (v * 1e9).round() as i64);
    }
    let (neg, body) = match s.as_bytes().first()? {
        b'-' => (true, &s[1..]),
        b'+' => (false, &s[1..]),
        _ => (false, s),
    };
    let (int, frac) = body.split_once('.').unwrap_or((body, ""));
    if (int.is_empty() && frac.is_empty())
        || !int.bytes().all(|b| b.is_ascii_digit())
        || !frac.bytes().all(|b| b.is_ascii_digit())
        || int.len() > 10
    {
        return None;
    }
    let secs: i64 = if int.is_empty() { 0 } else { int.parse().ok()? };
    let mut nanos: i64 = 0;
    for (i, b) in frac.bytes().enumerate() {
        if i < 9 {
            nanos = nanos * 10 + i64::from(b - b'0');
        } else if i == 9 && b >= b'5' {
            nanos += 1; // round half up on the 10th digit
        }
    }
    for _ in frac.len()..9 {
        nanos *= 10;
    }
    let ns = secs.checked_mul(1_000_000_000)?.checked_add(nanos)?;
    Some(if neg { -ns } else { ns })
}

impl PoseTable {
    /// A table from `(time ns, world_from_sensor)` pairs, strictly increasing in time.
    pub fn new(entries: Vec<(i64, Isometry3<f64>)>) -> Result<Self, PosesError> {
        if entries.len() < 2 {
            return Err(PosesError::TooFew {
                found: entries.len(),
            });
        }
        for (i, w) in entries.windows(2).enumerate() {
            if w[1].0 <= w[0].0 {
                return Err(PosesError::NotIncreasing {
                    line: i + 2,
                    t_ns: w[1].0,
                    previous_ns: w[0].0,
                });
            }
        }
        let (times_ns, poses) = entries.into_iter().unzip();
        Ok(Self { times_ns, poses })
    }

    /// Parses TUM text (see the module documentation).
    pub fn from_tum(text: &str) -> Result<Self, PosesError> {
        let mut entries = Vec::new();
        let mut previous: Option<i64> = None;
        for (i, line) in text.lines().enumerate() {
            let line_no = i + 1;
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let fields: Vec<&str> = line.split_whitespace().collect();
            if fields.len() != 8 {
                return Err(PosesError::FieldCount {
                    line: line_no,
                    found: fields.len(),
                });
            }
            let number_error = |column: usize| PosesError::Number {
                line: line_no,
                column: column + 1,
                text: fields[column].to_string(),
            };
            let t_ns = parse_seconds_ns(fields[0]).ok_or_else(|| number_error(0))?;
            let mut v = [0f64; 7];
            for (k, slot) in v.iter_mut().enumerate() {
                let x: f64 = fields[k + 1].parse().map_err(|_| number_error(k + 1))?;
                if !x.is_finite() {
                    return Err(number_error(k + 1));
                }
                *slot = x;
            }
            let q = Quaternion::new(v[6], v[3], v[4], v[5]);
            let norm = q.norm();
            if !(0.99..=1.01).contains(&norm) {
                return Err(PosesError::Quaternion {
                    line: line_no,
                    norm,
                });
            }
            if let Some(p) = previous {
                if t_ns <= p {
                    return Err(PosesError::NotIncreasing {
                        line: line_no,
                        t_ns,
                        previous_ns: p,
                    });
                }
            }
            previous = Some(t_ns);
            let pose = Isometry3::from_parts(
                Translation3::new(v[0], v[1], v[2]),
                UnitQuaternion::from_quaternion(q),
            );
            entries.push((t_ns, pose));
        }
        Self::new(entries)
    }

    /// The poses in time order: `(time ns, world_from_sensor)`.
    pub fn entries(&self) -> impl Iterator<Item = (i64, Isometry3<f64>)> + '_ {
        self.times_ns
            .iter()
            .copied()
            .zip(self.poses.iter().copied())
    }

    /// Number of poses.
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    /// Always false: a table holds at least two poses.
    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// Time of the first and of the last pose, ns.
    pub fn time_range_ns(&self) -> (i64, i64) {
        (
            self.times_ns.first().copied().unwrap_or(0),
            self.times_ns.last().copied().unwrap_or(0),
        )
    }

    /// `world_from_sensor` at `t_ns`, interpolated on SE(3) between the two poses around it.
    pub fn world_from_sensor(&self, t_ns: i64) -> Result<Isometry3<f64>, PosesError> {
        let (first_ns, last_ns) = self.time_range_ns();
        if t_ns < first_ns || t_ns > last_ns {
            return Err(PosesError::OutOfRange {
                t_ns,
                first_ns,
                last_ns,
            });
        }
        // First index whose time is > t_ns; t_ns ≥ first so it is ≥ 1.
        let hi = self
            .times_ns
            .partition_point(|&x| x <= t_ns)
            .clamp(1, self.times_ns.len() - 1);
        let lo = hi - 1;
        let (ta, tb) = (self.times_ns[lo], self.times_ns[hi]);
        // Pose times span up to ±9.2e9 s: their differences do not fit an i64.
        let s = t_ns.abs_diff(ta) as f64 / tb.abs_diff(ta) as f64;
        Ok(se3::interpolate(&self.poses[lo], &self.poses[hi], s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn seconds_parse_exactly_to_nanoseconds() {
        assert_eq!(
            parse_seconds_ns("1700000000.123456789"),
            Some(1_700_000_000_123_456_789)
        );
        assert_eq!(parse_seconds_ns("12"), Some(12_000_000_000));
        assert_eq!(parse_seconds_ns("0.5"), Some(500_000_000));
        assert_eq!(parse_seconds_ns("-0.25"), Some(-250_000_000));
        assert_eq!(parse_seconds_ns(".1"), Some(100_000_000));
        assert_eq!(parse_seconds_ns("1.0000000005"), Some(1_000_000_001));
        assert_eq!(parse_seconds_ns("1e-3"), Some(1_000_000));
        assert_eq!(parse_seconds_ns("x"), None);
        assert_eq!(parse_seconds_ns("."), None);
        assert_eq!(parse_seconds_ns("1.2.3"), None);
    }

    /// Poses at either end of the times TUM text gives (±9e9 s): the interpolation weight
    /// between them is computed without an i64 difference, which overflowed (a panic in
    /// debug, a weight of about −20 in release: a pose extrapolated far off).
    #[test]
    fn poses_far_apart_interpolate_without_overflow() {
        let t =
            PoseTable::from_tum("-9000000000 0 0 0 0 0 0 1\n9000000000 2 0 0 0 0 0 1\n").unwrap();
        let p = t.world_from_sensor(0).unwrap();
        assert!(
            (p.translation.vector - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-9,
            "{p}"
        );
        let q = t.world_from_sensor(4_500_000_000_000_000_000).unwrap();
        assert!((q.translation.x - 1.5).abs() < 1e-9, "{q}");
    }

    #[test]
    fn tum_text_parses_and_interpolates_on_se3() {
        // Two poses 1 s apart: a quarter turn about z (qz = qw = √½) while moving to (2, 2, 0).
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let text = format!("# t x y z qx qy qz qw\n10.0 0 0 0 0 0 0 1\n\n11.0 2 2 0 0 0 {h} {h}\n");
        let table = PoseTable::from_tum(&text).unwrap();
        assert_eq!(table.len(), 2);
        assert_eq!(table.time_range_ns(), (10_000_000_000, 11_000_000_000));
        let end = table.world_from_sensor(11_000_000_000).unwrap();
        assert!((end.translation.vector - Vector3::new(2.0, 2.0, 0.0)).norm() < 1e-12);
        // Halfway on the geodesic: the arc of radius 2 m about (0, 2), heading 45°:
        // (2 sin 45°, 2 − 2 cos 45°).
        let mid = table.world_from_sensor(10_500_000_000).unwrap();
        let expected = Vector3::new(2.0 * h, 2.0 - 2.0 * h, 0.0);
        assert!((mid.translation.vector - expected).norm() < 1e-9, "{mid:?}");
        assert!((mid.rotation.angle() - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        assert!(matches!(
            table.world_from_sensor(9_999_999_999),
            Err(PosesError::OutOfRange { .. })
        ));
    }

    #[test]
    fn bad_tum_text_is_rejected_with_its_line() {
        let err = |t: &str| PoseTable::from_tum(t).unwrap_err();
        assert_eq!(
            err("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n"),
            PosesError::FieldCount { line: 2, found: 7 }
        );
        assert!(matches!(
            err("1 0 0 nan 0 0 0 1\n2 0 0 0 0 0 0 1"),
            PosesError::Number {
                line: 1,
                column: 4,
                ..
            }
        ));
        assert!(matches!(
            err("1 0 0 0 0 0 0 2\n2 0 0 0 0 0 0 1"),
            PosesError::Quaternion { line: 1, .. }
        ));
        assert!(matches!(
            err("2 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1"),
            PosesError::NotIncreasing { line: 2, .. }
        ));
        assert_eq!(err("1 0 0 0 0 0 0 1"), PosesError::TooFew { found: 1 });
    }
}
