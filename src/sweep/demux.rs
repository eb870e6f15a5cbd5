//! Several sensors in one datagram stream: one stream per source address.
//!
//! Velodyne sensors send data (1206 B) and position (512 B) packets from the same address to
//! two ports; Ouster sensors send lidar and IMU packets from one address (two sensors may share
//! a port: `same_ports.pcap`). So the key is the source IPv4 address, and the kind of stream a
//! new address gets is decided by the caller's `config_for` from its first datagram (size,
//! port, and for Ouster the serial / init_id its metadata names). The number of sensors is
//! bounded ([`MAX_SENSORS`]): datagrams from further addresses are counted and dropped, so a
//! flood of spoofed sources cannot grow memory.

use std::net::Ipv4Addr;

use crate::sensor::{Claimed, Facts, FirstDatagram, SensorStream, StreamError};
use crate::sweep::Sweep;

/// Most sensors tracked at once.
pub const MAX_SENSORS: usize = 64;

/// Identifies a sensor: its source address.
pub type SensorKey = Ipv4Addr;

/// Counters of the demultiplexer itself.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DemuxStats {
    /// Datagrams routed to a sensor.
    pub routed: u64,
    /// Datagrams from addresses no configuration claims (other traffic).
    pub ignored: u64,
    /// Velodyne data packets to other ports than the one asked for.
    pub other_port: u64,
    /// Datagrams dropped because [`MAX_SENSORS`] sensors were already tracked.
    pub dropped_sensor_limit: u64,
}

/// Builds the stream of a new sensor from its first datagram ([`crate::sensor::claim`] asks
/// every family); `None` leaves the datagram unclaimed.
pub type ConfigFor = dyn FnMut(&FirstDatagram<'_>) -> Option<Claimed>;

/// Routes datagrams to per-sensor streams.
pub struct Demux {
    sensors: Vec<(SensorKey, Box<dyn SensorStream>, Vec<u16>)>,
    /// Datagrams per destination port, parallel to each sensor's port list.
    port_packets: Vec<Vec<u64>>,
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
    /// A demultiplexer; `config_for` is called with the datagrams of addresses no stream has
    /// yet. With `data_port` set, lidar datagrams ([`SensorStream::is_lidar_datagram`]) to
    /// other ports are ignored.
    pub fn new(config_for: Box<ConfigFor>, data_port: Option<u16>) -> Self {
        Self {
            sensors: Vec::new(),
            port_packets: Vec::new(),
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
    pub fn sensors(&self) -> impl Iterator<Item = (SensorKey, &dyn SensorStream, &[u16])> {
        self.sensors
            .iter()
            .map(|(k, s, p)| (*k, s.as_ref(), p.as_slice()))
    }

    /// Datagrams routed to sensor `idx`, per destination port (parallel to its port list).
    pub fn port_packets(&self, idx: usize) -> &[u64] {
        self.port_packets.get(idx).map_or(&[], |v| v.as_slice())
    }

    /// The stream of sensor `idx`.
    pub fn stream(&self, idx: usize) -> Option<(SensorKey, &dyn SensorStream)> {
        self.sensors.get(idx).map(|(k, s, _)| (*k, s.as_ref()))
    }

    /// The stream of sensor `idx`, mutably (to drain IMU samples).
    pub fn stream_mut(&mut self, idx: usize) -> Option<&mut (dyn SensorStream + 'static)> {
        self.sensors.get_mut(idx).map(|(_, s, _)| s.as_mut())
    }

    /// Routes one datagram; returns the index of the sensor it went to, if any. Finished
    /// sweeps go to `on_sweep(sensor index, sweep, facts)`.
    pub fn push(
        &mut self,
        host_ns: i64,
        src: SensorKey,
        dst_port: u16,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(usize, &mut Sweep, &dyn Facts),
    ) -> Result<Option<usize>, (usize, StreamError)> {
        let idx = match self.sensors.iter().position(|(k, _, _)| *k == src) {
            Some(i) => i,
            None => {
                let first = FirstDatagram {
                    src,
                    port: dst_port,
                    payload,
                };
                if self.sensors.len() >= MAX_SENSORS {
                    self.stats.dropped_sensor_limit += 1;
                    return Ok(None);
                }
                let stream = match (self.config_for)(&first) {
                    None => {
                        self.stats.ignored += 1;
                        return Ok(None);
                    }
                    Some(Ok(s)) => s,
                    Some(Err(e)) => return Err((self.sensors.len(), e)),
                };
                self.sensors.push((src, stream, Vec::new()));
                self.port_packets.push(Vec::new());
                self.sensors.len() - 1
            }
        };
        let (_, stream, ports) = &mut self.sensors[idx];
        if self.data_port.is_some_and(|p| p != dst_port) && stream.is_lidar_datagram(payload) {
            self.stats.other_port += 1;
            return Ok(None);
        }
        self.stats.routed += 1;
        match ports.iter().position(|&p| p == dst_port) {
            Some(i) => {
                if let Some(n) = self.port_packets.get_mut(idx).and_then(|v| v.get_mut(i)) {
                    *n += 1;
                }
            }
            None if ports.len() < 16 => {
                ports.push(dst_port);
                if let Some(v) = self.port_packets.get_mut(idx) {
                    v.push(1);
                }
            }
            None => {}
        }
        stream
            .push(host_ns, payload, &mut |sw, f| on_sweep(idx, sw, f))
            .map_err(|e| (idx, e))?;
        Ok(Some(idx))
    }

    /// Ends every stream, emitting their last sweeps.
    pub fn finish(
        &mut self,
        on_sweep: &mut dyn FnMut(usize, &mut Sweep, &dyn Facts),
    ) -> Result<(), (usize, StreamError)> {
        // A stream that fails does not keep the others from finishing; the first error is
        // returned.
        let mut first_error = None;
        for (idx, (_, stream, _)) in self.sensors.iter_mut().enumerate() {
            if let Err(e) = stream.finish(&mut |sw, f| on_sweep(idx, sw, f)) {
                first_error.get_or_insert((idx, e));
            }
        }
        first_error.map_or(Ok(()), Err)
    }
}
