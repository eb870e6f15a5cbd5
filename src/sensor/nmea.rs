//! NMEA `$GPRMC` / `$GNRMC` sentences as Velodyne position packets carry them.
//!
//! Only what time completion needs: UTC date and time, fix validity, checksum.

/// A parsed RMC sentence.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rmc {
    /// UTC time of the fix, ns since the Unix epoch.
    pub utc_ns: i64,
    /// Status `A` (valid fix) rather than `V`.
    pub valid: bool,
    /// Latitude, degrees (+ north), if present.
    pub lat_deg: Option<f64>,
    /// Longitude, degrees (+ east), if present.
    pub lon_deg: Option<f64>,
}

/// Why a sentence was not accepted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NmeaError {
    /// Not an RMC sentence (or empty).
    #[error("not an RMC sentence")]
    NotRmc,
    /// The `*hh` checksum does not match.
    #[error("checksum mismatch: sentence says {stated:02X}, computed {computed:02X}")]
    Checksum {
        /// Checksum written in the sentence.
        stated: u8,
        /// Checksum of the bytes.
        computed: u8,
    },
    /// A field is malformed.
    #[error("malformed field {0}")]
    Field(usize),
}

/// Parses `$xxRMC,hhmmss[.ss],A,ddmm.mmmm,N,dddmm.mmmm,W,speed,course,ddmmyy,...*CS`.
pub fn parse_rmc(sentence: &[u8]) -> Result<Rmc, NmeaError> {
    let s = core::str::from_utf8(sentence)
        .map_err(|_| NmeaError::NotRmc)?
        .trim();
    let body = s.strip_prefix('$').ok_or(NmeaError::NotRmc)?;
    let (body, stated) = match body.split_once('*') {
        Some((b, cs)) => {
            let cs = cs.get(..2).ok_or(NmeaError::Field(99))?;
            (
                b,
                Some(u8::from_str_radix(cs, 16).map_err(|_| NmeaError::Field(99))?),
            )
        }
        None => (body, None),
    };
    if let Some(stated) = stated {
        let computed = body.bytes().fold(0u8, |a, c| a ^ c);
        if computed != stated {
            return Err(NmeaError::Checksum { stated, computed });
        }
    }
    let mut f = body.split(',');
    let talker = f.next().ok_or(NmeaError::NotRmc)?;
    if talker.len() != 5 || !talker.ends_with("RMC") {
        return Err(NmeaError::NotRmc);
    }
    let time = f.next().ok_or(NmeaError::Field(1))?;
    let status = f.next().ok_or(NmeaError::Field(2))?;
    let lat = f.next().ok_or(NmeaError::Field(3))?;
    let ns = f.next().ok_or(NmeaError::Field(4))?;
    let lon = f.next().ok_or(NmeaError::Field(5))?;
    let ew = f.next().ok_or(NmeaError::Field(6))?;
    let _speed = f.next().ok_or(NmeaError::Field(7))?;
    let _course = f.next().ok_or(NmeaError::Field(8))?;
    let date = f.next().ok_or(NmeaError::Field(9))?;

    let (hh, mm, ss, frac_ns) = parse_hhmmss(time).ok_or(NmeaError::Field(1))?;
    let (day, month, yy) = parse_ddmmyy(date).ok_or(NmeaError::Field(9))?;
    // Two-digit years: 80..99 → 1980s/90s, else 2000s (GPS epoch is 1980).
    let year = if yy >= 80 { 1900 + yy } else { 2000 + yy };
    let days = days_from_civil(year, month, day);
    let secs = days * 86_400 + hh * 3600 + mm * 60 + ss;
    Ok(Rmc {
        utc_ns: secs * 1_000_000_000 + frac_ns,
        valid: status == "A",
        lat_deg: parse_coord(lat, ns, 2),
        lon_deg: parse_coord(lon, ew, 3),
    })
}

