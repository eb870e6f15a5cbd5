//! What the command line adds to the sensor families: reading `--calib` files, and naming a
//! sensor's channels. Everything per family is behind [`crate::sensor`]'s interface.

use std::collections::BTreeMap;
use std::net::Ipv4Addr;
use std::path::Path;

use crate::sensor::{
    self, CalibError, Calibration, CalibrationPool, Claimed, Facts, FirstDatagram, StreamSettings,
    MAX_CALIB_BYTES,
};

use super::run::RunError;

/// Reads and validates every `--calib [ADDR=]FILE`, each with the family whose format it is.
pub fn load_calibs(list: &[String]) -> Result<Vec<Calibration>, RunError> {
    let mut out = Vec::new();
    for item in list {
        let (addr, path) = match item.split_once('=') {
            Some((a, p)) => match a.parse::<Ipv4Addr>() {
                Ok(ip) => (Some(ip), p),
                Err(_) => {
                    return Err(RunError::Usage(format!(
                        "--calib {item}: `{a}` is not an IPv4 address"
                    )))
                }
            },
            None => (None, item.as_str()),
        };
        let cerr = |msg: String| RunError::Calib {
            path: path.to_string(),
            msg,
        };
        let meta = std::fs::metadata(path).map_err(|e| cerr(e.to_string()))?;
        if meta.len() > MAX_CALIB_BYTES as u64 {
            return Err(cerr(format!(
                "{} bytes; refusing anything over {MAX_CALIB_BYTES} bytes",
                meta.len()
            )));
        }
        let bytes = std::fs::read(path).map_err(|e| cerr(e.to_string()))?;
        let file_name = Path::new(path)
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        out.push(calibration(&bytes, &file_name, addr).map_err(cerr)?);
    }
    Ok(out)
}

/// Reads one calibration (a file's bytes, or metadata fetched from a sensor). Not only text:
/// the AT128's angle correction is a binary `.dat`; each family's reader checks what it claims.
pub fn calibration(
    bytes: &[u8],
    file_name: &str,
    addr: Option<Ipv4Addr>,
) -> Result<Calibration, String> {
    sensor::parse_calibration(bytes, file_name, addr).map_err(|e| {
        match std::str::from_utf8(bytes) {
            Err(u) if matches!(e, CalibError::UnknownFormat(_)) => format!(
                "{e} (binary from byte {}, and not the AT128's .dat, the one binary form read)",
                u.valid_up_to()
            ),
            _ => e.to_string(),
        }
    })
}

/// Chooses the stream of a new source address from its first datagram: the calibrations and
/// settings of the run, offered to every family.
pub struct Chooser {
    pool: CalibrationPool,
}

impl Chooser {
    pub fn new(calibs: &[Calibration], settings: StreamSettings) -> Self {
        Self {
            pool: CalibrationPool::new(calibs.to_vec(), settings),
        }
    }

    /// Adds a calibration after the start (Ouster metadata fetched from a sensor); it serves
    /// sensors first seen from now on.
    pub fn add(&mut self, c: &Calibration) {
        self.pool.add(c.clone());
    }

    /// Payload sizes that start a sensor's main stream, for every family.
    pub fn lidar_sizes(&self) -> Vec<usize> {
        sensor::FAMILIES
            .iter()
            .flat_map(|f| f.lidar_sizes(self.pool.all()))
            .collect()
    }

    /// Whether a calibration of `family` may still serve a new sensor at `addr`.
    pub fn pending(&self, family: &str, addr: Ipv4Addr) -> bool {
        self.pool.candidates(family, addr, true).next().is_some()
    }

    /// The stream for a new sensor whose first datagram is `d`.
    pub fn choose(&mut self, d: &FirstDatagram<'_>) -> Option<Claimed> {
        sensor::claim(d, &mut self.pool)
    }
}

/// MCAP channel metadata of a sensor: where it is, the driver, and its family's facts.
pub fn channel_metadata(
    facts: &dyn Facts,
    addr: Ipv4Addr,
    ports: &[u16],
) -> BTreeMap<String, String> {
    let mut md = BTreeMap::new();
    md.insert("source_address".into(), addr.to_string());
    md.insert(
        "ports".into(),
        ports
            .iter()
            .map(|p| p.to_string())
            .collect::<Vec<_>>()
            .join(","),
    );
    md.insert(
        "driver".into(),
        format!("ringscan {}", env!("CARGO_PKG_VERSION")),
    );
    md.insert("family".into(), facts.family().into());
    facts.channel_metadata(&mut md);
    md
}
