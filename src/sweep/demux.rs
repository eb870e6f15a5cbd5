//! Several sensors in one datagram stream: one stream per source address.
//!
//! Velodyne sensors send data (1206 B) and position (512 B) packets from the same address to
//! two ports; Ouster sensors send lidar and IMU packets from one address (two sensors may share
//! a port: `same_ports.pcap`). So the key is the source IPv4 address, and the kind of stream a
//! new address gets is decided by the caller's `config_for` from its first datagram (size,
//! port, and for Ouster the serial / init_id its metadata names). The number of sensors is
//! bounded ([`MAX_SENSORS`]): datagrams from further addresses are counted and dropped, so a
//! flood of spoofed sources cannot grow memory.
//!
//! A sensor is recognised by its main packets, but it may send others first: an Ouster IMU
//! packet before the first lidar packet (ACCEL32_GYRO32 or legacy IMU packets carry nothing
//! that names the metadata they belong to), a Velodyne position packet before the first data
//! packet. So the last few datagrams of each unclaimed address are held ([`EARLY_HOLD_COUNT`],
//! [`EARLY_HOLD_PER_ADDR`], [`EARLY_HOLD_BYTES`], [`EARLY_HOLD_NS`]) and routed, in arrival
//! order, to the sensor's stream before the datagram that starts it. The buffers are reused,
//! so other traffic on the port costs no allocation once warm.

use std::collections::VecDeque;
use std::net::{Ipv4Addr, SocketAddrV4};

use crate::sensor::{Claimed, Facts, FirstDatagram, SensorStream, StreamError};
use crate::sweep::Sweep;

/// Most sensors tracked at once.
pub const MAX_SENSORS: usize = 64;

/// Most datagrams held from unclaimed addresses, over all of them.
pub const EARLY_HOLD_COUNT: usize = 32;
/// Most datagrams held per unclaimed address: an Ouster sensor sends one IMU packet per 10 ms,
/// and its first lidar packet within a millisecond of starting, so a handful covers it.
pub const EARLY_HOLD_PER_ADDR: usize = 8;
/// Most payload bytes held, over all unclaimed addresses.
pub const EARLY_HOLD_BYTES: usize = 256 * 1024;
/// Datagrams held longer than this (host time, before the newest datagram) are let go: they
/// are not the start of a sensor's stream but other traffic.
pub const EARLY_HOLD_NS: i64 = 1_000_000_000;

/// Identifies a sensor: its source address.
pub type SensorKey = Ipv4Addr;

/// Counters of the demultiplexer itself.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DemuxStats {
    /// Datagrams routed to a sensor.
    pub routed: u64,
    /// Datagrams from addresses no configuration claims (other traffic).
    pub ignored: u64,
    /// Lidar datagrams to other ports than the one asked for.
    pub other_port: u64,
    /// The destination port of the first of them (what a run that decoded nothing names).
    pub other_port_first: Option<u16>,
    /// Datagrams dropped because [`MAX_SENSORS`] sensors were already tracked.
    pub dropped_sensor_limit: u64,
    /// Datagrams that came before their sensor was recognised, held and routed to it once it
    /// was (counted in `routed`, no longer in `ignored`).
    pub early: u64,
}

/// A datagram held before its sensor was recognised, and routed to it since
/// ([`Demux::replayed`]).
#[derive(Clone, Copy, Debug)]
pub struct EarlyDatagram<'a> {
    /// Host receive time, ns.
    pub host_ns: i64,
    /// Source UDP port.
    pub src_port: u16,
    /// Destination UDP port.
    pub dst_port: u16,
    /// The payload.
    pub payload: &'a [u8],
}

struct Held {
    addr: Ipv4Addr,
    host_ns: i64,
    src_port: u16,
    dst_port: u16,
    payload: Vec<u8>,
}

