//! Robosense per-laser angles: from the angle CSV RoboSense ships for each sensor, or from a
//! DIFOP packet ([`super::wire::Difop::angles`]), which carries the same table.
//!
//! The CSV (`angle.csv`, e.g. nebula's `RobosenseHelios16P.csv`) has no header: one row per
//! laser, laser 0 first, `vertical,horizontal` in degrees (the horizontal column may be
//! absent: 0). It is recognised when every non-blank line is one or two plain decimal numbers
//! separated by a comma, and there are as many rows as one of the models has lasers (16, 32,
//! 128); any other text is left to the other families. Angles must lie within −90°..180° (the
//! range RoboSense's SDK accepts).

use crate::sensor::calib::parse_decimal;
use crate::sensor::CalibError;

/// Laser counts of the Robosense models.
pub const LASER_COUNTS: [usize; 3] = [16, 32, 128];

/// Per-laser angles, degrees: (vertical, horizontal correction), laser 0 first.
#[derive(Clone, Debug, PartialEq)]
pub struct RobosenseAngles {
    /// Where they came from (a file name, or `DIFOP`).
    pub source: String,
    /// (vertical, horizontal), degrees.
    pub lasers: Vec<(f64, f64)>,
}

impl RobosenseAngles {
    /// Lasers described.
    pub fn lasers(&self) -> usize {
        self.lasers.len()
    }

    /// Checks the range of every angle.
    pub fn check(&self) -> Result<(), CalibError> {
        // An elevation beyond ±90° points behind the sensor's own axis: a misread file.
        for (i, &(v, h)) in self.lasers.iter().enumerate() {
            for (what, a, ok) in [
                ("vertical", v, (-90.0..=90.0).contains(&v)),
                ("horizontal", h, (-90.0..180.0).contains(&h)),
            ] {
                if !a.is_finite() || !ok {
                    return Err(CalibError::BadValue {
                        key: what.into(),
                        context: format!(" in laser {i}"),
                        expected: if what == "vertical" {
                            "an angle in −90°..90°".into()
                        } else {
                            "an angle in −90°..180°".into()
                        },
                        found: a.to_string(),
                    });
                }
            }
        }
        Ok(())
    }
}

/// One row: `Some(Some(..))` numbers, `Some(None)` blank, `None` not a row of this format.
fn row(line: &str) -> Option<Option<(f64, f64)>> {
    let l = line.trim();
    if l.is_empty() {
        return Some(None);
    }
    let mut it = l.split(',');
    let v = parse_decimal(it.next()?.trim())?;
    let h = match it.next() {
        None => 0.0,
        Some(s) => parse_decimal(s.trim())?,
    };
    if it.next().is_some() {
        return None;
    }
    Some(Some((v, h)))
}

/// Reads the angle CSV; `None` when `text` is not in this format.
pub fn parse_csv(text: &str) -> Option<Result<RobosenseAngles, CalibError>> {
    let text = text.trim_start_matches('\u{feff}');
    let mut lasers = Vec::new();
    for line in text.lines() {
        if let Some(r) = row(line)? {
            // Larger than any model: not this format (and bounded).
            if lasers.len() >= 128 {
                return None;
            }
            lasers.push(r);
        }
    }
    if !LASER_COUNTS.contains(&lasers.len()) {
        return None;
    }
    let a = RobosenseAngles {
        source: String::new(),
        lasers,
    };
    Some(a.check().map(|()| a))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_with_tabs_and_without_horizontal() {
        let mut s = String::new();
        for i in 0..16 {
            s.push_str(&format!("{}.5,{}\t\r\n", i, -i));
        }
        let a = parse_csv(&s).unwrap().unwrap();
        assert_eq!(a.lasers[3], (3.5, -3.0));
        let t: String = (0..32).map(|i| format!("{i}\n")).collect();
        assert_eq!(parse_csv(&t).unwrap().unwrap().lasers[5], (5.0, 0.0));
    }

    #[test]
    fn other_texts_are_not_ours() {
        assert!(parse_csv("Laser id,Elevation,Azimuth\n1,2,3\n").is_none());
        assert!(parse_csv("lasers:\n - {laser_id: 0}\n").is_none());
        assert!(parse_csv("1,2\n3,4\n").is_none());
        let bad: String = (0..16).map(|_| "95,0\n").collect();
        assert!(parse_csv(&bad).unwrap().is_err());
    }
}
