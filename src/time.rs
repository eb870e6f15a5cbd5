//! Device time: Velodyne top-of-hour microseconds completed to absolute time.
//!
//! `t = hour_of(reference) + toh_us`, moved by one hour when that lands more than 30 minutes
//! from the reference (the rule of the ROS driver's `resolveHourAmbiguity` and
//! velodyne_decoder's `time_conversion.cpp`). The reference is a GPS time (NMEA RMC) when the
//! sensor reports PPS locked, else the host's receive time.

/// Nanoseconds in one hour.
pub const HOUR_NS: i64 = 3_600_000_000_000;
/// Microseconds in one hour (the top-of-hour counter's modulus).
pub const HOUR_US: u32 = 3_600_000_000;

/// Which clock a timestamp is in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ClockSource {
    /// Sensor clock disciplined by GPS (PPS locked and a valid NMEA time).
    SensorGps,
    /// Sensor clock disciplined by PTP (Ouster, TAI converted to UTC).
    SensorPtp,
    /// The host's receive time.
    #[default]
    Host,
}

impl ClockSource {
    /// Name written in MCAP channel metadata and summaries.
    pub fn name(self) -> &'static str {
        match self {
            Self::SensorGps => "sensor-gps",
            Self::SensorPtp => "sensor-ptp",
            Self::Host => "host",
        }
    }
}

/// Completes a top-of-hour µs counter to ns since the Unix epoch, using the hour of
/// `reference_ns` and moving by ±1 h when the result is more than 30 min away from it.
///
/// Saturates at the ends of the `i64` range (a corrupt capture time can lie there).
pub fn complete_toh(toh_us: u32, reference_ns: i64) -> i64 {
    let reference = i128::from(reference_ns);
    let hour_ns = i128::from(HOUR_NS);
    let hour = reference.div_euclid(hour_ns) * hour_ns;
    let t = hour + i128::from(toh_us % HOUR_US) * 1_000;
    let half = hour_ns / 2;
    let t = if t - reference > half {
        t - hour_ns
    } else if reference - t > half {
        t + hour_ns
    } else {
        t
    };
    t.clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64
}

/// Difference `b − a` of two top-of-hour counters in µs, in (−30 min, +30 min], across the
/// hour roll-over.
pub fn toh_delta_us(a: u32, b: u32) -> i64 {
    let h = i64::from(HOUR_US);
    let d = (i64::from(b % HOUR_US) - i64::from(a % HOUR_US)).rem_euclid(h);
    if d > h / 2 {
        d - h
    } else {
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn completes_within_the_hour() {
        // Reference 10:20:00, counter 20 min 5 s → 10:20:05.
        let ref_ns = 10 * HOUR_NS + 20 * 60 * 1_000_000_000;
        assert_eq!(complete_toh(1_205_000_000, ref_ns), ref_ns + 5_000_000_000);
    }

    #[test]
    fn hour_roll_over_both_ways() {
        // Reference 11:00:01 (just after the hour), counter 59:59.5 → 10:59:59.5.
        let ref_ns = 11 * HOUR_NS + 1_000_000_000;
        assert_eq!(
            complete_toh(3_599_500_000, ref_ns),
            11 * HOUR_NS - 500_000_000
        );
        // Reference 10:59:59 (host late), counter 0:00.2 → 11:00:00.2.
        let ref_ns = 11 * HOUR_NS - 1_000_000_000;
        assert_eq!(complete_toh(200_000, ref_ns), 11 * HOUR_NS + 200_000_000);
    }

    #[test]
    fn extreme_references_saturate() {
        // Found by fuzzing: host times near the ends of i64 overflowed `hour + toh`.
        assert_eq!(complete_toh(3_599_999_999, i64::MAX), i64::MAX);
        let t = complete_toh(0, i64::MIN);
        assert!(t <= i64::MIN + HOUR_NS);
    }

    #[test]
    fn deltas_wrap() {
        assert_eq!(toh_delta_us(3_599_999_000, 1_000), 2_000);
        assert_eq!(toh_delta_us(1_000, 3_599_999_000), -2_000);
        assert_eq!(toh_delta_us(5, 5), 0);
        // Out-of-range counters are taken modulo one hour, never panic.
        assert_eq!(
            toh_delta_us(u32::MAX, 0),
            toh_delta_us(u32::MAX % HOUR_US, 0)
        );
    }
}