/// The datagrams of unclaimed addresses, oldest first, within the bounds above.
#[derive(Default)]
struct EarlyHold {
    held: VecDeque<Held>,
    bytes: usize,
    /// Payload buffers to reuse.
    spare: Vec<Vec<u8>>,
}

impl EarlyHold {
    fn remove(&mut self, i: usize) {
        if let Some(h) = self.held.remove(i) {
            self.bytes -= h.payload.len();
            self.spare.push(h.payload);
        }
    }

    fn hold(&mut self, addr: Ipv4Addr, host_ns: i64, src_port: u16, dst_port: u16, payload: &[u8]) {
        if payload.len() > EARLY_HOLD_BYTES {
            return;
        }
        // Too old to belong to a sensor's start (host time may step back: then kept).
        while self
            .held
            .front()
            .is_some_and(|h| host_ns.saturating_sub(h.host_ns) > EARLY_HOLD_NS)
        {
            self.remove(0);
        }
        let mine = self.held.iter().filter(|h| h.addr == addr).count();
        if mine >= EARLY_HOLD_PER_ADDR {
            if let Some(i) = self.held.iter().position(|h| h.addr == addr) {
                self.remove(i);
            }
        }
        while !self.held.is_empty()
            && (self.held.len() >= EARLY_HOLD_COUNT
                || self.bytes + payload.len() > EARLY_HOLD_BYTES)
        {
            self.remove(0);
        }
        let mut buf = self.spare.pop().unwrap_or_default();
        buf.clear();
        buf.extend_from_slice(payload);
        self.bytes += buf.len();
        self.held.push_back(Held {
            addr,
            host_ns,
            src_port,
            dst_port,
            payload: buf,
        });
    }

