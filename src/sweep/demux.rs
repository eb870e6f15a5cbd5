//! Several sensors in one datagram stream: one [`VelodyneStream`] per source address.
//!
//! Velodyne sensors send data (1206 B) and position (512 B) packets from the same address to
//! two ports, so the key is the source IPv4 address. The number of sensors is bounded
//! ([`MAX_SENSORS`]): datagrams from further addresses are counted and dropped, so a flood of
//! spoofed sources cannot grow memory.

use std::net::Ipv4Addr;

use super::velodyne::{SensorFacts, StreamConfig, StreamError, VelodyneStream};
use super::Sweep;
use crate::model::velodyne::{DATA_PACKET_LEN, POSITION_PACKET_LEN};

/// Most sensors tracked at once.
pub const MAX_SENSORS: usize = 64;

/// Identifies a sensor: its source address.
pub type SensorKey = Ipv4Addr;

/// Counters of the demultiplexer itself.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DemuxStats {
    /// Datagrams routed to a sensor.
    pub routed: u64,
    /// Datagrams of no Velodyne size from addresses with no sensor (other traffic).
    pub ignored: u64,
    /// Datagrams to other ports than the one asked for.
    pub other_port: u64,
    /// Datagrams dropped because [`MAX_SENSORS`] sensors were already tracked.
    pub dropped_sensor_limit: u64,
}

/// Per-sensor configuration chooser: gives each new sensor its configuration.
pub type ConfigFor = dyn FnMut(SensorKey) -> StreamConfig;

/// Routes datagrams to per-sensor streams.
pub struct Demux {
    sensors: Vec<(SensorKey, VelodyneStream, Vec<u16>)>,
    config_for: Box<ConfigFor>,
    data_port: Option<u16>,
    stats: DemuxStats,
}

impl core::fmt::Debug for Demux {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Demux")
            .field("sensors", &self.sensors.len())
            .field("stats", &self.stats)
            .finish()
    }
}

impl Demux {
    /// A demultiplexer; `config_for` is called once per new sensor address. With `data_port`
    /// set, data packets to other ports are ignored (position packets are always taken).
    pub fn new(config_for: Box<ConfigFor>, data_port: Option<u16>) -> Self {
        Self {
            sensors: Vec::new(),
            config_for,
            data_port,
            stats: DemuxStats::default(),
        }
    }

    /// Counters.
    pub fn stats(&self) -> &DemuxStats {
        &self.stats
    }

    /// The sensors seen, in order of first appearance, with the destination ports they used.
    pub fn sensors(&self) -> impl Iterator<Item = (SensorKey, &VelodyneStream, &[u16])> {
        self.sensors.iter().map(|(k, s, p)| (*k, s, p.as_slice()))
    }

    /// Routes one datagram; returns the index of the sensor it went to, if any. Finished sweeps
    /// go to `on_sweep(sensor index, sweep, facts)`.
    pub fn push(
        &mut self,
        host_ns: i64,
        src: SensorKey,
        dst_port: u16,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(usize, &Sweep, &SensorFacts),
    ) -> Result<Option<usize>, (usize, StreamError)> {
        let is_data = payload.len() == DATA_PACKET_LEN;
        if is_data {
            if let Some(p) = self.data_port {
                if p != dst_port {
                    self.stats.other_port += 1;
                    return Ok(None);
                }
            }
        }
        let idx = match self.sensors.iter().position(|(k, _, _)| *k == src) {
            Some(i) => i,
            None => {
                if !is_data && payload.len() != POSITION_PACKET_LEN {
                    self.stats.ignored += 1;
                    return Ok(None);
                }
                if self.sensors.len() >= MAX_SENSORS {
                    self.stats.dropped_sensor_limit += 1;
                    return Ok(None);
                }
                let cfg = (self.config_for)(src);
                self.sensors
                    .push((src, VelodyneStream::new(cfg), Vec::new()));
                self.sensors.len() - 1
            }
        };
        self.stats.routed += 1;
        let (_, stream, ports) = &mut self.sensors[idx];
        if !ports.contains(&dst_port) && ports.len() < 16 {
            ports.push(dst_port);
        }
        stream
            .push(host_ns, payload, &mut |s, f| on_sweep(idx, s, f))
            .map_err(|e| (idx, e))?;
        Ok(Some(idx))
    }

    /// The stream of sensor `idx`.
    pub fn stream(&self, idx: usize) -> Option<(SensorKey, &VelodyneStream)> {
        self.sensors.get(idx).map(|(k, s, _)| (*k, s))
    }

    /// Ends every stream, emitting their last sweeps.
    pub fn finish(
        &mut self,
        on_sweep: &mut dyn FnMut(usize, &Sweep, &SensorFacts),
    ) -> Result<(), (usize, StreamError)> {
        for (idx, (_, stream, _)) in self.sensors.iter_mut().enumerate() {
            stream
                .finish(&mut |s, f| on_sweep(idx, s, f))
                .map_err(|e| (idx, e))?;
        }
        Ok(())
    }
}
