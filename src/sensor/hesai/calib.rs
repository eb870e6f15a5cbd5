//! Hesai angle corrections: the angle-correction CSV every spinning model ships with, and the
//! AT128's and the ATX's binary `.dat` ([`super::at128`], [`super::atx`]).
//!
//! The CSV (Hesai user manuals, "Angle correction file"; what the sensor serves over PTC) is a
//! header line `Laser id,Elevation,Azimuth` (older files: `Channel,Elevation,Azimuth`) and one
//! row per channel: its 1-based id, elevation and azimuth offset in degrees. The file is
//! recognised by that header line alone, so that any other text goes on to the other families'
//! parsers; once recognised, every row must be well-formed: ids 1..N in order, N one of the
//! models' channel counts, finite angles (elevation within ±90°, azimuth offset within ±180°).

use super::at128::At128Correction;
use super::atx::{AtxCorrection, AtxFiretimes};
use crate::sensor::calib::parse_decimal;
use crate::sensor::CalibError;

/// Channel counts of the Hesai models (a CSV with another row count is refused).
pub const CHANNEL_COUNTS: [usize; 5] = [16, 32, 40, 64, 128];

/// One channel of a CSV correction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChannelAngles {
    /// Elevation, degrees (up positive).
    pub elevation_deg: f64,
    /// Azimuth offset added to the block azimuth, degrees (clockwise seen from above).
    pub azimuth_deg: f64,
}

/// A Hesai angle correction, read and checked.
#[derive(Clone, Debug, PartialEq)]
pub enum HesaiCalibration {
    /// The angle-correction CSV: one entry per channel, channel 0 first.
    Csv(Vec<ChannelAngles>),
    /// The AT128's binary correction.
    At128(At128Correction),
    /// The Pandar ATX's binary correction.
    Atx(AtxCorrection),
    /// The Pandar ATX's firetime CSV: it serves with an ATX angle correction, never alone.
    AtxFiretimes(AtxFiretimes),
}

impl HesaiCalibration {
    /// Channels the correction describes.
    pub fn channels(&self) -> usize {
        match self {
            Self::Csv(c) => c.len(),
            Self::At128(a) => a.channels(),
            Self::Atx(a) => a.channels(),
            Self::AtxFiretimes(f) => f.channels(),
        }
    }
}

/// Whether `text` starts (after a BOM and blank lines) with a Hesai CSV header line.
pub fn looks_like_csv(text: &str) -> bool {
    text.trim_start_matches('\u{feff}')
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty())
        .is_some_and(is_header)
}

fn is_header(line: &str) -> bool {
    let cols: Vec<String> = line
        .split(',')
        .map(|c| c.trim().to_ascii_lowercase())
        .collect();
    matches!(
        cols.first().map(String::as_str),
        Some("laser id" | "channel" | "laser_id" | "channel id")
    ) && cols.get(1).map(String::as_str) == Some("elevation")
        && cols.get(2).map(String::as_str) == Some("azimuth")
}

/// Parses an angle-correction CSV; `None` when the text has no Hesai header line.
pub fn parse_csv(text: &str) -> Option<Result<Vec<ChannelAngles>, CalibError>> {
    if !looks_like_csv(text) {
        return None;
    }
    Some(parse_rows(text))
}

fn bad(line: usize, key: &str, expected: &str, found: &str) -> CalibError {
    CalibError::BadValue {
        key: key.to_string(),
        context: format!(" on line {line}"),
        expected: expected.to_string(),
        found: found.chars().take(40).collect(),
    }
}

fn parse_rows(text: &str) -> Result<Vec<ChannelAngles>, CalibError> {
    let mut out = Vec::new();
    let mut header_seen = false;
    for (i, raw) in text.trim_start_matches('\u{feff}').lines().enumerate() {
        let line_no = i + 1;
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        if !header_seen {
            header_seen = true;
            continue;
        }
        let cols: Vec<&str> = line.split(',').map(str::trim).collect();
        if cols.len() < 3 {
            return Err(bad(line_no, "row", "id,elevation,azimuth", line));
        }
        let id: usize = cols[0]
            .parse()
            .map_err(|_| bad(line_no, "Laser id", "a channel number", cols[0]))?;
        if id != out.len() + 1 {
            return Err(bad(
                line_no,
                "Laser id",
                &format!("{}", out.len() + 1),
                cols[0],
            ));
        }
        let num = |s: &str, key: &str, limit: f64| -> Result<f64, CalibError> {
            match parse_decimal(s) {
                Some(v) if v.is_finite() && v.abs() <= limit => Ok(v),
                _ => Err(bad(line_no, key, &format!("degrees within ±{limit}"), s)),
            }
        };
        let elevation_deg = num(cols[1], "Elevation", 90.0)?;
        let azimuth_deg = num(cols[2], "Azimuth", 180.0)?;
        out.push(ChannelAngles {
            elevation_deg,
            azimuth_deg,
        });
        if out.len() > 256 {
            return Err(CalibError::Invalid(
                "Hesai angle correction has more than 256 rows".into(),
            ));
        }
    }
    if !CHANNEL_COUNTS.contains(&out.len()) {
        return Err(CalibError::Invalid(format!(
            "Hesai angle correction has {} channels; expected one of {CHANNEL_COUNTS:?}",
            out.len()
        )));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn csv(rows: usize) -> String {
        let mut s = String::from("Laser id,Elevation,Azimuth\n");
        for i in 1..=rows {
            s.push_str(&format!("{i},{},{}\n", 15.0 - i as f64, 0.1 * i as f64));
        }
        s
    }

    #[test]
    fn reads_a_well_formed_file() {
        let c = parse_csv(&csv(32)).unwrap().unwrap();
        assert_eq!(c.len(), 32);
        assert_eq!(c[0].elevation_deg, 14.0);
        let alt = csv(40).replace("Laser id", "Channel");
        assert_eq!(parse_csv(&alt).unwrap().unwrap().len(), 40);
    }

    #[test]
    fn other_texts_are_not_hesai() {
        assert!(parse_csv("lasers:\n  - {dist_correction: 1}\n").is_none());
        assert!(parse_csv("<?xml version=\"1.0\"?>").is_none());
        assert!(parse_csv("1,2,3\n").is_none());
        assert!(parse_csv("").is_none());
    }

    #[test]
    fn hostile_files_give_clear_errors() {
        let cases = [
            csv(31),
            csv(32).replace("\n5,10,0.5", "\n5,NaN,0.5"),
            csv(32).replace("\n5,10,0.5", "\n5,10,inf"),
            csv(32).replace("\n5,10,0.5", "\n5,1e300,0.5"),
            csv(32).replace("\n5,10,0.5", "\n5,10,720"),
            csv(32).replace("\n5,10,0.5", "\n7,10,0.5"),
            csv(32).replace("\n5,10,0.5", "\n5,10"),
            csv(300),
            "Laser id,Elevation,Azimuth\n".to_string(),
        ];
        for (i, text) in cases.iter().enumerate() {
            let r = parse_csv(text).expect("recognised");
            assert!(r.is_err(), "case {i} accepted");
            assert!(!r.unwrap_err().to_string().is_empty());
        }
    }
}