    /// Moves the datagrams of `addr` still recent at `host_ns` into `out`, in order; lets the
    /// older ones go.
    fn take(&mut self, addr: Ipv4Addr, host_ns: i64, out: &mut Vec<Held>) {
        let mut i = 0;
        while i < self.held.len() {
            if self.held[i].addr != addr {
                i += 1;
                continue;
            }
            let Some(h) = self.held.remove(i) else { break };
            self.bytes -= h.payload.len();
            if host_ns.saturating_sub(h.host_ns) > EARLY_HOLD_NS {
                self.spare.push(h.payload);
            } else {
                out.push(h);
            }
        }
    }
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
    early: EarlyHold,
    /// The datagrams routed from the hold by the last push, and the sensor they went to.
    replayed: Vec<Held>,
    replayed_to: Option<usize>,
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
            early: EarlyHold::default(),
            replayed: Vec::new(),
            replayed_to: None,
        }
    }

    /// Counters.
    pub fn stats(&self) -> &DemuxStats {
        &self.stats
    }

    /// The one destination port lidar datagrams are decoded from, when one was asked for.
    pub fn data_port(&self) -> Option<u16> {
        self.data_port
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
    /// sweeps go to `on_sweep(sensor index, sweep, facts)`. The source port is not known
    /// here: [`Demux::push_from`] keeps it for the held datagrams ([`Demux::replayed`]).
    pub fn push(
        &mut self,
        host_ns: i64,
        src: SensorKey,
        dst_port: u16,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(usize, &mut Sweep, &dyn Facts),
    ) -> Result<Option<usize>, (usize, StreamError)> {
        self.push_from(
            host_ns,
            SocketAddrV4::new(src, 0),
            dst_port,
            payload,
            on_sweep,
        )
    }

    /// [`Demux::push`] with the datagram's source port. When this datagram starts a sensor,
    /// the datagrams its address sent before are routed to it first ([`Demux::replayed`]
    /// lists them until the next push).
    pub fn push_from(
        &mut self,
        host_ns: i64,
        src: SocketAddrV4,
        dst_port: u16,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(usize, &mut Sweep, &dyn Facts),
    ) -> Result<Option<usize>, (usize, StreamError)> {
        for h in self.replayed.drain(..) {
            self.early.spare.push(h.payload);
        }
        self.replayed_to = None;
        let addr = *src.ip();
        let idx = match self.sensors.iter().position(|(k, _, _)| *k == addr) {
            Some(i) => i,
            None => {
                let first = FirstDatagram {
                    src: addr,
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
                        self.early
                            .hold(addr, host_ns, src.port(), dst_port, payload);
                        return Ok(None);
                    }
                    Some(Ok(s)) => s,
                    Some(Err(e)) => return Err((self.sensors.len(), e)),
                };
                self.sensors.push((addr, stream, Vec::new()));
                self.port_packets.push(Vec::new());
                let idx = self.sensors.len() - 1;
                self.replay_early(idx, addr, host_ns, on_sweep)?;
                idx
            }
        };
        Ok(self
            .route(idx, host_ns, dst_port, payload, on_sweep)?
            .then_some(idx))
    }

    /// Routes the held datagrams of `addr` to its new sensor `idx`.
    fn replay_early(
        &mut self,
        idx: usize,
        addr: Ipv4Addr,
        host_ns: i64,
        on_sweep: &mut dyn FnMut(usize, &mut Sweep, &dyn Facts),
    ) -> Result<(), (usize, StreamError)> {
        let mut held = std::mem::take(&mut self.replayed);
        self.early.take(addr, host_ns, &mut held);
        if held.is_empty() {
            self.replayed = held;
            return Ok(());
        }
        self.replayed_to = Some(idx);
        let mut result = Ok(());
        for (i, h) in held.iter().enumerate() {
            self.stats.ignored = self.stats.ignored.saturating_sub(1);
            self.stats.early += 1;
            if let Err(e) = self.route(idx, h.host_ns, h.dst_port, &h.payload, on_sweep) {
                result = Err(e);
                // Those after it were not routed: not listed, and still counted `ignored`.
                for h in held.drain(i + 1..) {
                    self.early.spare.push(h.payload);
                }
                break;
            }
        }
        self.replayed = held;
        result
    }

    /// The datagrams routed from the hold by the last push (oldest first), and the sensor
    /// they went to: a caller that records raw packets writes them before the last push's own.
    pub fn replayed(&self) -> (Option<usize>, impl Iterator<Item = EarlyDatagram<'_>>) {
        (
            self.replayed_to,
            self.replayed.iter().map(|h| EarlyDatagram {
                host_ns: h.host_ns,
                src_port: h.src_port,
                dst_port: h.dst_port,
                payload: &h.payload,
            }),
        )
    }

    /// Lets go of the datagrams held for `addr` (a caller that holds them itself and pushes
    /// them again).
    pub fn forget_early(&mut self, addr: Ipv4Addr) {
        while let Some(i) = self.early.held.iter().position(|h| h.addr == addr) {
            self.early.remove(i);
        }
    }

    /// Routes one datagram to sensor `idx`; `false` when it is a lidar datagram to another
    /// port than the one asked for.
    fn route(
        &mut self,
        idx: usize,
        host_ns: i64,
        dst_port: u16,
        payload: &[u8],
        on_sweep: &mut dyn FnMut(usize, &mut Sweep, &dyn Facts),
    ) -> Result<bool, (usize, StreamError)> {
        let Some((_, stream, ports)) = self.sensors.get_mut(idx) else {
            return Ok(false);
        };
        if self.data_port.is_some_and(|p| p != dst_port) && stream.is_lidar_datagram(payload) {
            self.stats.other_port += 1;
            self.stats.other_port_first.get_or_insert(dst_port);
            return Ok(false);
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
        Ok(true)
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;
    use std::sync::{Arc, Mutex};

    /// Payloads pushed, per sensor address.
    type Log = Arc<Mutex<Vec<(Ipv4Addr, Vec<u8>)>>>;

    #[derive(Debug)]
    struct Recorder {
        addr: Ipv4Addr,
        log: Log,
    }

    struct NoFacts;

    impl Facts for NoFacts {
        fn family(&self) -> &'static str {
            "test"
        }
        fn default_name(&self, _addr: Ipv4Addr) -> String {
            "test".into()
        }
        fn calibration_name(&self) -> &str {
            ""
        }
        fn channel_metadata(&self, _md: &mut BTreeMap<String, String>) {}
        fn diagnostics(&self, _out: &mut serde_json::Map<String, serde_json::Value>) {}
        fn as_any(&self) -> &dyn core::any::Any {
            self
        }
    }

    impl SensorStream for Recorder {
        fn push(
            &mut self,
            _host_ns: i64,
            payload: &[u8],
            _on_sweep: &mut crate::sensor::OnSweep<'_>,
        ) -> Result<(), StreamError> {
            self.log.lock().unwrap().push((self.addr, payload.to_vec()));
            Ok(())
        }
        fn finish(
            &mut self,
            _on_sweep: &mut crate::sensor::OnSweep<'_>,
        ) -> Result<(), StreamError> {
            Ok(())
        }
        fn ready(&self) -> bool {
            true
        }
        fn facts(&self) -> &dyn Facts {
            &NoFacts
        }
        fn summary(&self) -> (serde_json::Value, crate::sensor::PacketCounts) {
            (serde_json::Value::Null, Default::default())
        }
        fn is_lidar_datagram(&self, payload: &[u8]) -> bool {
            payload.first() == Some(&b'L')
        }
        fn channels(&self) -> Option<usize> {
            None
        }
        fn as_any(&self) -> &dyn core::any::Any {
            self
        }
    }

    /// A demultiplexer whose sensors start with a payload beginning with `L`; the others
    /// (`I`: an IMU packet) are theirs too but do not start them.
    fn demux() -> (Demux, Log) {
        let log: Log = Arc::default();
        let l = log.clone();
        let d = Demux::new(
            Box::new(move |f: &FirstDatagram<'_>| {
                (f.payload.first() == Some(&b'L')).then(|| {
                    Ok(Box::new(Recorder {
                        addr: f.src,
                        log: l.clone(),
                    }) as Box<dyn SensorStream>)
                })
            }),
            None,
        );
        (d, log)
    }

    const A: Ipv4Addr = Ipv4Addr::new(10, 0, 0, 1);
    const B: Ipv4Addr = Ipv4Addr::new(10, 0, 0, 2);
    const MS: i64 = 1_000_000;

    fn push(d: &mut Demux, t: i64, addr: Ipv4Addr, payload: &[u8]) -> Option<usize> {
        d.push_from(
            t,
            SocketAddrV4::new(addr, 4000),
            7502,
            payload,
            &mut |_, _, _| {},
        )
        .unwrap()
    }

    fn logged(log: &Log, addr: Ipv4Addr) -> Vec<Vec<u8>> {
        log.lock()
            .unwrap()
            .iter()
            .filter(|(a, _)| *a == addr)
            .map(|(_, p)| p.clone())
            .collect()
    }

    #[test]
    fn datagrams_before_the_one_that_starts_a_sensor_go_to_it_first_in_order() {
        let (mut d, log) = demux();
        assert_eq!(push(&mut d, 0, A, b"I0"), None);
        assert_eq!(push(&mut d, MS, B, b"I-b"), None);
        assert_eq!(push(&mut d, 2 * MS, A, b"I1"), None);
        assert_eq!(d.stats().ignored, 3);
        assert_eq!(push(&mut d, 3 * MS, A, b"L0"), Some(0));
        assert_eq!(
            logged(&log, A),
            [b"I0".to_vec(), b"I1".to_vec(), b"L0".to_vec()]
        );
        let (to, early) = d.replayed();
        let early: Vec<_> = early
            .map(|e| (e.host_ns, e.src_port, e.payload.to_vec()))
            .collect();
        assert_eq!(to, Some(0));
        assert_eq!(
            early,
            [(0, 4000, b"I0".to_vec()), (2 * MS, 4000, b"I1".to_vec())]
        );
        assert_eq!(d.stats().ignored, 1, "B's datagram is still unclaimed");
        assert_eq!((d.stats().early, d.stats().routed), (2, 3));
        assert_eq!(d.port_packets(0), [3]);
        // The list lasts until the next push; B's datagram waits for B.
        assert_eq!(push(&mut d, 4 * MS, A, b"I2"), Some(0));
        assert_eq!(d.replayed().0, None);
        assert_eq!(d.replayed().1.count(), 0);
        assert_eq!(push(&mut d, 5 * MS, B, b"L-b"), Some(1));
        assert_eq!(logged(&log, B), [b"I-b".to_vec(), b"L-b".to_vec()]);
        assert_eq!((d.stats().ignored, d.stats().early), (0, 3));
    }

    #[test]
    fn the_hold_is_bounded_in_age_per_address_in_count_and_in_bytes() {
        // Age: a datagram more than a second before the start is not the sensor's start.
        let (mut d, log) = demux();
        push(&mut d, 0, A, b"I-old");
        push(&mut d, 600 * MS, A, b"I-mid");
        push(&mut d, EARLY_HOLD_NS + 500 * MS, A, b"L");
        assert_eq!(logged(&log, A), [b"I-mid".to_vec(), b"L".to_vec()]);
        assert_eq!(d.stats().ignored, 1);

        // Per address: the newest EARLY_HOLD_PER_ADDR.
        let (mut d, log) = demux();
        for i in 0..EARLY_HOLD_PER_ADDR + 3 {
            push(&mut d, i as i64, A, format!("I{i}").as_bytes());
        }
        push(&mut d, 100, A, b"L");
        let got = logged(&log, A);
        assert_eq!(got.len(), EARLY_HOLD_PER_ADDR + 1);
        assert_eq!(got[0], b"I3".to_vec());

        // Over all addresses: the newest EARLY_HOLD_COUNT, whoever sent them.
        let (mut d, log) = demux();
        let addrs: Vec<Ipv4Addr> = (0..EARLY_HOLD_COUNT as u8 + 4)
            .map(|i| Ipv4Addr::new(10, 1, 0, i))
            .collect();
        for (i, a) in addrs.iter().enumerate() {
            push(&mut d, i as i64, *a, b"I");
        }
        for a in &addrs {
            push(&mut d, 1000, *a, b"L");
        }
        let routed_early = addrs
            .iter()
            .filter(|a| logged(&log, **a).len() == 2)
            .count();
        assert_eq!(routed_early, EARLY_HOLD_COUNT);
        assert_eq!(logged(&log, addrs[3]).len(), 1, "among the oldest, let go");

        // Bytes: a datagram larger than the whole hold is not held; others make room.
        let (mut d, log) = demux();
        let big = vec![b'I'; EARLY_HOLD_BYTES / 2 + 1];
        push(&mut d, 0, A, &big);
        push(&mut d, 1, A, &big);
        push(&mut d, 2, A, &vec![b'I'; EARLY_HOLD_BYTES + 1]);
        push(&mut d, 3, A, b"L");
        assert_eq!(logged(&log, A), [big.clone(), b"L".to_vec()]);
        assert!(d.early.bytes <= EARLY_HOLD_BYTES);
    }

    #[test]
    fn forgotten_datagrams_are_not_routed() {
        let (mut d, log) = demux();
        push(&mut d, 0, A, b"I0");
        push(&mut d, 0, B, b"I-b");
        d.forget_early(A);
        push(&mut d, 1, A, b"L");
        push(&mut d, 1, B, b"L");
        assert_eq!(logged(&log, A), [b"L".to_vec()]);
        assert_eq!(logged(&log, B), [b"I-b".to_vec(), b"L".to_vec()]);
        assert_eq!(d.early.held.len(), 0);
        assert_eq!(d.early.bytes, 0);
    }
}