fn digits(s: &str) -> Option<i64> {
    if s.is_empty() || !s.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

fn parse_hhmmss(t: &str) -> Option<(i64, i64, i64, i64)> {
    if !t.is_ascii() {
        return None; // byte-indexed slicing below needs single-byte characters
    }
    let (whole, frac) = t.split_once('.').unwrap_or((t, ""));
    if whole.len() != 6 {
        return None;
    }
    let hh = digits(&whole[0..2])?;
    let mm = digits(&whole[2..4])?;
    let ss = digits(&whole[4..6])?;
    if hh > 23 || mm > 59 || ss > 60 {
        return None;
    }
    let mut frac_ns = 0i64;
    if !frac.is_empty() {
        let f = frac.get(..frac.len().min(9))?;
        frac_ns = digits(f)? * 10i64.pow(9 - f.len() as u32);
    }
    Some((hh, mm, ss, frac_ns))
}

fn parse_ddmmyy(d: &str) -> Option<(i64, i64, i64)> {
    if d.len() != 6 || !d.is_ascii() {
        return None;
    }
    let day = digits(&d[0..2])?;
    let month = digits(&d[2..4])?;
    let yy = digits(&d[4..6])?;
    if !(1..=31).contains(&day) || !(1..=12).contains(&month) {
        return None;
    }
    Some((day, month, yy))
}

fn parse_coord(v: &str, hemi: &str, deg_digits: usize) -> Option<f64> {
    if v.len() < deg_digits + 2 || !v.is_ascii() {
        return None;
    }
    let deg: f64 = v.get(..deg_digits)?.parse().ok()?;
    let min: f64 = v.get(deg_digits..)?.parse().ok()?;
    let x = deg + min / 60.0;
    match hemi {
        "N" | "E" => Some(x),
        "S" | "W" => Some(-x),
        _ => None,
    }
}

/// Days since 1970-01-01 of a proleptic Gregorian date (Howard Hinnant's algorithm).
pub fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_monterey_sentence() {
        // From monterey-first-100-packets.pcap: 2012-12-11 22:06:32 UTC.
        let r = parse_rmc(
            b"$GPRMC,220632,A,3707.8324,N,12139.2864,W,000.0,144.7,111212,013.8,E,D*09\r\n",
        )
        .unwrap();
        // 2012-12-11 = 15685 days after 1970-01-01.
        assert_eq!(days_from_civil(2012, 12, 11), 15685);
        assert_eq!(
            r.utc_ns,
            (15685 * 86_400 + 22 * 3600 + 6 * 60 + 32) * 1_000_000_000
        );
        assert!(r.valid);
        assert!((r.lat_deg.unwrap() - (37.0 + 7.8324 / 60.0)).abs() < 1e-12);
        assert!((r.lon_deg.unwrap() + (121.0 + 39.2864 / 60.0)).abs() < 1e-12);
    }

    #[test]
    fn rejects_bad_checksum_and_garbage() {
        assert!(matches!(
            parse_rmc(b"$GPRMC,220632,A,3707.8324,N,12139.2864,W,000.0,144.7,111212,013.8,E,D*0A"),
            Err(NmeaError::Checksum { .. })
        ));
        assert_eq!(parse_rmc(b""), Err(NmeaError::NotRmc));
        assert_eq!(parse_rmc(b"$GPGGA,1,2,3"), Err(NmeaError::NotRmc));
        assert!(parse_rmc(b"$GPRMC,99xx32,A,,,,,,,111212").is_err());
        assert!(parse_rmc(&[0xff, 0xfe]).is_err());
        // Multi-byte characters where digits belong (found by fuzzing): an error, not a panic.
        assert!(parse_rmc("$GPRMC,2206é2,A,,,,,,,111212".as_bytes()).is_err());
        assert!(parse_rmc("$GPRMC,220632,A,,,,,,,1é1212".as_bytes()).is_err());
        assert!(parse_rmc("$GPRMC,220632,A,37é7.8324,N,,,,,111212".as_bytes()).is_ok());
    }
}
