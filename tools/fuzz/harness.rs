//! The fuzz harnesses: one function per target, each taking the fuzzer's bytes and panicking
//! when an invariant breaks.
//!
//! Shared by the cargo-fuzz targets (`tools/fuzz/fuzz_targets/*.rs`, which are one-line
//! wrappers) and by `tests/regressions.rs`, which replays every saved crash input through the
//! very same function. It uses only the library's public API (plus the `mcap` crate to read
//! back what the sink wrote), so it compiles in both places. See `FUZZING.md`.
#![allow(dead_code)]

use std::cell::{Cell, RefCell};
use std::collections::BTreeMap;
use std::io::{Cursor, Seek, SeekFrom, Write};
use std::net::{Ipv4Addr, SocketAddrV4};
use std::rc::Rc;
use std::sync::OnceLock;

use ringscan::point::Point;
use ringscan::sensor::nmea::parse_rmc;
use ringscan::sensor::ouster::OusterFacts;
use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::calib::parse_velodyne_bytes;
use ringscan::sensor::velodyne::calib::LaserCalibration;
use ringscan::sensor::velodyne::calib::VelodyneCalibration;
use ringscan::sensor::velodyne::model::ALL_MODELS;
use ringscan::sensor::velodyne::model::BLOCKS;
use ringscan::sensor::velodyne::model::DATA_PACKET_LEN;
use ringscan::sensor::velodyne::model::POSITION_PACKET_LEN;
use ringscan::sensor::velodyne::model::SLOTS;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::wire::PositionPacket;
use ringscan::sensor::velodyne::wire::FLAG_BANK2;
use ringscan::sensor::velodyne::wire::FLAG_BANK3;
use ringscan::sensor::velodyne::wire::FLAG_LOWER;
use ringscan::sensor::velodyne::wire::FLAG_UPPER;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::SensorFacts;
use ringscan::sensor::velodyne::StreamConfig;
use ringscan::sensor::velodyne::VelodyneDecoder;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::velodyne::VelodyneStream;
use ringscan::sensor::DecodeOptions;
use ringscan::sensor::{Claimed, Facts, FirstDatagram, SensorStream};
use ringscan::sink::mcap::{
    Compression, Format, McapSink, SensorId, SensorInfo, SinkError, SinkOptions, SweepMsg,
};
use ringscan::source::pcap::PcapSource;
use ringscan::source::read_ahead::ReadAhead;
use ringscan::source::reassembly::{
    FragmentKey, Push, Reassembler, ReassemblyConfig, MAX_IPV4_PAYLOAD,
};
use ringscan::sweep::Demux;
use ringscan::sweep::Organized;
use ringscan::sweep::Sweep;

// ----- issues found and not fixed yet ----------------------------------------------------------

/// Crashes and broken invariants this harness found, reported and not fixed yet. The fuzz
/// targets step around them so that fuzzing goes on; `tests/regressions.rs` replays each saved
/// input with [`set_strict`] on (an `#[ignore]`d test until the fix lands). When a fix lands,
/// remove its name here: the fuzz targets then check it again.
pub const OPEN_ISSUES: &[&str] = &[];

// Fixed in the commit that added fixtures/regressions/family_stream-*.bin (2026-11-30):
// "robosense-difop-counted-twice" (a DIFOP before any MSOP was counted at each reading); the
// late Hesai packet whose tail time lies went into a sweep with t = u32::MAX (no issue name:
// "family-point-time" caught it).
// Fixed in 8664547, checked again by the fuzz targets (their step-arounds below stay, inert,
// for the next such issue): "decode-t-base-overflow" (now src/sensor/velodyne/decode.rs),
// "nmea-char-boundary" (src/sensor/nmea.rs), "stream-host-time-overflow" (src/time.rs,
// src/sensor/velodyne/sweep.rs), "cli-sensor-name-collision" (src/cli/run.rs).

/// Whether `parse_rmc` may be given these bytes: anything once "nmea-char-boundary" is fixed,
/// ASCII only while it is open.
fn nmea_ok(sentence: &[u8]) -> bool {
    sentence.is_ascii() || check("nmea-char-boundary")
}

/// The NMEA field of a 512-byte position packet, as `PositionPacket::nmea` reads it.
fn nmea_field(payload: &[u8]) -> &[u8] {
    match payload.get(0xCE..0xCE + 128) {
        Some(f) if payload.len() == POSITION_PACKET_LEN => {
            &f[..f.iter().position(|&c| c == 0).unwrap_or(f.len())]
        }
        _ => &[],
    }
}

/// Host times every capture format writes in practice (classic pcap: u32 seconds, to 2106):
/// while "stream-host-time-overflow" is open, the harnesses keep host times in this range.
const SANE_HOST_NS: core::ops::RangeInclusive<i64> = 0..=4_300_000_000_000_000_000;

thread_local! {
    static STRICT: Cell<bool> = const { Cell::new(false) };
}

/// Checks open issues too (regression tests), instead of stepping around them (fuzzing).
pub fn set_strict(on: bool) {
    STRICT.with(|s| s.set(on));
}

/// Whether the check for `issue` runs: always when strict ([`set_strict`], or the environment
/// variable `RINGSCAN_FUZZ_STRICT` set for a fuzz run), else only once it is fixed.
fn check(issue: &str) -> bool {
    static STRICT_ENV: OnceLock<bool> = OnceLock::new();
    STRICT.with(Cell::get)
        || *STRICT_ENV.get_or_init(|| std::env::var_os("RINGSCAN_FUZZ_STRICT").is_some())
        || !OPEN_ISSUES.contains(&issue)
}

const MODES: [ReturnMode; 3] = [ReturnMode::Strongest, ReturnMode::Last, ReturnMode::Dual];

/// Largest UDP payload any datagram can carry (a 16-bit UDP length minus its 8-byte header).
const MAX_UDP_PAYLOAD: usize = 65_535 - 8;

/// Points one data packet can yield: 12 blocks × 32 slots (a dual pair yields at most two
/// points per slot of its two blocks).
const MAX_POINTS_PER_PACKET: usize = BLOCKS * SLOTS;

// ----- input reader ----------------------------------------------------------------------------

/// Reads little-endian numbers off the front of the fuzzer's bytes; past the end, zeros.
pub struct Bytes<'a> {
    data: &'a [u8],
}

impl<'a> Bytes<'a> {
    /// A reader over `data`.
    pub fn new(data: &'a [u8]) -> Self {
        Self { data }
    }

    /// Whether every byte was consumed.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// The next `n` bytes (fewer at the end).
    pub fn take(&mut self, n: usize) -> &'a [u8] {
        let (head, tail) = self.data.split_at(n.min(self.data.len()));
        self.data = tail;
        head
    }

    fn array<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        let head = self.take(N);
        out[..head.len()].copy_from_slice(head);
        out
    }

    /// One byte (0 past the end).
    pub fn u8(&mut self) -> u8 {
        self.array::<1>()[0]
    }

    /// A little-endian u16.
    pub fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.array())
    }

    /// A little-endian u32.
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.array())
    }

    /// A little-endian i64.
    pub fn i64(&mut self) -> i64 {
        i64::from_le_bytes(self.array())
    }
}

// ----- pcap ------------------------------------------------------------------------------------

/// `pcap`: any bytes as a capture. Every datagram is read; the source never panics, returns
/// no more datagrams than there are input bytes, no payload longer than UDP allows, keeps the
/// reassembler within its byte bound, is fused after an error, and its counters add up.
pub fn pcap(data: &[u8]) {
    let Ok(mut src) = PcapSource::new(data) else {
        return;
    };
    let max_bytes = src.reassembler().config().max_bytes;
    let mut datagrams = 0u64;
    let mut failed = false;
    loop {
        match src.next_datagram() {
            Ok(Some(d)) => {
                datagrams += 1;
                assert!(
                    d.payload.len() <= MAX_UDP_PAYLOAD,
                    "payload of {} bytes",
                    d.payload.len()
                );
                assert!(datagrams <= data.len() as u64);
            }
            Ok(None) => break,
            Err(_) => {
                failed = true;
                break;
            }
        }
        assert!(src.reassembler().pending_bytes() <= max_bytes);
    }
    // Fused: after the end or an error, only `Ok(None)`.
    assert!(matches!(src.next_datagram(), Ok(None)));
    let s = src.stats().clone();
    assert_eq!(s.datagrams, datagrams, "{s:?}");
    assert!(s.bytes <= data.len() as u64, "{s:?}");
    assert!(s.datagrams <= s.records, "{s:?}");
    assert!(s.ip_length_overruns <= s.datagrams, "{s:?}");
    assert!(s.fragments_expired <= s.fragments, "{s:?}");
    assert!(s.reassembled <= s.fragments, "{s:?}");
    if let Some(t) = s.truncated_tail {
        assert!(t < data.len() as u64, "{s:?}");
    }
    if s.records > 0 {
        assert!(
            s.first_time_ns.is_some() && s.last_time_ns.is_some(),
            "{s:?}"
        );
    }
    // Every record is one of: an unfragmented datagram, a fragment, skipped (non-UDP,
    // malformed, truncated). A reassembled datagram whose UDP header is bad counts as
    // reassembled and malformed at once, which cancels out.
    let lhs = i128::from(s.records);
    let rhs = i128::from(s.datagrams) - i128::from(s.reassembled)
        + i128::from(s.fragments)
        + i128::from(s.non_udp)
        + i128::from(s.malformed)
        + i128::from(s.truncated_records);
    assert_eq!(lhs, rhs, "records not accounted for: {s:?}");
    if !failed {
        // The end of the file expires every incomplete set.
        assert_eq!(src.reassembler().pending_sets(), 0);
        assert_eq!(src.reassembler().pending_bytes(), 0);
    }
    // The same bytes read ahead on a thread (classic records parsed inside its block instead
    // of copied): the same datagrams, the same error, the same counts.
    let Ok(ahead) = ReadAhead::spawn(Cursor::new(data.to_vec()), "fuzz-read-ahead") else {
        return;
    };
    let Ok(mut fast) = PcapSource::<Cursor<Vec<u8>>>::read_ahead(ahead) else {
        panic!("read ahead refused a header the record buffer took");
    };
    let Ok(mut slow) = PcapSource::new(data) else {
        return;
    };
    assert_eq!(drain_datagrams(&mut fast), drain_datagrams(&mut slow));
    assert_eq!(fast.stats(), slow.stats());
}

type Drained = (
    Vec<(i64, SocketAddrV4, SocketAddrV4, Vec<u8>)>,
    Option<String>,
);

/// Every datagram until the end or the first error (its message).
fn drain_datagrams<R: std::io::Read>(src: &mut PcapSource<R>) -> Drained {
    let mut out = Vec::new();
    loop {
        match src.next_datagram() {
            Ok(Some(d)) => out.push((d.time_ns, d.src, d.dst, d.payload.to_vec())),
            Ok(None) => return (out, None),
            Err(e) => return (out, Some(e.to_string())),
        }
    }
}

// ----- reassembly ------------------------------------------------------------------------------

/// Content of byte `i` of the datagram with key index `k` (keys 2 and 3 carry this pattern,
/// so a datagram completed from them must reproduce it exactly).
fn pattern_byte(k: u8, i: usize) -> u8 {
    (i.wrapping_mul(31) ^ (i >> 8) ^ (usize::from(k) * 97)) as u8
}

fn fragment_key(k: u8) -> FragmentKey {
    FragmentKey {
        src: Ipv4Addr::new(10, 0, 0, 1 + (k & 1)),
        dst: Ipv4Addr::new(10, 0, 0, 100),
        protocol: 17,
        id: u16::from(k >> 1),
    }
}

/// `reassembly`: a configuration, then a sequence of fragment pushes (and expiries) decoded
/// from the bytes. Pending bytes and sets stay within the configured bounds, completed
/// datagrams have the length announced and the content sent, counters stay consistent.
pub fn reassembly(data: &[u8]) {
    let mut b = Bytes::new(data);
    let timeout = b.u16();
    let config = ReassemblyConfig {
        timeout_ns: if timeout == u16::MAX {
            i64::MAX
        } else {
            i64::from(timeout) * 1_000_000
        },
        max_pending: usize::from(b.u8() % 17),
        max_bytes: usize::from(b.u16()) * 4,
    };
    let mut r = Reassembler::new(config);
    let mut time = i64::from(b.u32());
    let mut scratch = Vec::new();
    while !b.is_empty() {
        let op = b.u8();
        let k = op & 3;
        let more = op & 4 != 0;
        match op >> 6 {
            // Time moves by a signed step of up to ±1.27 s; occasionally to an extreme.
            3 if op & 0x38 == 0x38 => {
                time = b.i64();
                r.expire(time);
                continue;
            }
            3 if op & 0x38 == 0x30 => {
                r.expire_all();
                assert_eq!(r.pending_sets(), 0);
                assert_eq!(r.pending_bytes(), 0);
                continue;
            }
            _ => {}
        }
        time = time.saturating_add(i64::from(b.u8() as i8) * 10_000_000);
        let raw_offset = usize::from(b.u16());
        let offset = if op & 8 != 0 {
            raw_offset // possibly misaligned
        } else {
            (raw_offset & 0x1fff) * 8
        };
        let len_raw = usize::from(b.u16());
        let len = if op & 16 != 0 {
            len_raw
        } else {
            (len_raw % 1500) & !7
        };
        scratch.clear();
        if k < 2 {
            // Keys 0 and 1: arbitrary bytes from the input (overlaps may disagree).
            scratch.extend_from_slice(b.take(len));
        } else {
            scratch.extend((offset..offset + len).map(|i| pattern_byte(k, i)));
        }
        let push = r.push(time, fragment_key(k), offset, more, &scratch);
        match push {
            Push::Complete { len } => {
                let done = r.completed();
                assert_eq!(done.len(), len);
                assert!(len <= MAX_IPV4_PAYLOAD);
                assert!(len >= offset + scratch.len() || !more);
                if k >= 2 {
                    for (i, &x) in done.iter().enumerate() {
                        assert_eq!(x, pattern_byte(k, i), "byte {i} of a completed datagram");
                    }
                }
            }
            Push::Pending | Push::Dropped | Push::Rejected(_) => {}
        }
        assert!(
            r.pending_bytes() <= config.max_bytes,
            "{} pending bytes, bound {}",
            r.pending_bytes(),
            config.max_bytes
        );
        assert!(r.pending_sets() <= config.max_pending.max(1));
        let s = r.stats();
        assert!(s.expired_fragments <= s.fragments, "{s:?}");
        assert!(s.duplicates <= s.fragments, "{s:?}");
        assert!(s.reassembled <= s.fragments, "{s:?}");
    }
    r.expire_all();
    assert_eq!(r.pending_sets(), 0);
    assert_eq!(r.pending_bytes(), 0);
}

// ----- calibrations ----------------------------------------------------------------------------

/// Evenly spread elevations from −24.9° to +2°, interleaved so ring ≠ laser id, with small
/// rotational corrections: a table for models without a built-in one.
pub fn spread(n: usize) -> VelodyneCalibration {
    let lasers = (0..n)
        .map(|i| {
            let k = if i % 2 == 0 { i / 2 } else { n / 2 + i / 2 };
            let deg = -24.9 + 26.9 * k as f64 / (n - 1) as f64;
            LaserCalibration::angles(
                i as u16,
                deg.to_radians(),
                ((i % 4) as f64 - 1.5).to_radians() * 0.5,
            )
        })
        .collect();
    VelodyneCalibration {
        lasers,
        distance_resolution: None,
        advanced: false,
        source: "fuzz spread".into(),
    }
    .validate()
    .expect("spread table is valid")
}

/// Maps a byte onto [-limit, limit].
fn scaled(byte: u8, limit: f64) -> f64 {
    (f64::from(byte) / 127.5 - 1.0) * limit
}

/// A calibration for `model`: 0 = built-in (or spread), 1 = spread, 2 = HDL-64E style
/// corrections taken from `bytes`, 3 = every value at its validated extreme (bit 2: flagged
/// `advanced`, else applied as plain offsets).
fn calibration(model: VelodyneModel, variant: u8, bytes: &[u8]) -> VelodyneCalibration {
    let n = model.lasers();
    match variant & 3 {
        0 => builtin(model).unwrap_or_else(|| spread(n)),
        1 => spread(n),
        2 => {
            let at = |i: usize| bytes.get(i % bytes.len().max(1)).copied().unwrap_or(0);
            let lasers = (0..n)
                .map(|i| {
                    let o = i * 7;
                    LaserCalibration {
                        dist_correction: scaled(at(o), 10.0),
                        dist_correction_x: scaled(at(o + 1), 10.0),
                        dist_correction_y: scaled(at(o + 2), 10.0),
                        vert_offset_correction: scaled(at(o + 3), 10.0),
                        horiz_offset_correction: scaled(at(o + 4), 10.0),
                        ..LaserCalibration::angles(
                            i as u16,
                            scaled(at(o + 5), core::f64::consts::FRAC_PI_2),
                            scaled(at(o + 6), core::f64::consts::PI),
                        )
                    }
                })
                .collect();
            VelodyneCalibration {
                lasers,
                distance_resolution: Some(0.001 + f64::from(at(n * 7)) / 2600.0),
                advanced: true,
                source: "fuzz corrections".into(),
            }
            .validate()
            .expect("fuzz corrections are within the validated ranges")
        }
        _ => {
            let lasers = (0..n)
                .map(|i| {
                    let s = if i % 2 == 0 { 1.0 } else { -1.0 };
                    LaserCalibration {
                        dist_correction: 10.0 * s,
                        dist_correction_x: -10.0 * s,
                        dist_correction_y: 10.0,
                        vert_offset_correction: -10.0 * s,
                        horiz_offset_correction: 10.0 * s,
                        ..LaserCalibration::angles(
                            i as u16,
                            core::f64::consts::FRAC_PI_2 * s,
                            core::f64::consts::PI * s,
                        )
                    }
                })
                .collect();
            VelodyneCalibration {
                lasers,
                distance_resolution: Some(0.1),
                advanced: variant & 4 != 0,
                source: "fuzz extremes".into(),
            }
            .validate()
            .expect("extreme table is valid")
        }
    }
}

/// The largest |coordinate| a point decoded with `calib` can have: the largest encodable
/// range (65535 units + the distance correction), grown by the HDL-64E two-point
/// interpolation (which scales with range) and the beam-origin offsets.
fn coordinate_bound(model: VelodyneModel, calib: &VelodyneCalibration) -> f64 {
    let res = model
        .fixed_distance_resolution()
        .or(calib.distance_resolution)
        .unwrap_or(model.distance_resolution());
    let m = calib
        .lasers
        .iter()
        .flat_map(|l| {
            [
                l.dist_correction,
                l.dist_correction_x,
                l.dist_correction_y,
                l.vert_offset_correction,
                l.horiz_offset_correction,
            ]
        })
        .fold(0f64, |a, v| a.max(v.abs()));
    let d = 65_535.0 * res + m;
    let two_point = if calib.advanced {
        // |(dc − dcx)·(xx − 2.4)/22.64 + dcx − dc| with |xx| ≤ d + 2m.
        2.0 * m * (d + 2.0 * m + 2.4) / 22.64 + 2.0 * m
    } else {
        0.0
    };
    (d + two_point + 2.0 * m) * 1.001 + 1e-3
}

/// Checks one decoded point against the model, calibration and packet span.
fn check_point(p: &Point, model: VelodyneModel, bound: f64, t_max: u32, dual: bool) {
    for (name, v) in [("x", p.x), ("y", p.y), ("z", p.z)] {
        assert!(v.is_finite(), "{model}: {name} = {v} in {p:?}");
        assert!(
            f64::from(v).abs() <= bound,
            "{model}: |{name}| = {v} beyond the encodable {bound} m in {p:?}"
        );
    }
    assert!(
        p.intensity.is_finite() && (0.0..=255.0).contains(&p.intensity),
        "{p:?}"
    );
    assert_eq!(p.intensity.fract(), 0.0, "{p:?}");
    assert!(usize::from(p.ring) < model.lasers(), "{model}: {p:?}");
    assert!(p.ret == 0 || (dual && p.ret == 1), "{model}: {p:?}");
    assert_eq!(p.pad, 0);
    assert!(
        p.t <= t_max,
        "{model}: t = {} past the packet span {t_max}",
        p.t
    );
}

/// What a decoder must emit for a packet, in its order: (raw distance, reflectivity, laser,
/// return), before the range filter.
fn expected_measurements(
    model: VelodyneModel,
    mode: ReturnMode,
    p: &DataPacket<'_>,
) -> Vec<(u16, u8, usize, u8)> {
    let bpf = model.blocks_per_firing(mode);
    let banks = if model.is_hdl64() {
        2
    } else if model == VelodyneModel::Vls128 {
        4
    } else {
        1
    };
    let mut out = Vec::new();
    if mode.is_dual() {
        // (last-return block, strongest-return block, bank) of every pair, in packet order.
        let mut pairs = Vec::new();
        if model == VelodyneModel::Vls128 {
            // One column: bank b's last return in block 2b, its strongest in 2b + 1; blocks
            // 8-11 empty (velodyne_decoder 3.1.0 `unpack_vls128`).
            pairs.extend((0..4).map(|bank| (2 * bank, 2 * bank + 1, bank)));
        } else {
            let half = bpf / 2;
            for g in (0..BLOCKS).step_by(bpf) {
                for k in 0..half {
                    if g + half + k >= BLOCKS {
                        continue;
                    }
                    // Which block of the pair holds the last return is the model's documented
                    // convention (HDL-64E: the strongest comes first).
                    let (lb, sb) = if model.dual_strongest_first() {
                        (g + half + k, g + k)
                    } else {
                        (g + k, g + half + k)
                    };
                    pairs.push((lb, sb, (lb % bpf) % banks));
                }
            }
        }
        for (lb, sb, bank) in pairs {
            for s in 0..SLOTS {
                let laser = model.laser_of(bank, s);
                let (dl, ds) = (p.distance(lb, s), p.distance(sb, s));
                if dl == ds {
                    out.push((ds, p.reflectivity(sb, s), laser, 0));
                } else {
                    out.push((dl, p.reflectivity(lb, s), laser, 1));
                    out.push((ds, p.reflectivity(sb, s), laser, 0));
                }
            }
        }
    } else {
        for b in 0..BLOCKS {
            let bank = (b % bpf) % banks;
            for s in 0..SLOTS {
                out.push((
                    p.distance(b, s),
                    p.reflectivity(b, s),
                    model.laser_of(bank, s),
                    0,
                ));
            }
        }
    }
    out
}

/// Latest firing offset of any slot of a packet, ns.
fn packet_span_ns(model: VelodyneModel, mode: ReturnMode) -> u32 {
    (0..BLOCKS)
        .flat_map(|b| (0..SLOTS).map(move |s| (b, s)))
        .map(|(b, s)| model.firing(mode, b, s).0)
        .fold(0f64, f64::max)
        .ceil() as u32
}

/// Writes block flags of `model`'s layout in `mode` into a packet buffer.
fn fix_layout(buf: &mut [u8; DATA_PACKET_LEN], model: VelodyneModel, mode: ReturnMode) {
    let bpf = model.blocks_per_firing(mode);
    let banks = if model.is_hdl64() {
        2
    } else if model == VelodyneModel::Vls128 {
        4
    } else {
        1
    };
    for b in 0..BLOCKS {
        let bank = if model == VelodyneModel::Vls128 && mode.is_dual() {
            (b / 2) % 4
        } else {
            (b % bpf) % banks
        };
        let flag = [FLAG_UPPER, FLAG_LOWER, FLAG_BANK2, FLAG_BANK3][bank];
        buf[b * 100..b * 100 + 2].copy_from_slice(&flag.to_le_bytes());
    }
}

// ----- velodyne_packet -------------------------------------------------------------------------

/// `velodyne_packet`: byte 0 chooses the calibration variant (bits 0–2), the range filter
/// (bit 3) and whether to repair the block flags (bit 5) / azimuths (bit 6); the rest is a payload (data packet: 1206 bytes, zero-padded
/// or cut; the raw rest is also tried as a position packet and an NMEA sentence). The payload is
/// decoded with every model in every return mode: at most 384 points, every
/// coordinate finite and within the largest encodable range, `t` within the packet span, and —
/// for tables without HDL-64E corrections — each point at the distance its measurement encodes.
pub fn velodyne_packet(data: &[u8]) {
    let Some((&sel, rest)) = data.split_first() else {
        return;
    };
    // Position packets and NMEA.
    if let Ok(pos) = PositionPacket::new(rest) {
        let _ = pos.pps().name();
        let _ = pos.timestamp_us();
        let nmea = pos.nmea();
        assert!(nmea.len() <= 128);
        if nmea_ok(nmea) {
            let _ = parse_rmc(nmea);
        }
    }
    if nmea_ok(rest) {
        let _ = parse_rmc(rest);
    }
    let _ = DataPacket::new(rest);

    let mut buf = [0u8; DATA_PACKET_LEN];
    let n = rest.len().min(DATA_PACKET_LEN);
    buf[..n].copy_from_slice(&rest[..n]);
    let layout_model = ALL_MODELS[usize::from(buf[1205]) % ALL_MODELS.len()];
    let layout_mode = MODES[usize::from(buf[1204]) % 3];
    if sel & 0x20 != 0 {
        fix_layout(&mut buf, layout_model, layout_mode);
    }
    if sel & 0x40 != 0 {
        for b in 0..BLOCKS {
            let o = b * 100 + 2;
            let az = u16::from_le_bytes([buf[o], buf[o + 1]]) % 36_001;
            buf[o..o + 2].copy_from_slice(&az.to_le_bytes());
        }
    }
    let Ok(p) = DataPacket::new(&buf) else {
        return;
    };
    for b in 0..BLOCKS {
        assert!(p.azimuth(b) < 36_000);
        assert!(p.bank(b).is_some());
    }
    let _ = (p.looks_dual(), p.looks_like_hdl64(), p.timestamp_us());

    let opts = if sel & 0x08 != 0 {
        DecodeOptions {
            min_range: f32::from(rest.get(1206).copied().unwrap_or(7)) * 0.15,
            max_range: 40.0 + f32::from(rest.get(1207).copied().unwrap_or(0)),
        }
    } else {
        DecodeOptions::default()
    };
    let mut points = Vec::new();
    for model in ALL_MODELS {
        let calib = calibration(model, sel & 7, rest);
        let bound = coordinate_bound(model, &calib);
        let res = model
            .fixed_distance_resolution()
            .or(calib.distance_resolution)
            .unwrap_or(model.distance_resolution());
        let rings = calib.rings();
        for mode in MODES {
            let dec = VelodyneDecoder::new(model, mode, &calib, opts).expect("decoder builds");
            let _ = dec.check_layout(&p);
            let t_max = packet_span_ns(model, mode);
            points.clear();
            let n = dec.decode(&p, 0, &mut points);
            assert_eq!(n.points, points.len());
            assert!(points.len() <= MAX_POINTS_PER_PACKET, "{model} {mode}");
            assert!(
                n.points + n.empty <= MAX_POINTS_PER_PACKET,
                "{model} {mode}: {n:?}"
            );
            for pt in &points {
                check_point(pt, model, bound, t_max, mode.is_dual());
            }
            if !calib.advanced {
                // Independent of the decoder's tables: the measurements in packet order,
                // each at |p − beam origin| = raw · resolution + distance correction.
                let expected: Vec<_> = expected_measurements(model, mode, &p)
                    .into_iter()
                    .filter(|&(raw, _, laser, _)| {
                        let d = f32::from(raw) * res as f32
                            + calib.lasers[laser].dist_correction as f32;
                        raw != 0 && d >= opts.min_range && d <= opts.max_range
                    })
                    .collect();
                assert_eq!(
                    expected.len(),
                    points.len(),
                    "{model} {mode}: points emitted"
                );
                for (pt, &(raw, refl, laser, ret)) in points.iter().zip(&expected) {
                    let l = &calib.lasers[laser];
                    let d = f64::from(raw) * res + l.dist_correction;
                    let got = (f64::from(pt.x).powi(2)
                        + f64::from(pt.y).powi(2)
                        + (f64::from(pt.z) - l.vert_offset_correction).powi(2))
                    .sqrt();
                    assert!(
                        (got - d.abs()).abs() <= 1e-3 + 1e-5 * d.abs(),
                        "{model} {mode}: laser {laser} raw {raw}: range {got}, expected {d}"
                    );
                    assert_eq!(pt.ring, rings[laser], "{model} {mode}");
                    assert_eq!(pt.intensity, f32::from(refl), "{model} {mode}");
                    assert_eq!(pt.ret, ret, "{model} {mode}");
                }
            }
            // Partial and degenerate block ranges, extreme time bases: no panic, same bounds.
            let bpf = dec.blocks_per_firing();
            #[allow(clippy::reversed_empty_ranges)]
            let ranges = [0..bpf, bpf..BLOCKS, 5..3, 11..40, 40..50];
            for range in ranges {
                points.clear();
                let n = dec.decode_blocks(&p, range, 0, &mut points);
                assert_eq!(n.points, points.len());
                assert!(points.len() <= MAX_POINTS_PER_PACKET);
            }
            // `t` is clamped to the u32 range.
            for (base, want) in [
                (i64::MIN / 2, Some(0)),
                (-1, None),
                (i64::MAX / 2, Some(u32::MAX)),
                (i64::MIN, Some(0)),
                (i64::MAX, Some(u32::MAX)),
            ] {
                if (base == i64::MIN || base == i64::MAX) && !check("decode-t-base-overflow") {
                    continue;
                }
                points.clear();
                dec.decode(&p, base, &mut points);
                if let Some(want) = want {
                    assert!(points.iter().all(|pt| pt.t == want), "{model} {mode}");
                }
            }
        }
    }
}

// ----- velodyne_stream -------------------------------------------------------------------------

/// A valid RMC sentence (with its checksum) for the given time of day and date.
fn rmc_sentence(secs_of_day: u32, day: u8, month: u8, yy: u8, valid: bool) -> String {
    let body = format!(
        "GPRMC,{:02}{:02}{:02},{},3707.8324,N,12139.2864,W,000.0,144.7,{:02}{:02}{:02},013.8,E,D",
        (secs_of_day / 3600) % 24,
        (secs_of_day / 60) % 60,
        secs_of_day % 60,
        if valid { 'A' } else { 'V' },
        1 + day % 28,
        1 + month % 12,
        yy % 100
    );
    let cs = body.bytes().fold(0u8, |a, c| a ^ c);
    format!("${body}*{cs:02X}\r\n")
}

/// Builds a data packet from a few parameters: the layout of a model and mode, block azimuths
/// from a start and a per-block step, distances from a seed.
fn synth_data_packet(b: &mut Bytes<'_>, toh_us: u32) -> [u8; DATA_PACKET_LEN] {
    let sel = b.u8();
    let model = ALL_MODELS[usize::from(sel & 7) % ALL_MODELS.len()];
    let mode = MODES[usize::from(sel >> 3 & 3) % 3];
    let az0 = b.u16() % 36_000;
    let step = b.u16() as i16;
    let seed = b.u8();
    let mut buf = [0u8; DATA_PACKET_LEN];
    fix_layout(&mut buf, model, mode);
    let bpf = model.blocks_per_firing(mode);
    for blk in 0..BLOCKS {
        let o = blk * 100;
        let firing = (blk / bpf) as i32;
        let az = (i32::from(az0) + firing * i32::from(step)).rem_euclid(36_000) as u16;
        buf[o + 2..o + 4].copy_from_slice(&az.to_le_bytes());
        for s in 0..SLOTS {
            let m = o + 4 + 3 * s;
            let v = (usize::from(seed) * 131 + blk * 17 + s * 7) % 251;
            let d: u16 = if v % 7 == 0 {
                0
            } else if seed & 0x80 != 0 {
                (v as u16) * 261
            } else {
                (v as u16) * 13 + 500
            };
            buf[m..m + 2].copy_from_slice(&d.to_le_bytes());
            buf[m + 2] = v as u8;
        }
    }
    buf[1200..1204].copy_from_slice(&toh_us.to_le_bytes());
    buf[1204] = if sel & 0x40 != 0 { sel } else { mode.byte() };
    buf[1205] = if sel & 0x80 != 0 {
        b.u8()
    } else {
        model.product_id().unwrap_or(0)
    };
    buf
}

#[derive(Default)]
struct StreamCheck {
    keep_columns: bool,
    sweeps: Vec<u64>,
    next_index: Vec<u64>,
    points: Vec<u64>,
}

impl StreamCheck {
    fn on_sweep(&mut self, idx: usize, sweep: &Sweep, facts: &SensorFacts) {
        if self.sweeps.len() <= idx {
            self.sweeps.resize(idx + 1, 0);
            self.points.resize(idx + 1, 0);
            self.next_index.resize(idx + 1, 0);
        }
        self.sweeps[idx] += 1;
        self.points[idx] += sweep.points.len() as u64;
        assert_eq!(
            sweep.index, self.next_index[idx],
            "sweep indices are consecutive"
        );
        self.next_index[idx] += 1;
        assert!(sweep.packets >= 1);
        assert!(
            sweep.points.len() <= MAX_POINTS_PER_PACKET * sweep.packets as usize,
            "{} points from {} packets",
            sweep.points.len(),
            sweep.packets
        );
        assert!(sweep.first_azimuth < 36_000 && sweep.last_azimuth < 36_000);
        let model = facts.model.expect("a sweep has a model");
        let dual = facts.mode.is_some_and(ReturnMode::is_dual);
        for p in &sweep.points {
            assert!(
                p.x.is_finite() && p.y.is_finite() && p.z.is_finite(),
                "{p:?}"
            );
            assert!(
                p.x.abs() < 7_000.0 && p.y.abs() < 7_000.0 && p.z.abs() < 7_000.0,
                "{p:?}"
            );
            assert!(usize::from(p.ring) < model.lasers(), "{p:?}");
            assert!(p.ret == 0 || dual, "{p:?}");
        }
        if self.keep_columns {
            assert_eq!(sweep.columns.len(), sweep.points.len());
            assert!(sweep
                .columns
                .iter()
                .all(|&c| c < sweep.columns_count.max(1) + 24));
            let img = Organized::from_sweep(sweep, model.lasers()).expect("columns kept");
            assert_eq!(img.points.len(), img.layers * img.rows * img.cols);
        }
    }
}

/// `velodyne_stream`: a stream configuration, then a sequence of datagrams (raw or synthesised
/// data packets, position packets with or without valid NMEA, other sizes) from a few source
/// addresses with host times moving by signed steps or jumping to extremes, through
/// [`Demux`] into [`ringscan::sensor::velodyne::VelodyneStream`]s. Sweeps and points are bounded per
/// packet (and so per input byte), indices are consecutive, and the counters add up.
pub fn velodyne_stream(data: &[u8]) {
    let mut b = Bytes::new(data);
    let c0 = b.u8();
    let model = (c0 & 8 != 0).then(|| ALL_MODELS[usize::from(c0 & 7) % ALL_MODELS.len()]);
    let keep_columns = c0 & 0x10 != 0;
    let calibrations = if c0 & 0x20 != 0 {
        vec![spread(16), spread(32), spread(64), spread(128)]
    } else if c0 & 0x04 != 0 && c0 & 0x08 == 0 {
        vec![spread(32)]
    } else {
        Vec::new()
    };
    let max_gap_ns = if c0 & 0x40 != 0 {
        1_000_000
    } else {
        1_000_000_000
    };
    let max_sweep_ns = if c0 & 0x80 != 0 {
        10_000_000
    } else {
        1_000_000_000
    };
    let cut_angle = b.u16() % 36_000;
    let data_port = (b.u8() & 1 == 1).then_some(2368);
    let cfg = StreamConfig {
        model,
        calibrations,
        cut_angle,
        max_gap_ns,
        max_sweep_ns,
        keep_columns,
        ..StreamConfig::default()
    };
    let velodyne_only = move |d: &FirstDatagram<'_>| -> Option<Claimed> {
        matches!(d.payload.len(), DATA_PACKET_LEN | POSITION_PACKET_LEN)
            .then(|| Ok(Box::new(VelodyneStream::new(cfg.clone())) as Box<dyn SensorStream>))
    };
    let mut demux = Demux::new(Box::new(velodyne_only), data_port);
    let mut seen = StreamCheck {
        keep_columns,
        ..StreamCheck::default()
    };
    let mut host = 1_700_000_000_000_000_000i64;
    let mut toh = b.u32();
    let mut pushes = 0u64;
    let mut data_pushes = 0u64;
    let mut extra_replays = 0u64;
    while !b.is_empty() {
        let op = b.u8();
        let src = if op & 0x10 != 0 {
            Ipv4Addr::new(10, 1, b.u8() % 2, b.u8())
        } else {
            Ipv4Addr::new(10, 0, 0, 1 + ((op >> 2) & 3))
        };
        if op & 0x20 != 0 && op & 3 == 3 {
            host = b.i64();
        } else {
            host = host.saturating_add(i64::from(b.u16() as i16) * 10_000);
        }
        if !check("stream-host-time-overflow") {
            host = host.clamp(*SANE_HOST_NS.start(), *SANE_HOST_NS.end());
        }
        let port = if op & 0x40 != 0 { 2369 } else { 2368 };
        let payload: Vec<u8> = match op & 3 {
            0 => {
                let mut v = b.take(DATA_PACKET_LEN).to_vec();
                v.resize(DATA_PACKET_LEN, 0);
                v
            }
            1 => {
                let dt = if op & 0x80 != 0 {
                    b.u32()
                } else {
                    u32::from(b.u16())
                };
                toh = toh.wrapping_add(dt);
                synth_data_packet(&mut b, toh).to_vec()
            }
            2 => {
                let kind = b.u8();
                let stamp = b.u32();
                let nmea = match kind & 3 {
                    0 => String::new(),
                    1 | 2 => rmc_sentence(b.u32(), b.u8(), b.u8(), b.u8(), kind & 1 == 1),
                    _ => String::from_utf8_lossy(b.take(usize::from(kind >> 2))).into_owned(),
                };
                let mut v = vec![0u8; POSITION_PACKET_LEN];
                v[0xC6..0xCA].copy_from_slice(&stamp.to_le_bytes());
                v[0xCA] = kind >> 5;
                let n = nmea.len().min(127);
                v[0xCE..0xCE + n].copy_from_slice(&nmea.as_bytes()[..n]);
                v
            }
            _ => {
                let len = usize::from(b.u16()) % 1300;
                b.take(len).to_vec()
            }
        };
        let mut payload = payload;
        if !nmea_ok(nmea_field(&payload)) {
            // Keep the sentence ASCII while "nmea-char-boundary" is open.
            for c in &mut payload[0xCE..0xCE + 128] {
                *c &= 0x7f;
            }
        }
        pushes += 1;
        if payload.len() == DATA_PACKET_LEN {
            data_pushes += 1;
        }
        let r = demux.push(host, src, port, &payload, &mut |idx, s, f| {
            if let Some(f) = f.as_any().downcast_ref::<SensorFacts>() {
                seen.on_sweep(idx, s, f)
            }
        });
        if r.is_err() {
            // The stream keeps its packets for detection and may replay them later.
            extra_replays += 1;
        }
    }
    let finished = demux.finish(&mut |idx, s, f| {
        if let Some(f) = f.as_any().downcast_ref::<SensorFacts>() {
            seen.on_sweep(idx, s, f)
        }
    });
    // Streams after one that failed to finish never emitted their last sweep (open issue).
    let unfinished_from = match finished {
        Err((idx, _)) if !check("demux-finish-stops-at-first-error") => idx + 1,
        _ => usize::MAX,
    };

    let ds = demux.stats();
    assert_eq!(
        ds.routed + ds.ignored + ds.other_port + ds.dropped_sensor_limit,
        pushes,
        "{ds:?}"
    );
    let mut total_points = 0u64;
    for (idx, (_, stream, ports)) in demux.sensors().enumerate() {
        let Some(stream) = stream.as_any().downcast_ref::<VelodyneStream>() else {
            continue;
        };
        let st = stream.stats();
        assert!(ports.len() <= 16);
        // A packet held for detection is decoded once, whenever detection succeeds.
        assert!(st.data_packets <= data_pushes, "{st:?}");
        assert!(
            st.points <= MAX_POINTS_PER_PACKET as u64 * st.data_packets,
            "{st:?}"
        );
        // Each decoded packet opens at most one sweep per firing group plus one.
        assert!(st.sweeps <= (BLOCKS as u64 + 1) * st.data_packets, "{st:?}");
        if idx < unfinished_from {
            // Every sweep counted was handed over, with every point counted.
            assert_eq!(
                st.sweeps,
                seen.sweeps.get(idx).copied().unwrap_or(0),
                "{st:?}"
            );
            assert_eq!(
                st.points,
                seen.points.get(idx).copied().unwrap_or(0),
                "{st:?}"
            );
        }
        total_points += st.points;
    }
    assert!(demux.sensors().count() <= ringscan::sweep::demux::MAX_SENSORS);
    assert!(total_points <= MAX_POINTS_PER_PACKET as u64 * data.len() as u64);
    let _ = extra_replays;
}

// ----- calib_velodyne --------------------------------------------------------------------------

/// Checks every invariant a parsed calibration promises.
pub fn check_calibration(c: &VelodyneCalibration) {
    let n = c.num_lasers();
    assert!(matches!(n, 16 | 32 | 64 | 128), "{n} lasers");
    for (i, l) in c.lasers.iter().enumerate() {
        assert_eq!(usize::from(l.laser_id), i, "laser ids 0..n in order");
        assert!(
            l.vert_correction.is_finite()
                && l.vert_correction.abs() <= core::f64::consts::FRAC_PI_2
        );
        assert!(l.rot_correction.is_finite() && l.rot_correction.abs() <= core::f64::consts::PI);
        for v in [
            l.dist_correction,
            l.dist_correction_x,
            l.dist_correction_y,
            l.vert_offset_correction,
            l.horiz_offset_correction,
        ] {
            assert!(v.is_finite() && v.abs() <= 10.0, "{l:?}");
        }
        assert!(
            l.focal_distance.is_finite() && l.focal_slope.is_finite(),
            "{l:?}"
        );
        assert!(l.min_intensity <= l.max_intensity, "{l:?}");
    }
    if let Some(r) = c.distance_resolution {
        assert!(r.is_finite() && r > 0.0 && r <= 0.1, "resolution {r}");
    }
    let has_corrections = c.lasers.iter().any(|l| {
        [
            l.dist_correction,
            l.dist_correction_x,
            l.dist_correction_y,
            l.vert_offset_correction,
            l.horiz_offset_correction,
        ]
        .iter()
        .any(|&v| v != 0.0)
    });
    assert_eq!(
        c.advanced, has_corrections,
        "`advanced` is true exactly when a laser has a distance or offset correction"
    );
    // Validation is idempotent.
    assert_eq!(c.clone().validate().expect("a parsed table validates"), *c);
    // Rings are a permutation of 0..n.
    let mut rings = c.rings();
    rings.sort_unstable();
    assert!(rings.iter().enumerate().all(|(i, &r)| usize::from(r) == i));
    // Every model with this many lasers decodes a packet of far returns with it.
    let mut buf = [0u8; DATA_PACKET_LEN];
    let mut points = Vec::new();
    for model in ALL_MODELS.into_iter().filter(|m| m.lasers() == n) {
        for mode in MODES {
            fix_layout(&mut buf, model, mode);
            for blk in 0..BLOCKS {
                let o = blk * 100;
                buf[o + 2..o + 4].copy_from_slice(&((blk as u16) * 3_001).to_le_bytes());
                for s in 0..SLOTS {
                    let m = o + 4 + 3 * s;
                    let d: u16 = if s % 3 == 0 { u16::MAX } else { 1 + s as u16 };
                    buf[m..m + 2].copy_from_slice(&d.to_le_bytes());
                }
            }
            let p = DataPacket::new(&buf).expect("packet is valid");
            let dec = VelodyneDecoder::new(model, mode, c, DecodeOptions::default())
                .expect("a validated table builds a decoder");
            points.clear();
            dec.decode(&p, 0, &mut points);
            let bound = coordinate_bound(model, c);
            let t_max = packet_span_ns(model, mode);
            for pt in &points {
                check_point(pt, model, bound, t_max, mode.is_dual());
            }
        }
    }
}

/// `calib_velodyne`: any bytes as a calibration file (ROS yaml or VeloView xml). No panic;
/// the text and byte entry points agree; a table that parses satisfies every invariant and
/// decodes packets of every model with its laser count.
pub fn calib_velodyne(data: &[u8]) {
    let from_bytes = parse_velodyne_bytes(data, "fuzz.yaml");
    match core::str::from_utf8(data) {
        Ok(text) => {
            let from_text = parse_velodyne(text, "fuzz.yaml");
            match (&from_bytes, &from_text) {
                (Ok(a), Ok(b)) => assert_eq!(a, b),
                (Err(_), Err(_)) => {}
                _ => panic!("parse_velodyne and parse_velodyne_bytes disagree"),
            }
        }
        Err(_) => assert!(from_bytes.is_err(), "non-UTF-8 bytes parsed"),
    }
    if let Ok(c) = from_bytes {
        check_calibration(&c);
    }
}

// ----- decode_to_mcap --------------------------------------------------------------------------

/// An in-memory MCAP output the caller keeps a handle on after the sink is finished.
#[derive(Clone, Default)]
pub struct SharedBuf(Rc<RefCell<Cursor<Vec<u8>>>>);

impl Write for SharedBuf {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.borrow_mut().write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Seek for SharedBuf {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.0.borrow_mut().seek(pos)
    }
}

impl SharedBuf {
    /// The bytes written so far.
    pub fn bytes(&self) -> Vec<u8> {
        self.0.borrow().get_ref().clone()
    }
}

/// Per-sensor output state, as `ringscan decode` keeps it (src/cli/run.rs).
struct OutSensor {
    id: Option<SensorId>,
    registered: bool,
    name: String,
}

struct Out {
    sink: McapSink<SharedBuf>,
    sensors: Vec<OutSensor>,
    single: bool,
    raw: bool,
    error: Option<SinkError>,
    /// Messages written, per topic.
    written: BTreeMap<String, u64>,
    topics: Vec<String>,
}

impl Out {
    /// Registers a sensor with the name and metadata `ringscan decode` gives it.
    fn register_any(&mut self, idx: usize, addr: Ipv4Addr, facts: &dyn Facts, ports: &[u16]) {
        let any = facts.as_any();
        match (
            any.downcast_ref::<SensorFacts>(),
            any.downcast_ref::<OusterFacts>(),
        ) {
            (Some(f), _) => self.register(idx, addr, f, ports),
            (None, None) => {}
            (None, Some(f)) => {
                let mut md = BTreeMap::new();
                md.insert("source_address".to_string(), addr.to_string());
                md.insert("serial".to_string(), f.serial.to_string());
                md.insert("profile".to_string(), f.profile.clone());
                md.insert("mode".to_string(), f.mode.clone());
                md.insert("clock".to_string(), f.clock.name().to_string());
                md.insert("family".to_string(), "ouster".to_string());
                md.insert(
                    "lidar_packet_bytes".to_string(),
                    f.lidar_packet_bytes.to_string(),
                );
                let base = format!("os-{}", addr.octets()[3]);
                self.register_named(idx, addr, base, md);
            }
        }
    }

    fn register(&mut self, idx: usize, addr: Ipv4Addr, facts: &SensorFacts, ports: &[u16]) {
        // The names and metadata `ringscan decode` gives a sensor (src/cli/sensors.rs
        // `default_name`).
        let name = match facts.model {
            Some(m) => format!("{}-{}", m.id(), addr.octets()[3]),
            None => format!("velodyne-{}", addr.octets()[3]),
        };
        let mut md = BTreeMap::new();
        md.insert("source_address".to_string(), addr.to_string());
        md.insert(
            "ports".to_string(),
            ports
                .iter()
                .map(|p| p.to_string())
                .collect::<Vec<_>>()
                .join(","),
        );
        if let Some(m) = facts.model {
            md.insert("model".to_string(), m.name().to_string());
        }
        if let Some(m) = facts.mode {
            md.insert("return_mode".to_string(), m.name().to_string());
        }
        md.insert("model_detection".to_string(), facts.detection.clone());
        md.insert("clock".to_string(), facts.clock.name().to_string());
        md.insert("calibration".to_string(), facts.calibration.clone());
        md.insert("family".to_string(), "velodyne".to_string());
        self.register_named(idx, addr, name, md);
    }

    fn register_named(
        &mut self,
        idx: usize,
        addr: Ipv4Addr,
        mut name: String,
        md: BTreeMap<String, String>,
    ) {
        while self.sensors.len() <= idx {
            self.sensors.push(OutSensor {
                id: None,
                registered: false,
                name: String::new(),
            });
        }
        if self.sensors[idx].registered || self.error.is_some() {
            return;
        }
        // Made unique by the whole address, as src/cli/run.rs `register` does.
        if self.sensors.iter().any(|s| s.registered && s.name == name) {
            let o = addr.octets();
            name = format!("{name}-{}-{}-{}", o[0], o[1], o[2]);
        }
        self.sensors[idx].name = name.clone();
        let single = self.single && idx == 0;
        let topic_prefix = if single {
            String::new()
        } else {
            format!("/{name}")
        };
        let info = SensorInfo {
            name,
            topic_prefix: topic_prefix.clone(),
            metadata: md,
            calibration: None,
        };
        match self.sink.add_sensor(&info) {
            Ok(id) => {
                self.sensors[idx].id = Some(id);
                self.topics.push(topic_prefix);
            }
            Err(e) => self.error = Some(e),
        }
        self.sensors[idx].registered = true;
    }

    fn count(&mut self, topic: String) {
        *self.written.entry(topic).or_insert(0) += 1;
    }

    fn on_sweep(&mut self, idx: usize, addr: Ipv4Addr, sweep: &Sweep, facts: &dyn Facts) {
        if self.error.is_some() {
            return;
        }
        self.register_any(idx, addr, facts, &[]);
        let Some(id) = self.sensors.get(idx).and_then(|s| s.id) else {
            return;
        };
        let msg = SweepMsg {
            log_time_ns: sweep.last_host_ns.max(0) as u64,
            timestamp_ns: sweep.timestamp_ns.max(0) as u64,
            points: &sweep.points,
        };
        let topic = self.sink.channels(id).map(|c| c.points_topic());
        let written = if sweep.extras.len() == sweep.points.len() && !sweep.extras.is_empty() {
            self.sink.write_sweep_extended(id, &msg, &sweep.extras)
        } else {
            self.sink.write_sweep(id, &msg)
        };
        match written {
            Ok(()) => self.count(topic.unwrap_or_default()),
            Err(e) => {
                self.error = Some(e);
                return;
            }
        }
        let diag = serde_like_diagnostics(sweep);
        let topic = self.sink.channels(id).map(|c| c.diagnostics_topic());
        match self
            .sink
            .write_diagnostics(id, sweep.last_host_ns.max(0) as u64, &diag)
        {
            Ok(()) => self.count(topic.unwrap_or_default()),
            Err(e) => self.error = Some(e),
        }
    }
}

/// The per-sweep diagnostics object `ringscan decode` writes.
fn serde_like_diagnostics(sweep: &Sweep) -> serde_json::Value {
    let mut m = serde_json::Map::new();
    m.insert("sweep".into(), sweep.index.into());
    m.insert("packets".into(), sweep.packets.into());
    m.insert("missing_packets".into(), sweep.missing_packets.into());
    m.insert("points".into(), sweep.points.len().into());
    m.insert("columns".into(), sweep.columns_count.into());
    m.insert("span_ns".into(), sweep.span_ns().into());
    m.insert("clock".into(), sweep.clock.name().into());
    m.insert("device_time_ns".into(), sweep.device_time_ns.into());
    m.insert(
        "first_azimuth_deg".into(),
        (f64::from(sweep.first_azimuth) / 100.0).into(),
    );
    serde_json::Value::Object(m)
}

/// Sink errors a capture's contents may legitimately cause (the CLI reports them and still
/// finalises the file); any other is a bug.
fn expected_sink_error(e: &SinkError) -> bool {
    matches!(
        e,
        SinkError::TimestampOutOfRange { .. } | SinkError::TooLarge { .. }
    )
}

/// `decode_to_mcap`: the bytes as a pcap through the decode path of `ringscan decode`
/// (`PcapSource` → `Demux` → `McapSink`, with its sensor naming, diagnostics and optional raw
/// packets), into memory. The sink must finish, and the file must read back with the official
/// `mcap` crate (`Summary::read`, `MessageStream`) holding exactly the messages written. The
/// output format, compression and `--raw` are chosen by the input length.
pub fn decode_to_mcap(data: &[u8]) {
    let variant = data.len() % 12;
    let opts = SinkOptions {
        format: if variant % 2 == 0 {
            Format::Foxglove
        } else {
            Format::Ros2
        },
        compression: [Compression::Zstd, Compression::Lz4, Compression::None][variant / 2 % 3],
        chunk_size: if variant >= 6 { 64 * 1024 } else { 0 },
        zstd_level: [1, -3, 3][variant % 3],
        ..SinkOptions::default()
    };
    let raw = variant % 4 == 3;
    // An Ouster sensor beside the Velodyne ones: datagrams of its lidar or IMU size go to it.
    let ouster = decode_to_mcap_ouster(variant);
    let ouster_lidar = ouster.info.lidar_packet_bytes();
    let ouster_imu = OusterStreamConfig::imu_len_of(&ouster.info);
    let is_ouster = move |n: usize| n == ouster_lidar || Some(n) == ouster_imu;
    // The sensor count first, as the CLI's pre-scan does.
    let Ok(mut pre) = PcapSource::new(data) else {
        return;
    };
    let mut addrs: Vec<Ipv4Addr> = Vec::new();
    while let Ok(Some(d)) = pre.next_datagram() {
        let n = d.payload.len();
        if (n == DATA_PACKET_LEN || is_ouster(n)) && !addrs.contains(d.src.ip()) {
            addrs.push(*d.src.ip());
        }
    }
    let out_buf = SharedBuf::default();
    let sink = McapSink::new(out_buf.clone(), opts).expect("an in-memory sink starts");
    let mut out = Out {
        sink,
        sensors: Vec::new(),
        single: addrs.len() <= 1,
        raw,
        error: None,
        written: BTreeMap::new(),
        topics: Vec::new(),
    };
    let config_for = move |d: &FirstDatagram<'_>| -> Option<Claimed> {
        match d.payload.len() {
            DATA_PACKET_LEN | POSITION_PACKET_LEN => Some(Ok(Box::new(VelodyneStream::new(
                StreamConfig::default(),
            ))
                as Box<dyn SensorStream>)),
            n if is_ouster(n) => Some(
                OusterStream::new(ouster.clone())
                    .map(|s| Box::new(s) as Box<dyn SensorStream>)
                    .map_err(ringscan::sensor::StreamError::Decode),
            ),
            _ => None,
        }
    };
    let mut demux = Demux::new(Box::new(config_for), None);
    let mut src = PcapSource::new(data).expect("opened once already");
    // A source error ends the input, as in the CLI (which then reports it).
    while let Ok(Some(d)) = src.next_datagram() {
        let (time, addr, port, src_port) = (d.time_ns, *d.src.ip(), d.dst.port(), d.src.port());
        if !SANE_HOST_NS.contains(&time) && !check("stream-host-time-overflow") {
            continue;
        }
        if !nmea_ok(nmea_field(d.payload)) {
            continue;
        }
        let routed = demux.push(time, addr, port, d.payload, &mut |idx, sweep, facts| {
            out.on_sweep(idx, addr, sweep, facts);
        });
        let idx = match routed {
            Ok(Some(idx)) => idx,
            Ok(None) => continue,
            Err(_) => break,
        };
        if out.error.is_some() {
            break;
        }
        if !out.sensors.get(idx).is_some_and(|s| s.registered) {
            if let Some((_, stream)) = demux.stream(idx) {
                if stream.ready() {
                    let ports: Vec<u16> = demux
                        .sensors()
                        .nth(idx)
                        .map(|(_, _, p)| p.to_vec())
                        .unwrap_or_default();
                    out.register_any(idx, addr, stream.facts(), &ports);
                }
            }
        }
        // IMU samples, as `ringscan decode` writes them.
        if let Some(s) = demux.stream_mut(idx) {
            let id = out.sensors.get(idx).and_then(|x| x.id);
            let mut samples = Vec::new();
            s.drain_imu(&mut |smp, _| samples.push(*smp));
            for smp in samples {
                let Some(id) = id else { continue };
                if out.error.is_some() {
                    break;
                }
                let msg = serde_json::json!({
                    "timestamp_ns": smp.sensor_ns,
                    "linear_acceleration": smp.accel,
                    "angular_velocity": smp.gyro,
                });
                let topic = out.sink.channels(id).map(|c| c.imu_topic());
                match out.sink.write_imu(id, smp.host_ns.max(0) as u64, &msg) {
                    Ok(()) => out.count(topic.unwrap_or_default()),
                    Err(e) => out.error = Some(e),
                }
            }
        }
        if out.raw {
            if let Some(id) = out.sensors.get(idx).and_then(|s| s.id) {
                let topic = out.sink.channels(id).map(|c| c.raw_topic());
                // `--format ros2` gathers packets into the family's ROS messages (checked
                // against the sink's summary below); the Foxglove output has one per packet.
                let foxglove = out.sink.format() == Format::Foxglove;
                match out.sink.write_raw(
                    id,
                    time.max(0) as u64,
                    SocketAddrV4::new(addr, src_port),
                    port,
                    d.payload,
                ) {
                    Ok(()) if foxglove => out.count(topic.unwrap_or_default()),
                    Ok(()) => {}
                    Err(e) => out.error = Some(e),
                }
            }
        }
        if out.error.is_some() {
            break;
        }
    }
    if out.error.is_none() {
        let addrs: Vec<Ipv4Addr> = demux.sensors().map(|(a, _, _)| a).collect();
        let _ = demux.finish(&mut |idx, sweep, facts| {
            let addr = addrs.get(idx).copied().unwrap_or(Ipv4Addr::UNSPECIFIED);
            out.on_sweep(idx, addr, sweep, facts);
        });
    }
    if let Some(e) = &out.error {
        let name_collision =
            matches!(e, SinkError::InvalidSensor { reason, .. } if reason.contains("already used"));
        let known = name_collision && !check("cli-sensor-name-collision");
        assert!(
            expected_sink_error(e) || known,
            "unexpected sink error: {e}"
        );
    }
    let summary = out.sink.finish().expect("an in-memory sink finishes");
    let bytes = out_buf.bytes();

    // Read back with the official crate.
    let read = mcap::Summary::read(&bytes)
        .expect("the summary reads back")
        .expect("the file has a summary");
    let mut per_topic: BTreeMap<String, u64> = BTreeMap::new();
    let mut last_sequence: BTreeMap<u16, u32> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).expect("the message stream opens") {
        let m = m.expect("every message reads back");
        *per_topic.entry(m.channel.topic.clone()).or_insert(0) += 1;
        let seq = last_sequence.entry(m.channel.id).or_insert(0);
        assert!(m.sequence >= *seq, "sequence numbers go backwards");
        *seq = m.sequence;
    }
    let mut written: BTreeMap<String, u64> =
        out.written.into_iter().filter(|(_, n)| *n > 0).collect();
    // The ROS packet topics of `--format ros2 --raw`: as many read back as the sink says.
    for (topic, n) in &summary.messages {
        let packets = [
            "/velodyne_packets",
            "/lidar_packets",
            "/imu_packets",
            "/metadata",
        ];
        if *n > 0 && packets.iter().any(|p| topic.ends_with(p)) {
            assert_eq!(per_topic.get(topic), Some(n), "{topic} read back");
            written.insert(topic.clone(), *n);
        }
    }
    assert_eq!(per_topic, written, "messages read back = messages written");
    let stats = read.stats.expect("statistics record");
    assert_eq!(stats.message_count, written.values().sum::<u64>());
    for (topic, n) in &summary.messages {
        assert_eq!(
            written.get(topic).copied().unwrap_or(0),
            *n,
            "sink summary for {topic}"
        );
    }
}

// ----- Ouster ----------------------------------------------------------------------------------

use ringscan::sensor::ouster::calib::parse as parse_ouster;
use ringscan::sensor::ouster::calib::OusterInfo;
use ringscan::sensor::ouster::model::HeaderKind;
use ringscan::sensor::ouster::model::Profile;
use ringscan::sensor::ouster::model::ALL_PROFILES;
use ringscan::sensor::ouster::sweep::OusterStream;
use ringscan::sensor::ouster::sweep::OusterStreamConfig;
use ringscan::sensor::ouster::wire::ImuPacketLegacy;
use ringscan::sensor::ouster::wire::ImuPacketNmea;
use ringscan::sensor::ouster::wire::LidarPacket;
use ringscan::sensor::ouster::wire::ZonePacket;
use ringscan::sensor::ouster::wire::ZONE_PACKET_BYTES;
use ringscan::sensor::ouster::OusterDecoder;

/// Largest range, metres, the range field of a profile can carry (its width and shift).
fn ouster_max_range_m(profile: Profile) -> f64 {
    let f = profile.layout().range;
    let raw_max = if f.width >= 32 {
        f64::from(u32::MAX)
    } else {
        f64::from((1u32 << f.width) - 1)
    };
    raw_max * f64::from(1u32 << f.shift) / 1000.0
}

/// Bound on any decoded coordinate, metres: the parser keeps rotation entries in [−1, 1]
/// (a 3 × 3 matrix of those stretches a vector at most 3×) and translations within 10 m, and
/// the point is `lidar_to_sensor · (range · direction + beam offset)`.
fn ouster_coordinate_bound(info: &OusterInfo) -> f64 {
    let beam = info.lidar_origin_to_beam_origin_mm.abs() / 1000.0
        + info.beam_to_lidar[3].abs() / 1000.0
        + info.beam_to_lidar[7].abs() / 1000.0
        + info.beam_to_lidar[11].abs() / 1000.0;
    3.0 * (ouster_max_range_m(info.format.profile) + beam) + 10.0 + 1e-3
}

/// Metadata JSON (the current nested form) for a sensor chosen by the fuzzer's bytes: profile,
/// lidar mode, beam count, IMU profile, beam angles, beam-origin offset, firmware. Returns the
/// text; the parser decides whether it is valid (the angles come from the input).
fn ouster_metadata(b: &mut Bytes<'_>) -> String {
    let profile = ALL_PROFILES[usize::from(b.u8()) % ALL_PROFILES.len()];
    let (w, fps) = [
        (512, 10),
        (1024, 10),
        (2048, 10),
        (512, 20),
        (1024, 20),
        (4096, 5),
    ][usize::from(b.u8()) % 6];
    let h = [16usize, 32, 64, 128][usize::from(b.u8()) % 4];
    let cpp = [16usize, 8, 4, 32][usize::from(b.u8()) % 4];
    let sel = b.u8();
    let imu = if profile == Profile::Legacy || sel & 1 == 0 {
        "LEGACY"
    } else {
        "ACCEL32_GYRO32_NMEA"
    };
    let firmware = ["v2.5.2", "v2.3.0", "v3.1.0", "v2.0.0"][usize::from(sel >> 1) % 4];
    let scale = |v: u8, lim: f64| (f64::from(v) / 255.0 * 2.0 - 1.0) * lim;
    let alt: Vec<f64> = (0..h).map(|_| scale(b.u8(), 45.0)).collect();
    let az: Vec<f64> = (0..h).map(|_| scale(b.u8(), 10.0)).collect();
    let shift: Vec<i64> = (0..h).map(|_| i64::from(b.u8() % 64) - 32).collect();
    let offset_mm = scale(b.u8(), 100.0);
    let first = usize::from(b.u16()) % w;
    let last = usize::from(b.u16()) % w;
    serde_json::json!({
        "sensor_info": {
            "prod_line": format!("OS-1-{h}"),
            "prod_sn": "992210000957",
            "build_rev": firmware,
            "image_rev": format!("ousteros-image-prod-aries-{firmware}+20230101000000"),
            "initialization_id": 5_431_293,
        },
        "beam_intrinsics": {
            "beam_altitude_angles": alt,
            "beam_azimuth_angles": az,
            "lidar_origin_to_beam_origin_mm": offset_mm,
        },
        "imu_intrinsics": {
            "imu_to_sensor_transform": [1, 0, 0, 6.253, 0, 1, 0, -11.775, 0, 0, 1, 7.645, 0, 0, 0, 1],
        },
        "lidar_intrinsics": {
            "lidar_to_sensor_transform": [-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 36.18, 0, 0, 0, 1],
        },
        "config_params": {
            "lidar_mode": format!("{w}x{fps}"),
            "udp_port_lidar": 7502,
            "udp_port_imu": 7503,
            "udp_dest": "10.0.0.1",
            "udp_profile_lidar": profile.name(),
            "udp_profile_imu": imu,
        },
        "lidar_data_format": {
            "columns_per_frame": w,
            "columns_per_packet": cpp,
            "pixels_per_column": h,
            "pixel_shift_by_row": shift,
            "column_window": [first, last],
            "udp_profile_lidar": profile.name(),
            "udp_profile_imu": imu,
        },
        "imu_data_format": { "imu_measurements_per_packet": 8 },
        "calibration_status": { "reflectivity": { "valid": true } },
    })
    .to_string()
}

/// Invariants of a parsed Ouster calibration, and of the decoder and stream built from it.
pub fn check_ouster_info(info: &OusterInfo) {
    let h = info.pixels_per_column();
    let w = info.columns_per_frame;
    assert!([16, 32, 64, 128].contains(&h), "H = {h}");
    assert!([512, 1024, 2048, 4096].contains(&w), "W = {w}");
    assert_eq!(info.beam_altitude_angles.len(), h);
    assert_eq!(info.beam_azimuth_angles.len(), h);
    assert_eq!(info.pixel_shift_by_row.len(), h);
    assert!(info
        .pixel_shift_by_row
        .iter()
        .all(|s| s.unsigned_abs() < w as u32));
    assert!(info.columns_per_packet() > 0 && w % info.columns_per_packet() == 0);
    assert!(info.column_window.0 < w && info.column_window.1 < w);
    assert!(info.lidar_packet_bytes() <= MAX_UDP_PAYLOAD);
    let in_window = (0..w).filter(|&c| info.is_column_in_window(c)).count();
    assert_eq!(in_window, info.columns_in_window());
    assert!(info.expected_packets_per_frame() <= w);
    for m in [
        &info.beam_to_lidar,
        &info.lidar_to_sensor,
        &info.imu_to_sensor,
    ] {
        assert!(m.iter().all(|v| v.is_finite()));
    }
    assert!(info.beam_altitude_angles.iter().all(|a| a.is_finite()));
    assert!(info.beam_azimuth_angles.iter().all(|a| a.is_finite()));
    if let Some(n) = OusterStreamConfig::imu_len_of(info) {
        assert!(n <= MAX_UDP_PAYLOAD);
    }
    if info.lidar_off {
        return;
    }
    // A valid calibration makes a decoder whose every pixel direction is finite and unit-ish.
    let dec = OusterDecoder::new(info).expect("a parsed calibration makes a decoder");
    let bound = ouster_coordinate_bound(info);
    for row in 0..h {
        for col in [0, w / 3, w - 1] {
            let (d, o) = dec.lut(row, col).expect("inside the frame");
            assert!(d.iter().chain(&o).all(|v| v.is_finite()));
            let far = dec
                .xyz(
                    row,
                    col,
                    (ouster_max_range_m(info.format.profile) * 1000.0) as u32,
                )
                .expect("inside the frame");
            assert!(far
                .iter()
                .all(|v| v.is_finite() && f64::from(v.abs()) <= bound));
        }
    }
    assert!(dec.rings().iter().all(|&r| usize::from(r) < h));
    let mut rings = dec.rings().to_vec();
    rings.sort_unstable();
    rings.dedup();
    assert_eq!(rings.len(), h, "rings are a permutation of 0..H");
}

/// `calib_ouster`: any bytes as Ouster metadata JSON. Never a panic; a file that parses is
/// internally consistent and makes a decoder with finite, bounded geometry. The first input
/// byte can also select a generated, mostly valid file mutated by the rest.
pub fn calib_ouster(data: &[u8]) {
    let generated;
    let text = match data.split_first() {
        Some((&0xA5, rest)) => {
            generated = ouster_metadata(&mut Bytes::new(rest));
            generated.as_str()
        }
        _ => match core::str::from_utf8(data) {
            Ok(t) => t,
            Err(_) => return,
        },
    };
    if let Ok(info) = parse_ouster(text, "fuzz.json") {
        check_ouster_info(&info);
    }
}

/// Checks one decoded Ouster point.
fn check_ouster_point(p: &Point, h: usize, returns: usize, bound: f64) {
    for v in [p.x, p.y, p.z] {
        assert!(
            v.is_finite() && f64::from(v.abs()) <= bound,
            "coordinate {v} > {bound}"
        );
    }
    assert!(p.intensity.is_finite() && p.intensity >= 0.0 && p.intensity <= 255.0);
    assert!(usize::from(p.ring) < h);
    assert!(usize::from(p.ret) < returns);
}

/// `ouster_packet`: a generated calibration (as `calib_ouster`'s) and the rest of the bytes as
/// one lidar packet of its format (cut or zero-padded to the size), and as IMU packets. Every
/// decode path (`decode`, `decode_with`, `decode_packet_into_frame`) agrees on the point count,
/// emits at most columns × rows × returns points, each finite, within the largest range the
/// format can encode plus the calibration offsets, ring < H, return < returns; rows and
/// columns inside the frame.
pub fn ouster_packet(data: &[u8]) {
    let mut b = Bytes::new(data);
    let text = ouster_metadata(&mut b);
    let flags = b.u8();
    let Ok(info) = parse_ouster(&text, "fuzz.json") else {
        return;
    };
    check_ouster_info(&info);
    let rest = b.take(usize::MAX);
    // IMU views over the same bytes: any length, never a panic.
    if let Ok(p) = ImuPacketLegacy::new(rest) {
        let _ = (
            p.sys_ts_ns(),
            p.accel_ts_ns(),
            p.gyro_ts_ns(),
            p.accel_g(),
            p.gyro_dps(),
        );
    }
    for m in [1, 8, info.imu_measurements_per_packet] {
        if let Ok(p) = ImuPacketNmea::new(rest, m) {
            let _ = (
                p.packet_type(),
                p.frame_id(),
                p.init_id(),
                p.serial(),
                p.nmea_ts_ns(),
            );
            let _ = (p.alert_flags(), p.nmea(), p.crc(), p.computed_crc());
            assert!(p.measurements().count() <= m);
        }
    }
    // The zone-monitor view over the same bytes, with either header layout.
    for header in [HeaderKind::Standard, HeaderKind::Fusa] {
        if let Ok(p) = ZonePacket::new(rest, header) {
            let _ = (p.packet_type(), p.frame_id(), p.init_id(), p.serial());
            let _ = (p.alert_flags(), p.timestamp_ns(), p.zoneset_hash());
            let _ = (p.crc(), p.computed_crc());
            for i in 0..=16 {
                if let Some(z) = p.zone(i) {
                    assert!(z.trigger_type < 4 && z.trigger_status < 2);
                    assert!(z.min_range_mm < 1 << 19 && z.max_range_mm < 1 << 19);
                    assert!(z.mean_range_mm < 1 << 19);
                } else {
                    assert_eq!(i, 16);
                }
            }
        }
    }
    let Ok(dec) = OusterDecoder::new(&info) else {
        panic!("a parsed calibration makes a decoder");
    };
    let dec = dec.with_crc_check(flags & 1 != 0);
    let len = info.lidar_packet_bytes();
    let mut buf = vec![0u8; len];
    let n = rest.len().min(len);
    buf[..n].copy_from_slice(&rest[..n]);
    // The exact input too: a wrong length is an error, never a panic.
    let _ = dec.packet(rest);
    let Ok(p) = LidarPacket::new(&buf, &info.format) else {
        panic!("a buffer of the format's size is a packet");
    };
    let _ = dec.packet(&buf);
    let _ = dec.check_sensor(&p);
    let _ = (
        p.crc_ok(),
        p.frame_id(),
        p.init_id(),
        p.serial(),
        p.packet_type(),
    );
    let _ = (p.alert_flags(), p.thermal_shutdown(), p.shot_limiting());
    let (h, w, returns) = (
        dec.pixels_per_column(),
        dec.columns_per_frame(),
        dec.returns(),
    );
    let max_points = info.columns_per_packet() * h * returns;
    let bound = ouster_coordinate_bound(&info);
    let start = u64::from_le_bytes(
        rest.get(..8)
            .and_then(|s| s.try_into().ok())
            .unwrap_or([0; 8]),
    );
    let mut points = Vec::new();
    let d = dec
        .decode(&p, start, &mut points)
        .expect("the packet is in the format");
    assert_eq!(d.points, points.len());
    assert!(points.len() <= max_points);
    for pt in &points {
        check_ouster_point(pt, h, returns, bound);
    }
    let mut with = Vec::new();
    dec.decode_with(&p, start, |pt, extra, row, col| {
        assert!(row < h && col < w, "pixel ({row}, {col}) outside {h} × {w}");
        assert!(f64::from(extra.range_mm) / 1000.0 <= ouster_max_range_m(info.format.profile));
        with.push(pt);
    })
    .expect("the packet is in the format");
    assert_eq!(with, points, "decode and decode_with emit the same points");
    let mut frame = dec.new_frame();
    let f = dec
        .decode_packet_into_frame(&p, &mut frame)
        .expect("a cleared frame takes any packet of the format");
    assert_eq!(f.points, points.len(), "the frame holds the same points");
    assert!(frame.valid_columns() <= info.columns_per_packet());
    // Two columns of one packet with the same measurement id land on the same frame column
    // (the later one wins, as in ouster-sdk's batcher): the frame then holds fewer points.
    let mut ids: Vec<u16> = p.columns().map(|c| c.measurement_id()).collect();
    ids.sort_unstable();
    let distinct = ids.windows(2).all(|w| w[0] != w[1]);
    let staggered: usize = (0..returns).map(|r| frame.points(r)).sum();
    if distinct {
        assert_eq!(staggered, points.len(), "every point is in the frame");
    } else {
        assert!(staggered <= points.len());
    }
    let de = frame.destagger();
    let destaggered: usize = (0..returns).map(|r| de.points(r)).sum();
    assert_eq!(destaggered, staggered, "destaggering keeps every point");
}

/// `ouster_stream`: a generated calibration, then datagrams (u16 length, u8 kind, u64 host
/// time delta, bytes; kind picks lidar-sized, IMU-sized or raw) through an `OusterStream`.
/// Every datagram is counted once (decoded, malformed, CRC, wrong sensor or late); sweeps
/// never hold more points than a frame's pixels × returns, and every point is bounded; IMU
/// samples stay within the queue bound and finite when the packet's floats are.
pub fn ouster_stream(data: &[u8]) {
    let mut b = Bytes::new(data);
    let text = ouster_metadata(&mut b);
    let flags = b.u8();
    let Ok(info) = parse_ouster(&text, "fuzz.json") else {
        return;
    };
    let cfg = OusterStreamConfig {
        info: info.clone(),
        metadata_name: "fuzz.json".into(),
        crc: Some(flags & 1 != 0),
        decode: DecodeOptions::default(),
        keep_extras: flags & 2 != 0,
        keep_columns: flags & 4 != 0,
    };
    let Ok(mut stream) = OusterStream::new(cfg) else {
        panic!("a parsed calibration makes a stream");
    };
    let h = info.pixels_per_column();
    let returns = if info.format.profile.is_dual() { 2 } else { 1 };
    let frame_points = info.columns_per_frame * h * returns;
    let bound = ouster_coordinate_bound(&info);
    let lidar_len = info.lidar_packet_bytes();
    let imu_len = OusterStreamConfig::imu_len_of(&info);
    let mut host: i64 = 1_700_000_000_000_000_000;
    let mut pushed = 0u64;
    let mut sweeps = 0u64;
    let mut points = 0u64;
    let mut template: Vec<u8> = Vec::new();
    let mut on_sweep = |s: &mut Sweep, _: &ringscan::sensor::ouster::sweep::OusterFacts| {
        sweeps += 1;
        points += s.points.len() as u64;
        assert!(
            s.points.len() <= frame_points,
            "{} > {frame_points}",
            s.points.len()
        );
        if !s.extras.is_empty() {
            assert_eq!(s.extras.len(), s.points.len());
        }
        if !s.columns.is_empty() {
            assert_eq!(s.columns.len(), s.points.len());
        }
        for p in &s.points {
            check_ouster_point(p, h, returns, bound);
        }
    };
    while !b.is_empty() && pushed < 4096 {
        let n = usize::from(b.u16());
        let kind = b.u8();
        host = host.saturating_add(i64::from(b.u32()));
        let body = b.take(n);
        let payload: Vec<u8> = match kind % 4 {
            // A lidar packet: the body patches the previous one (frame ids, columns…).
            0 | 1 => {
                template.resize(lidar_len, 0);
                let at = usize::from(kind) * 7 % lidar_len.max(1);
                let m = body.len().min(lidar_len - at);
                template[at..at + m].copy_from_slice(&body[..m]);
                template.clone()
            }
            2 => {
                let len = imu_len.unwrap_or(48);
                let mut v = body.to_vec();
                v.resize(len, 0);
                v
            }
            // A zone-monitor packet of this sensor (type 3, its serial), the rest fuzzed.
            3 if kind & 4 != 0 => {
                let mut v = body.to_vec();
                v.resize(ZONE_PACKET_BYTES, 0);
                v[..2].copy_from_slice(&3u16.to_le_bytes());
                v[7..12].copy_from_slice(&info.serial.to_le_bytes()[..5]);
                v
            }
            _ => body.to_vec(),
        };
        stream.push(host, &payload, &mut on_sweep);
        pushed += 1;
        let imu: Vec<_> = stream.drain_imu().collect();
        assert!(imu.len() <= ringscan::sensor::ouster::sweep::MAX_IMU_QUEUE);
        if kind & 8 != 0 {
            // Drained only now and then, so the queue's bound is reached too.
            let zones = stream.drain_zones().count();
            assert!(zones <= ringscan::sensor::ouster::sweep::MAX_ZONE_QUEUE);
        }
    }
    stream.finish(&mut on_sweep);
    let st = stream.stats().clone();
    let counted = st.lidar_packets
        + st.imu_packets
        + st.zone_packets
        + st.malformed
        + st.crc_failures
        + st.wrong_sensor;
    assert_eq!(
        counted + st.late,
        pushed,
        "every datagram is counted once: {st:?}, {pushed} pushed"
    );
    assert_eq!(st.sweeps, sweeps);
    assert_eq!(st.points, points);
    // The rate the column timestamps give is a finite positive number, or none.
    if let Some(fps) = stream.measured_fps() {
        assert!(fps.is_finite() && fps > 0.0, "{fps}");
    }
    let _ = stream.rate_mismatch();
}

/// The Ouster sensor of `decode_to_mcap`: a small OS-1-16 in one of three profiles (single,
/// dual, LEGACY), extra fields on or off, by the input length.
fn decode_to_mcap_ouster(variant: usize) -> OusterStreamConfig {
    let profile = ["RNG19_RFL8_SIG16_NIR16", "RNG15_RFL8_NIR8_DUAL", "LEGACY"][variant % 3];
    let alt: Vec<f64> = (0..16).map(|i| 15.0 - 2.0 * f64::from(i)).collect();
    let text = serde_json::json!({
        "prod_line": "OS-1-16",
        "prod_sn": "992210000957",
        "build_rev": "v2.3.0",
        "lidar_mode": "512x10",
        "beam_altitude_angles": alt,
        "beam_azimuth_angles": vec![1.5; 16],
        "data_format": {
            "pixels_per_column": 16,
            "columns_per_packet": 16,
            "columns_per_frame": 512,
            "pixel_shift_by_row": vec![0; 16],
            "column_window": [0, 511],
            "udp_profile_lidar": profile,
            "udp_profile_imu": "LEGACY",
        },
    })
    .to_string();
    let info = parse_ouster(&text, "fuzz.json").expect("the fixed metadata parses");
    OusterStreamConfig {
        info,
        metadata_name: "fuzz.json".into(),
        crc: Some(false),
        decode: DecodeOptions::default(),
        keep_extras: variant % 2 == 1,
        keep_columns: false,
    }
}

// ----- pipeline configuration and poses files --------------------------------------------------

use ringscan::deskew::PoseTable as DeskewPoses;
use ringscan::pipeline::config::PipelineConfig;
use ringscan::pipeline::run::Pipeline;

/// `pipeline_config`: bytes up to the first NUL as a pipeline TOML file
/// (`PipelineConfig::from_toml`), the rest as points (x, y, z as i16 centimetres, t as u16 µs,
/// ring byte; at most 4 096). A configuration that loads validates again and builds a
/// `Pipeline`, which runs every stage on the points (twice: buffers reused) without a panic:
/// ground + obstacles + unclustered = voxels ≤ points after the filters ≤ input, clusters'
/// points = obstacles, every output coordinate finite.
pub fn pipeline_config(data: &[u8]) {
    let cut = data.iter().position(|&b| b == 0).unwrap_or(data.len());
    let Ok(text) = core::str::from_utf8(&data[..cut]) else {
        return;
    };
    let Ok(cfg) = PipelineConfig::from_toml(text) else {
        return;
    };
    cfg.validate()
        .expect("a loaded configuration validates again");
    let Ok(mut pipeline) = Pipeline::new(&cfg, nalgebra::Isometry3::identity()) else {
        panic!("a loaded configuration builds a pipeline");
    };
    let mut b = Bytes::new(data.get(cut + 1..).unwrap_or_default());
    let mut sweep = Sweep::default();
    while !b.is_empty() && sweep.points.len() < 4096 {
        let c = |v: u16| f32::from(v as i16) / 100.0;
        let (x, y, z) = (c(b.u16()), c(b.u16()), c(b.u16()));
        let t = u32::from(b.u16()) * 1000;
        let ring = u16::from(b.u8() % 32);
        sweep.points.push(Point {
            x,
            y,
            z,
            intensity: 10.0,
            t,
            ring,
            ..Point::default()
        });
    }
    let input = sweep.points.clone();
    for _ in 0..2 {
        sweep.points.clone_from(&input);
        let mut now = 0u64;
        let st = pipeline.run(&mut sweep, &mut || {
            now += 1;
            now
        });
        assert_eq!(st.input, input.len());
        assert!(st.filtered <= st.input, "{st:?}");
        assert!(st.voxels <= st.filtered, "{st:?}");
        assert_eq!(
            st.ground + st.obstacles + st.unclustered,
            st.voxels,
            "{st:?}"
        );
        assert_eq!(st.clusters, pipeline.clusters().len());
        let in_clusters: usize = pipeline.clusters().iter().map(|c| c.point_count).sum();
        assert_eq!(in_clusters, st.obstacles, "{st:?}");
        for p in pipeline.ground().iter().chain(pipeline.obstacles()) {
            assert!(p.x.is_finite() && p.y.is_finite() && p.z.is_finite());
        }
    }
}

/// `tum_poses`: any bytes as a TUM poses file, through both parsers (`deskew::PoseTable`, the
/// one `--deskew poses:FILE` reads, and the simulator's). A table that parses has ≥ 2 poses
/// strictly increasing in time; interpolating it anywhere (inside, at the ends, outside) gives
/// an error or a finite pose with a unit rotation, never a panic.
pub fn tum_poses(data: &[u8]) {
    let Ok(text) = core::str::from_utf8(data) else {
        return;
    };
    let _ = ringscan::sim::motion::PoseTable::parse_tum(text);
    let Ok(table) = DeskewPoses::from_tum(text) else {
        return;
    };
    assert!(table.len() >= 2);
    let (a, z) = table.time_range_ns();
    assert!(a < z);
    let mid = a + (z - a) / 2;
    let probes = [
        a,
        z,
        mid,
        a.saturating_sub(1),
        z.saturating_add(1),
        i64::MIN,
        i64::MAX,
        a + (z - a) / 3,
    ];
    for t in probes {
        if let Ok(pose) = table.world_from_sensor(t) {
            let v = pose.translation.vector;
            assert!(v.iter().all(|x| x.is_finite()), "pose at {t}: {pose:?}");
            let q = pose.rotation.quaternion();
            assert!((q.norm() - 1.0).abs() < 1e-6, "pose at {t}: {pose:?}");
        }
    }
}

// ----- network parsers of the live path ----------------------------------------------------------

/// `http_response`: any bytes as the reply to the Ouster metadata request
/// (`source::udp::parse_http_response`, plain, sized or chunked bodies). No panic; a body is
/// never longer than what came after the headers (chunk framing only removes bytes); a
/// plain 200 response built around the input gives the input back.
pub fn http_response(data: &[u8]) {
    use ringscan::source::udp::parse_http_response;
    if let Ok(body) = parse_http_response(data) {
        let head_end = data
            .windows(4)
            .position(|w| w == b"\r\n\r\n")
            .expect("a parsed response has an end of headers");
        assert!(
            body.len() <= data.len() - head_end - 4,
            "body longer than the input"
        );
    }
    let mut framed =
        format!("HTTP/1.1 200 OK\r\nContent-Length: {}\r\n\r\n", data.len()).into_bytes();
    framed.extend_from_slice(data);
    assert_eq!(
        parse_http_response(&framed).as_deref(),
        Ok(data),
        "sized body"
    );
    // The same body in chunks of up to 7 bytes.
    let mut chunked = b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n".to_vec();
    for part in data.chunks(7) {
        chunked.extend_from_slice(format!("{:x}\r\n", part.len()).as_bytes());
        chunked.extend_from_slice(part);
        chunked.extend_from_slice(b"\r\n");
    }
    chunked.extend_from_slice(b"0\r\n\r\n");
    assert_eq!(
        parse_http_response(&chunked).as_deref(),
        Ok(data),
        "chunked body"
    );
}

/// `live_view_requests`: the input split at newlines as a live-view client's text messages
/// (`sink::live_view::ClientRequest`), applied in turn to its subscriptions with a channel
/// count taken from the first byte. No panic; requests stay within `MAX_ENTRIES`; after each
/// one every subscription names an advertised channel, and no channel and no subscription id
/// appears twice.
pub fn live_view_requests(data: &[u8]) {
    use ringscan::sink::live_view::ClientRequest;
    let Some((&n, rest)) = data.split_first() else {
        return;
    };
    let n_channels = u64::from(n % 16);
    let mut subs: Vec<(u32, u32)> = Vec::new();
    for line in rest.split(|&b| b == b'\n') {
        let Ok(text) = std::str::from_utf8(line) else {
            continue;
        };
        let Some(req) = ClientRequest::parse(text) else {
            continue;
        };
        match &req {
            ClientRequest::Subscribe(v) => assert!(v.len() <= ClientRequest::MAX_ENTRIES),
            ClientRequest::Unsubscribe(v) => assert!(v.len() <= ClientRequest::MAX_ENTRIES),
        }
        req.apply(&mut subs, n_channels);
        assert!(
            subs.len() as u64 <= n_channels,
            "more subscriptions than channels"
        );
        for (i, &(ch, sub)) in subs.iter().enumerate() {
            assert!(
                ch >= 1 && u64::from(ch) <= n_channels,
                "unknown channel {ch}"
            );
            for &(ch2, sub2) in &subs[i + 1..] {
                assert!(ch != ch2 && sub != sub2, "duplicate channel or id");
            }
        }
        if let ClientRequest::Unsubscribe(ids) = &req {
            assert!(
                subs.iter().all(|(_, s)| !ids.contains(s)),
                "unsubscribed id kept"
            );
        }
    }
}

// ----- bags (source::bag) ---------------------------------------------------------------------

/// The packets of one message of `kind`: each inside the message; at most one per 1 byte of
/// it (a packet takes at least its stamp or length field).
fn bag_check_packets(
    kind: ringscan::source::bag::messages::MsgKind,
    enc: ringscan::source::bag::messages::Encoding,
    msg: &[u8],
    out: &mut Vec<ringscan::source::bag::messages::PacketRef>,
) {
    use ringscan::source::bag::messages;
    match messages::packets(kind, enc, msg, out) {
        Ok(()) => {
            assert!(out.len() <= msg.len().max(1));
            for p in out.iter() {
                assert!(p.start.checked_add(p.len).is_some_and(|e| e <= msg.len()));
            }
        }
        Err(_) => assert!(out.is_empty(), "packets left after an error"),
    }
    if let Ok((a, n)) = messages::string(enc, msg) {
        assert!(a + n <= msg.len());
    }
    // ringscan.RawPacket: a payload inside the message; written again by the MCAP sink's
    // encoder, it reads back the same.
    if let Ok(r) = messages::raw_packet(messages::Encoding::Protobuf, msg) {
        let p = r.packet;
        assert!(p.start.checked_add(p.len).is_some_and(|e| e <= msg.len()));
        let payload = &msg[p.start..p.start + p.len];
        let t = p.stamp_ns.and_then(|t| u64::try_from(t).ok());
        if let Some(t) = t {
            let mut again = Vec::new();
            ringscan::sink::foxglove::encode_raw_packet(
                &mut again,
                t,
                r.source,
                r.destination_port,
                payload,
            )
            .expect("a payload read from a message fits one");
            let back = messages::raw_packet(messages::Encoding::Protobuf, &again)
                .expect("the encoder's message reads back");
            assert_eq!(
                (back.source, back.destination_port),
                (r.source, r.destination_port)
            );
            assert_eq!(back.packet.stamp_ns, p.stamp_ns);
            assert_eq!(&again[back.packet.start..][..back.packet.len], payload);
        }
    }
    // Livox CustomMsg: a whole points frame of no more points than 19-byte groups of the
    // message, or nothing.
    let mut frame = Vec::new();
    match messages::livox_custom(enc, msg, &mut frame) {
        Ok(_) => {
            let f = ringscan::sensor::livox::frame::PointsFrame::new(&frame)
                .expect("a CustomMsg read is a whole frame");
            assert!(f.len() <= msg.len() / 19);
            assert_eq!(f.points().count(), f.len());
        }
        Err(_) => assert!(frame.is_empty(), "frame left after an error"),
    }
    // sensor_msgs/Imu: the IMU frame the bag source makes of it reads back the same sample.
    if let Ok(m) = messages::imu(enc, msg) {
        use ringscan::sensor::livox::frame::{write_imu, ImuFrame};
        let t = u64::try_from(m.stamp_ns).unwrap_or(0);
        write_imu(&mut frame, t, m.angular_velocity, m.linear_acceleration);
        let f = ImuFrame::new(&frame).expect("an IMU frame written is whole");
        assert_eq!(f.time_ns(), t);
        let same =
            |a: [f64; 3], b: [f64; 3]| a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same(f.gyro(), m.angular_velocity) && same(f.accel(), m.linear_acceleration));
    }
}

/// `bag_messages`: byte 0 picks the type and the encoding, the rest is one message (every
/// message is also read as a Livox CustomMsg and as a sensor_msgs/Imu).
pub fn bag_messages(data: &[u8]) {
    use ringscan::source::bag::messages::{Encoding, MsgKind};
    let Some((&sel, msg)) = data.split_first() else {
        return;
    };
    let kinds = [
        MsgKind::VelodyneScan,
        MsgKind::OusterPacket,
        MsgKind::PandarScan,
        MsgKind::NebulaPackets,
        MsgKind::HesaiUdpFrame,
        MsgKind::RobosenseScan,
        MsgKind::RslidarPacket,
        MsgKind::StdString,
    ];
    let kind = kinds[usize::from(sel & 7)];
    let enc = if sel & 8 == 0 {
        Encoding::Cdr
    } else {
        Encoding::Ros1
    };
    let mut out = Vec::new();
    bag_check_packets(kind, enc, msg, &mut out);
}

/// Reads every message of a bag-format reader, checking each one's packets.
fn bag_drain(
    mut next: impl FnMut(
        &mut Vec<u8>,
    ) -> Option<(String, Option<ringscan::source::bag::messages::Encoding>)>,
) -> usize {
    use ringscan::source::bag::messages::MsgKind;
    let (mut buf, mut out, mut n) = (Vec::new(), Vec::new(), 0usize);
    while let Some((type_name, enc)) = next(&mut buf) {
        assert!(buf.len() <= ringscan::source::bag::MAX_MESSAGE_BYTES);
        if let (Some(kind), Some(enc)) = (MsgKind::from_type_name(&type_name), enc) {
            bag_check_packets(kind, enc, &buf, &mut out);
        }
        n += 1;
    }
    n
}

/// `bag_ros1`: any bytes as a ROS 1 bag (`Ros1Reader` over a slice).
pub fn bag_ros1(data: &[u8]) {
    use ringscan::source::bag::ros1::Ros1Reader;
    let Ok(mut r) = Ros1Reader::new(data) else {
        return;
    };
    let mut errors = 0;
    bag_drain(|buf| match r.next_message() {
        Ok(Some(m)) => {
            buf.clear();
            buf.extend_from_slice(r.message());
            let c = r.connection(m.conn);
            Some((
                c.map(|c| c.type_name.clone()).unwrap_or_default(),
                c.and_then(|c| c.encoding),
            ))
        }
        Ok(None) => None,
        Err(_) => {
            errors += 1;
            None
        }
    });
    assert!(r.offset() <= data.len() as u64);
    // Fused after the end or an error.
    assert!(matches!(r.next_message(), Ok(None)));
}

/// `bag_mcap`: any bytes as an MCAP file of ROS messages (`McapReader` over a slice).
pub fn bag_mcap(data: &[u8]) {
    use ringscan::source::bag::mcap_in::McapReader;
    let mut r = McapReader::new(data);
    bag_drain(|buf| match r.next_message() {
        Ok(Some(m)) => {
            buf.clear();
            buf.extend_from_slice(r.message());
            let c = r.connection(m.conn);
            Some((
                c.map(|c| c.type_name.clone()).unwrap_or_default(),
                c.and_then(|c| c.encoding),
            ))
        }
        _ => None,
    });
    assert!(r.offset() <= data.len() as u64);
    // The same bytes through the summary's attachment indexes (the calibrations of a bag
    // ringscan wrote): bounded in number and size, whatever the offsets and lengths say.
    let found = ringscan::source::bag::mcap_in::attachments(&mut std::io::Cursor::new(data), 4096);
    assert!(found.len() <= 16);
    assert!(found
        .iter()
        .all(|(_, b)| b.len() <= 4096 && b.len() <= data.len()));
}

/// `bag_metadata`: any bytes as a rosbag2 `metadata.yaml`.
pub fn bag_metadata(data: &[u8]) {
    use ringscan::source::bag::rosbag2::Metadata;
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(m) = Metadata::parse(text) {
        assert!(m.files.len() <= text.len());
        assert!(m.topics.len() <= text.len());
    }
}

// ----- hesai_packet / calib_hesai --------------------------------------------------------------

use ringscan::sensor::hesai::calib::CHANNEL_COUNTS as HESAI_CHANNEL_COUNTS;
use ringscan::sensor::hesai::family::parse_hesai_calibration;
use ringscan::sensor::hesai::model::ALL_MODELS as HESAI_MODELS;
use ringscan::sensor::hesai::{
    HesaiCalibration, HesaiConfig, HesaiDecoder, HesaiModel, HesaiOptions, HesaiPacket, HesaiStream,
};

/// A plausible correction for `model`: a CSV spread over ±15° (the AT128: a zero-offset
/// `.dat` with three 120° mirror fields).
pub fn hesai_correction(model: HesaiModel) -> HesaiCalibration {
    let n = model.channels();
    if model == HesaiModel::PandarAt128 {
        let mut b = vec![0u8; 16 + 24 + 1024 + 46080 + 32];
        b[..7].copy_from_slice(&[0xEE, 0xFF, 1, 5, 128, 3, 3]);
        b[15] = 1;
        for m in 0..3u32 {
            let s = m * 120 * 25_600;
            let e = ((m + 1) % 3) * 120 * 25_600;
            b[16 + 4 * m as usize..20 + 4 * m as usize].copy_from_slice(&s.to_le_bytes());
            b[28 + 4 * m as usize..32 + 4 * m as usize].copy_from_slice(&e.to_le_bytes());
        }
        return parse_hesai_calibration(&b).unwrap().unwrap();
    }
    if model == HesaiModel::PandarAtx {
        // Version x.3 in 1/100°: even azimuths 1°, odd 2°, elevations 10° … −9.8°, adjustment
        // 0.5°.
        let mut b = vec![0xEE, 0xFF, 4, 3, 0, 0, n as u8, 100, 0];
        for v in (0..n).map(|_| 100i16).chain((0..n).map(|_| 200)) {
            b.extend_from_slice(&v.to_le_bytes());
        }
        for i in 0..n {
            b.extend_from_slice(&(1_000 - 20 * i as i16).to_le_bytes());
        }
        for _ in 0..70 {
            b.extend_from_slice(&50i16.to_le_bytes());
        }
        b.extend_from_slice(&[0; 32]);
        return parse_hesai_calibration(&b).unwrap().unwrap();
    }
    let mut s = String::from("Laser id,Elevation,Azimuth\n");
    for i in 0..n {
        let el = 15.0 - 30.0 * i as f64 / n as f64;
        let az = if i % 2 == 0 { 1.5 } else { -2.25 };
        s.push_str(&format!("{},{el},{az}\n", i + 1));
    }
    parse_hesai_calibration(s.as_bytes()).unwrap().unwrap()
}

fn check_hesai_point(p: &Point, model: HesaiModel, max_m: f32) {
    assert!(
        p.x.is_finite() && p.y.is_finite() && p.z.is_finite(),
        "{p:?}"
    );
    let r = (p.x * p.x + p.y * p.y + p.z * p.z).sqrt();
    assert!(r <= max_m * 1.001 + 1e-3, "{p:?} beyond {max_m} m");
    assert!(usize::from(p.ring) < model.channels(), "{p:?}");
    assert!(p.ret <= 2, "{p:?}");
    assert!((0.0..=255.0).contains(&p.intensity), "{p:?}");
}

/// The two host receive times a packet harness pushes its payload at: ordinary ones, or (by
/// the payload's last byte) times at either end of `i64`, which a corrupt capture can give
/// (an MCAP log time of 2^64 − 1, a pcapng `if_tsoffset` that saturates).
fn host_times(payload: &[u8]) -> [i64; 2] {
    match payload.last().map(|b| b % 4) {
        Some(3) => [i64::MAX - 1_000_000, i64::MAX],
        Some(2) => [i64::MIN, i64::MIN + 1_000_000],
        _ => [0, 1_000_000],
    }
}

/// One datagram (the first byte picks the model and the options) through the packet view and a
/// stream. The view refuses what does not fit its layout and never panics; detection and the
/// view agree; the stream counts the datagram (decoded, malformed or a copy), and every point is finite,
/// within the model's range, on a ring of the model and of a return 0–2, at most
/// blocks × channels per packet.
pub fn hesai_packet(data: &[u8]) {
    let Some((&sel, payload)) = data.split_first() else {
        return;
    };
    if let Some(m) = HesaiModel::detect(payload) {
        assert!(
            HesaiPacket::new(payload, m).is_ok(),
            "detected {m:?} but the view refuses"
        );
    }
    let model = HESAI_MODELS[usize::from(sel) % HESAI_MODELS.len()];
    if let Ok(p) = HesaiPacket::new(payload, model) {
        let l = p.layout();
        for b in 0..l.blocks {
            let _ = p.azimuth(b);
            assert_eq!(p.units(b).len(), l.channels * l.unit_len);
            for c in 0..l.channels {
                let _ = p.unit(b, c);
            }
        }
        let _ = (
            p.stamp_ns(),
            p.udp_seq(),
            p.functional_safety(),
            p.check_crc(),
            p.check_safety_crc(),
        );
        // A time the tail gives is a date's second plus less than a second of µs.
        if let (Some(ns), Some(s)) = (p.stamp_ns(), p.unix_seconds()) {
            assert!(
                (0..1_000_000_000).contains(&ns.saturating_sub(s.saturating_mul(1_000_000_000)))
                    || s.unsigned_abs() > 9_000_000_000
            );
        }
        let _ = (
            p.protocol(),
            p.tail_flags(),
            p.motor_rpm(),
            p.has_signature(),
        );
    }
    let mut cfg = HesaiConfig::new(Some(hesai_correction(model)), "fuzz.csv");
    cfg.model = Some(model);
    cfg.check_crc = sel & 0x10 == 0;
    cfg.options = HesaiOptions {
        dual_return_threshold_m: if sel & 0x20 != 0 { 0.1 } else { 0.0 },
        fov_cdeg: (sel & 0x40 != 0).then_some((3_000, 15_000)),
        ..HesaiOptions::default()
    };
    cfg.cut_cdeg = Some(u32::from(sel & 0x80) * 100);
    let max_m = model.spec().max_range_m;
    // The most points a packet can hold: its layout's (the ATX's, from its header).
    let per_packet =
        HesaiPacket::new(payload, model).map_or(0, |p| p.layout().blocks * p.layout().channels);
    let mut stream = HesaiStream::new(cfg);
    let mut points = 0usize;
    let mut on_sweep = |sw: &mut Sweep, _: &ringscan::sensor::hesai::HesaiFacts| {
        for p in &sw.points {
            check_hesai_point(p, model, max_m);
        }
        points += sw.points.len();
    };
    for (i, host) in host_times(payload).into_iter().enumerate() {
        stream.push(host, payload, &mut on_sweep).unwrap();
        let st = stream.stats();
        // The second push is the same datagram: a copy where its number or time tells it.
        assert_eq!(
            st.packets + st.malformed + st.duplicates,
            i as u64 + 1,
            "{st:?}"
        );
    }
    stream.finish(&mut on_sweep);
    assert!(points <= 2 * per_packet, "{points} points from two packets");
}

/// Any bytes as a Hesai correction: recognised only by the CSV header line or the `.dat` start;
/// a CSV that parses has one of the models' channel counts and finite angles within ±90° / ±180°,
/// and serves a decoder for every model of its channel count; an AT128 correction gives angles
/// within one turn for every channel and encoder azimuth tried.
pub fn calib_hesai(data: &[u8]) {
    // The ATX's binary firetimes (fetched over PTC): bounded, and the CSV written from them
    // reads back the same.
    if let Ok(f) = ringscan::sensor::hesai::atx::AtxFiretimes::parse_binary(data) {
        assert!((1..=200).contains(&f.channels()) && f.odd_ns.len() == f.channels());
        assert!(f
            .even_ns
            .iter()
            .chain(&f.odd_ns)
            .all(|t| (0.0..=1e6).contains(t)));
        let csv = ringscan::sensor::hesai::atx::AtxFiretimes::parse_csv(&f.to_csv());
        assert_eq!(csv.ok().as_ref(), Some(&f));
    }
    let Some(parsed) = parse_hesai_calibration(data) else {
        return;
    };
    let Ok(c) = parsed else {
        return;
    };
    match &c {
        HesaiCalibration::Csv(rows) => {
            assert!(HESAI_CHANNEL_COUNTS.contains(&rows.len()));
            for r in rows {
                assert!(r.elevation_deg.is_finite() && r.elevation_deg.abs() <= 90.0);
                assert!(r.azimuth_deg.is_finite() && r.azimuth_deg.abs() <= 180.0);
            }
            for m in HESAI_MODELS {
                if m.channels() == rows.len()
                    && !matches!(m, HesaiModel::PandarAt128 | HesaiModel::PandarAtx)
                {
                    HesaiDecoder::new(m, &c, HesaiOptions::default()).unwrap();
                }
            }
        }
        HesaiCalibration::At128(a) => {
            let d =
                HesaiDecoder::new(HesaiModel::PandarAt128, &c, HesaiOptions::default()).unwrap();
            for ch in [0, 1, 63, 127] {
                for enc in [0i64, 1, 12_345_678, 9_215_999] {
                    if let Some((az, _el)) = a.angles(ch, enc) {
                        assert!((0..360 * 25_600).contains(&az));
                    }
                    if let Some(az) = d.channel_azimuth_udeg((enc as u32) & 0xFF_FFFF, ch) {
                        assert!((0..360_000_000).contains(&az));
                    }
                }
            }
        }
        HesaiCalibration::AtxFiretimes(f) => {
            assert!((1..=200).contains(&f.channels()));
            assert_eq!(f.odd_ns.len(), f.channels());
            for t in f.even_ns.iter().chain(&f.odd_ns) {
                assert!(t.is_finite() && t.abs() <= 1e6);
            }
            assert!(HesaiDecoder::new(HesaiModel::PandarAtx, &c, HesaiOptions::default()).is_err());
        }
        HesaiCalibration::Atx(a) => {
            HesaiDecoder::new(HesaiModel::PandarAtx, &c, HesaiOptions::default()).unwrap();
            // Block azimuths up to 256°, offsets within ±180°, elevations and their
            // adjustment within ±90° each.
            let n = a.channels();
            assert!(a.angles(n, 0, false, 0).is_none());
            for ch in [0, 1, n / 2, n - 1].into_iter().filter(|&c| c < n) {
                for raw in [0u16, 1, 5_120, 40_448, u16::MAX] {
                    for odd in [false, true] {
                        let (az, el) = a.angles(ch, raw, odd, i16::MIN).unwrap();
                        assert!(az.abs() <= 436 * 25_600 && el.abs() <= 180 * 25_600);
                    }
                }
            }
        }
    }
}

// ----- robosense_packet / calib_robosense --------------------------------------------------------

use ringscan::sensor::robosense::family::parse_robosense_calibration;
use ringscan::sensor::robosense::model::ALL_MODELS as ROBOSENSE_MODELS;
use ringscan::sensor::robosense::{
    Difop, Msop, RobosenseAngles, RobosenseConfig, RobosenseDecoder, RobosenseModel,
    RobosenseStream,
};

/// Plausible angles for `model`: a fan over ±15°, horizontal offsets ±4°.
pub fn robosense_angles(model: RobosenseModel) -> RobosenseAngles {
    let n = model.lasers();
    let s: String = (0..n)
        .map(|i| {
            format!(
                "{:.2},{}\n",
                15.0 - 30.0 * i as f64 / n as f64,
                if i % 2 == 0 { -4.0 } else { 3.6 }
            )
        })
        .collect();
    parse_robosense_calibration(s.as_bytes()).unwrap().unwrap()
}

/// One datagram (the first byte picks the model and options) through the packet views and a
/// stream, pushed twice. The views refuse what does not fit and never panic; every push is
/// counted once (decoded, DIFOP, malformed, held, dropped or a copy); held packets stay within the bound; every
/// point is finite, within the model's range (plus the lens offset), on a ring of the model,
/// return 0 or 1, at most blocks × slots per packet.
pub fn robosense_packet(data: &[u8]) {
    let Some((&sel, payload)) = data.split_first() else {
        return;
    };
    // Low nibble: the model (bits 0x10–0x80 are the options).
    let model = ROBOSENSE_MODELS[usize::from(sel & 0x0F) % ROBOSENSE_MODELS.len()];
    let dual = sel & 0x10 != 0;
    robosense_m1_views(payload);
    if let Ok(p) = Msop::new(payload, model) {
        let shape = model.spec().shape;
        for b in 0..shape.blocks() {
            assert!(p.azimuth(b) < 36_000);
            assert_eq!(p.block_units(b).len(), 3 * shape.slots());
        }
        let _ = (
            p.stamp_ns(model.spec().clock),
            p.protocol_version(),
            p.return_id(0),
        );
        let dec =
            RobosenseDecoder::new(model, &robosense_angles(model), Default::default()).unwrap();
        let mut n = 0;
        dec.decode(&p, dual, |d| {
            n += 1;
            assert!(d.offset_ns >= 0 && d.offset_ns < 2_000_000);
        });
        assert!(n <= shape.blocks() * shape.slots());
    }
    if let Ok(d) = Difop::new(payload) {
        let _ = (
            d.rpm(),
            d.fov(),
            d.network(),
            d.firmware(),
            d.serial(),
            d.return_mode(),
        );
        if let Ok(a) = d.angles(model) {
            assert_eq!(a.len(), model.lasers());
            for (v, h) in a {
                assert!((-90.0..180.0).contains(&v) && (-90.0..180.0).contains(&h));
            }
        }
    }
    // The M1 has no angle file (5 channels is no table's row count).
    let angles = (sel & 0x40 == 0 && model != RobosenseModel::M1).then(|| robosense_angles(model));
    let mut cfg = RobosenseConfig::new(angles);
    if sel & 0x20 == 0 {
        cfg.model = Some(model);
    }
    cfg.cut_cdeg = u16::from(sel & 0x80) * 100;
    // Without a named model the stream tells it from the packet: any model's range may apply.
    let max_m = match cfg.model {
        Some(m) => m.spec().max_range_m,
        None => ROBOSENSE_MODELS
            .iter()
            .map(|m| m.spec().max_range_m)
            .fold(0.0, f32::max),
    } + 0.2;
    let mut stream = RobosenseStream::new(cfg);
    let mut points = 0usize;
    let mut on_sweep = |sw: &mut Sweep, _: &ringscan::sensor::robosense::RobosenseFacts| {
        for p in &sw.points {
            assert!(
                p.x.is_finite() && p.y.is_finite() && p.z.is_finite(),
                "{p:?}"
            );
            let r = (p.x * p.x + p.y * p.y + p.z * p.z).sqrt();
            assert!(r <= max_m, "{p:?}");
            assert!(usize::from(p.ring) < 128 && p.ret <= 1, "{p:?}");
        }
        points += sw.points.len();
    };
    for (i, host) in host_times(payload).into_iter().enumerate() {
        // An error is an angle file that does not fit the model the packet names: clear, and
        // the stream decodes nothing.
        if stream.push(host, payload, &mut on_sweep).is_err() {
            assert!(stream.decoder().is_none());
            return;
        }
        let st = stream.stats();
        let held = stream.held() as u64;
        assert_eq!(
            st.packets + st.malformed + st.difop + held + st.dropped + st.duplicates,
            i as u64 + 1,
            "{st:?}"
        );
        assert!(stream.held() <= ringscan::sensor::robosense::sweep::MAX_HELD);
    }
    stream.finish(&mut on_sweep);
    assert!(points <= 2 * 12 * 128, "{points} points from two packets");
}

/// The M1's views and decoder on any bytes: they refuse what is not an M1 packet, every
/// accessor answers, at most 125 points a packet, each finite, within 200 m, at its block's
/// offset (< 256 µs), on channel 0..4, return 0 / 1.
fn robosense_m1_views(payload: &[u8]) {
    use ringscan::sensor::robosense::m1::{is_m1_msop, M1Decoder, M1Difop, M1Msop};
    let msop = M1Msop::new(payload);
    assert_eq!(msop.is_ok(), is_m1_msop(payload));
    if let Ok(p) = msop {
        let _ = (
            p.seq(),
            p.protocol_version(),
            p.return_mode(),
            p.time_mode(),
            p.lidar_type(),
            p.temperature_c(),
            p.stamp_ns(),
        );
        let mut n = 0;
        M1Decoder::new(Default::default()).decode(&p, |d| {
            n += 1;
            let q = d.point;
            assert!(q.x.is_finite() && q.y.is_finite() && q.z.is_finite());
            assert!(
                (q.x * q.x + q.y * q.y + q.z * q.z).sqrt() <= 200.01,
                "{q:?}"
            );
            assert!(d.offset_ns >= 0 && d.offset_ns < 256_000);
            assert!(q.ring < 5 && q.ret <= 1);
        });
        assert!(n <= 125);
    }
    if let Ok(d) = M1Difop::new(payload) {
        let _ = (d.frame_rate(), d.network(), d.firmware(), d.serial());
    }
}

/// Any bytes as a Robosense angle CSV: recognised only when every line is one or two numbers
/// and the row count is a model's laser count; a table that parses has finite angles within
/// −90°..180° and serves a decoder for every model of its laser count.
pub fn calib_robosense(data: &[u8]) {
    let Some(parsed) = parse_robosense_calibration(data) else {
        return;
    };
    let Ok(a) = parsed else {
        return;
    };
    assert!(ringscan::sensor::robosense::calib::LASER_COUNTS.contains(&a.lasers()));
    for &(v, h) in &a.lasers {
        assert!(v.is_finite() && (-90.0..180.0).contains(&v));
        assert!(h.is_finite() && (-90.0..180.0).contains(&h));
    }
    for m in ROBOSENSE_MODELS {
        if m.lasers() == a.lasers() {
            RobosenseDecoder::new(m, &a, Default::default()).unwrap();
        }
    }
}

// ----- livox_packet ----------------------------------------------------------------------------

use ringscan::sensor::livox::family::detect_protocol;
use ringscan::sensor::livox::model::ALL_MODELS as LIVOX_MODELS;
use ringscan::sensor::livox::sweep::MAX_IMU_QUEUE as LIVOX_MAX_IMU_QUEUE;
use ringscan::sensor::livox::{
    LivoxConfig, LivoxStream, Protocol as LivoxProtocol, Sdk1Packet, Sdk2Packet,
};

/// One or more datagrams (byte 0 picks the model, the CRC check and a 100 ms or 1 µs
/// integration period; the rest is split at each 0xFE byte into datagrams) through both packet views and a `LivoxStream`, each pushed twice.
/// No panic; the views and `detect_protocol` agree; every datagram is counted once (point
/// packet, IMU packet, malformed, a copy or a late packet dropped); points are finite, ring < lines, return ≤ 2, intensity
/// 0–255, at most 3 returns × records per packet; the IMU queue stays bounded.
pub fn livox_packet(data: &[u8]) {
    let Some((&sel, rest)) = data.split_first() else {
        return;
    };
    let model = LIVOX_MODELS[usize::from(sel) % LIVOX_MODELS.len()];
    let mut cfg = LivoxConfig::new(Some(model), model.protocol());
    cfg.check_crc = sel & 0x80 == 0;
    cfg.period_ns = if sel & 0x40 == 0 { 100_000_000 } else { 1_000 };
    let lines = model.lines();
    let mut s = LivoxStream::new(cfg);
    let mut pushed = 0u64;
    let check = |sw: &ringscan::sweep::Sweep| {
        for p in &sw.points {
            assert!(
                p.x.is_finite() && p.y.is_finite() && p.z.is_finite(),
                "{p:?}"
            );
            assert!(p.ring < lines, "{p:?}");
            assert!(p.ret <= 2, "{p:?}");
            assert!((0.0..=255.0).contains(&p.intensity), "{p:?}");
        }
        // At most one return per 8 bytes of a 64 KiB datagram.
        assert!(sw.points.len() <= 8192 * sw.packets as usize);
    };
    for d in rest.split(|&b| b == 0xFE) {
        let v2 = Sdk2Packet::new(d);
        let v1 = Sdk1Packet::new(d);
        match detect_protocol(d) {
            Some(LivoxProtocol::Sdk2) => assert!(v2.is_ok()),
            Some(LivoxProtocol::Sdk1) => assert!(v1.is_ok() && v2.is_err()),
            None => assert!(v1.is_err() && v2.is_err()),
        }
        if let Ok(p) = v2 {
            let _ = (
                p.crc_ok(),
                p.timestamp_ns(),
                p.time_interval_ns(),
                p.frame_cnt(),
            );
            for i in 0..p.records() {
                assert_eq!(p.record_bytes(i).len(), p.record().size());
            }
        }
        if let Ok(p) = v1 {
            let _ = (p.timestamp_ns(), p.status_code());
            for i in 0..p.records() {
                assert_eq!(p.record_bytes(i).len(), p.record().size());
            }
        }
        for _ in 0..2 {
            s.push(pushed as i64, d, &mut |sw, _| check(sw));
            pushed += 1;
        }
        // The same bytes as the values of an IMU frame (a CustomMsg bag's IMU topic): any
        // values, NaN and infinities included, are a sample or skipped, never a panic.
        if let Some(v) = d.get(..56) {
            let mut f = ringscan::sensor::livox::frame::IMU_MAGIC.to_vec();
            f.extend_from_slice(v);
            s.push(pushed as i64, &f, &mut |sw, _| check(sw));
            pushed += 1;
        }
    }
    s.finish(&mut |sw, _| check(sw));
    let st = s.stats();
    assert_eq!(
        st.packets + st.imu_packets + st.frames + st.malformed + st.duplicates + st.late_dropped,
        pushed
    );
    assert!(s.drain_imu().count() <= LIVOX_MAX_IMU_QUEUE);
}

/// Target `livox_control`: any bytes as a Livox control frame of both protocols
/// (`sensor::livox::control::sdk2_parse` / `sdk1_parse`, what `listen --configure` reads from
/// the network), then the ACK and broadcast readers on what they hold.
///
/// No panic; a frame that parses spans the whole input, its data is the input after the
/// header (SDK2) or between the command bytes and the CRC-32 (SDK1), and the frame built
/// again from its fields parses to the same fields.
pub fn livox_control(data: &[u8]) {
    use ringscan::sensor::livox::control as c;
    if let Ok(f) = c::sdk2_parse(data) {
        assert_eq!(f.data.len() + c::SDK2_HEADER, data.len());
        assert_eq!(f.data, &data[c::SDK2_HEADER..]);
        let again = c::sdk2_frame(f.seq, f.cmd_id, f.cmd_type, f.sender_type, f.data);
        let g = c::sdk2_parse(&again).expect("a rebuilt SDK2 frame parses");
        assert_eq!(
            (g.seq, g.cmd_id, g.cmd_type, g.sender_type, g.data),
            (f.seq, f.cmd_id, f.cmd_type, f.sender_type, f.data)
        );
        if let Ok(a) = c::sdk2_discovery_ack(f.data) {
            let _ = (a.serial_str(), c::sdk2_model(a.dev_type));
        }
        let _ = c::sdk2_params_ack(f.data).map(|(r, _)| c::sdk2_return_name(r));
    }
    if let Ok(f) = c::sdk1_parse(data) {
        assert_eq!(f.payload.len() + c::SDK1_WRAPPER, data.len());
        let again = c::sdk1_frame(f.cmd_type, f.seq, f.cmd_set, f.cmd_id, f.payload);
        assert_eq!(
            again, data,
            "SDK1 frames have no free bytes: rebuilt byte for byte"
        );
        if let Some(b) = c::sdk1_broadcast(&f) {
            let _ = (b.code_str(), c::sdk1_model(b.dev_type));
        }
        let _ = c::sdk1_ack_code(&f, c::sdk1_cmd::HEARTBEAT).map(c::sdk1_return_name);
    }
}

// ----- lvx -------------------------------------------------------------------------------------

use ringscan::source::lvx::LvxSource;

/// A Livox recording. Byte 0 picks what precedes the rest: nothing (the rest is a whole file),
/// or valid `.lvx2` / `.lvx` headers with one device (MID-360 id 0 / Avia index 0), so the
/// fuzzer starts at the frames. Every datagram goes into a `LivoxStream` of the file's model.
/// No panic; the source never reads past the input, returns no datagram longer than one UDP
/// payload and no more datagrams than packages; the stream counts each datagram once.
pub fn lvx(data: &[u8]) {
    let Some((&sel, rest)) = data.split_first() else {
        return;
    };
    let mut file = Vec::with_capacity(data.len() + 100);
    if sel % 3 != 0 {
        let v2 = sel % 3 == 1;
        file.extend_from_slice(b"livox_tech\0\0\0\0\0\0");
        file.extend_from_slice(if v2 { &[2, 0, 0, 0] } else { &[1, 1, 0, 0] });
        file.extend_from_slice(&0xAC0E_A767u32.to_le_bytes());
        file.extend_from_slice(&50u32.to_le_bytes());
        file.push(1);
        file.extend_from_slice(&[0; 32]);
        if v2 {
            file.extend_from_slice(&[0, 0, 0, 0, 8, 9, 0]);
        } else {
            file.extend_from_slice(&[0, 7, 0]);
        }
        file.extend_from_slice(&[0; 24]);
    }
    file.extend_from_slice(rest);
    let Ok(mut src) = LvxSource::new(&file[..]) else {
        return;
    };
    let model = src.model().unwrap_or(LIVOX_MODELS[0]);
    let mut s = LivoxStream::new(LivoxConfig::new(Some(model), model.protocol()));
    let mut pushed = 0u64;
    while let Ok(Some(d)) = src.next_datagram() {
        assert!(d.payload.len() <= 1500, "{} bytes", d.payload.len());
        s.push(d.time_ns, d.payload, &mut |_, _| {});
        pushed += 1;
    }
    s.finish(&mut |_, _| {});
    let st = src.stats();
    assert!(st.bytes <= file.len() as u64, "{st:?}");
    assert_eq!(st.datagrams, pushed);
    assert!(st.datagrams <= st.packages);
    let ls = s.stats();
    assert_eq!(
        ls.packets + ls.imu_packets + ls.malformed + ls.duplicates + ls.late_dropped,
        pushed
    );
}

/// `render_messages`: byte 0 picks the reader, the rest is one CDR message as `render` reads
/// a `--format ros2` file's (`sink::read::PointCloud::from_cdr`, `SceneUpdate::from_cdr_markers`).
/// No panic; a cloud that reads holds no more record bytes and fields than the message has
/// bytes, a marker array no more cubes than one per 16 bytes. Then the ROS 2 sink's encoder
/// writes a `PointCloud2` of the fuzzed records (a frame id and stride from the bytes) that
/// reads back with the same frame, stride, fields and records.
pub fn render_messages(data: &[u8]) {
    use ringscan::point::FieldType;
    use ringscan::sink::read::{PointCloud, SceneUpdate};
    let Some((&sel, msg)) = data.split_first() else {
        return;
    };
    if sel % 2 == 0 {
        if let Ok(pc) = PointCloud::from_cdr(msg) {
            assert!(pc.data.len() <= msg.len());
            assert!(pc.fields.len() * 13 <= msg.len());
            let stride = pc.point_stride as usize;
            for f in &pc.fields {
                let _ = pc.f32s(f.offset as usize).count();
            }
            if let Some(records) = pc.data.len().checked_div(stride) {
                assert!(pc.f32s(0).count() <= records);
            }
        }
    } else if let Ok(u) = SceneUpdate::from_cdr_markers(msg) {
        assert!((u.entities.len() + u.deletions.len()) * 16 <= msg.len());
        for e in &u.entities {
            assert_eq!(e.cubes.len(), 1);
        }
    }
    // The encoder's output reads back.
    let stride = usize::from(sel % 32) + 4;
    let frame: String = msg
        .iter()
        .take(12)
        .map(|b| char::from(b'a' + b % 26))
        .collect();
    let records = &msg[..msg.len() / stride * stride];
    let fields = [("x", 0usize, FieldType::F32)];
    let mut buf = Vec::new();
    if ringscan::sink::ros2::encode_point_cloud2_fields(
        &mut buf, 1, &frame, stride, &fields, records,
    )
    .is_ok()
    {
        let pc = PointCloud::from_cdr(&buf).expect("the encoder's PointCloud2 reads back");
        assert_eq!(pc.frame_id, frame);
        assert_eq!(pc.point_stride as usize, stride);
        assert_eq!(pc.data, records);
        assert_eq!(pc.fields.len(), 1);
        assert_eq!((pc.fields[0].name.as_str(), pc.fields[0].offset), ("x", 0));
    }
}

// ----- family_stream ---------------------------------------------------------------------------

use ringscan::sensor::livox::LivoxModel;
use ringscan::sensor::{Calibration, CalibrationPool, StreamSettings};

/// One model's simulated traffic for `family_stream`, built once: the packets in the order the
/// simulator sends them, and what bounds the stream's output.
struct FamilySet {
    /// Family name as `Calibration::family` spells it, and the model's `--model` id.
    family: &'static str,
    model_id: &'static str,
    /// (host receive time, destination port, payload).
    packets: Vec<(i64, u16, Vec<u8>)>,
    /// The angle correction / angle file a run gives (`--calib`), if the family takes one.
    calib: Option<Calibration>,
    /// Farthest point the model's packets can give, metres (the coordinate bound).
    max_range_m: f32,
    /// Rings and returns a point may be on.
    rings: u16,
    max_ret: u8,
    /// Most points one datagram of the model yields.
    per_packet: usize,
    /// Points of a nominal sweep (100 ms at the simulated rate), and how many of those the
    /// stream's caps let a sweep hold (its time cap over 100 ms, or its packet cap, plus slack).
    nominal_sweep_points: usize,
    sweeps_per_cap: usize,
    /// Largest point time (`t`, ns after the sweep's start) the stream's sweep cut allows.
    max_t_ns: u32,
}

/// Simulated sessions start here (2024-05-01): host and sensor clocks agree.
const FAMILY_T0: i64 = 1_714_564_800_000_000_000;

/// A `Calibration` as `--calib` gives it, around an already parsed table.
fn family_calibration<T: std::any::Any + Send + Sync>(
    family: &'static str,
    file: &str,
    t: T,
) -> Calibration {
    Calibration {
        family,
        addr: None,
        file_name: file.into(),
        bytes: std::sync::Arc::from(&b""[..]),
        parsed: std::sync::Arc::new(t),
    }
}

/// The models `family_stream` drives, one simulated run each (built on first use).
fn family_sets() -> &'static [FamilySet] {
    static SETS: OnceLock<Vec<FamilySet>> = OnceLock::new();
    SETS.get_or_init(|| {
        use ringscan::sensor::hesai::sim::HesaiSim;
        use ringscan::sensor::livox::sim::LivoxSim;
        use ringscan::sensor::robosense::m1::{M1_BLOCKS, M1_CHANNELS, M1_PACKETS_PER_FRAME};
        use ringscan::sensor::robosense::sim::{M1Sim, RobosenseSim};
        let scene = ringscan::sim::scene::Shapes::room(20.0, 15.0, 1.8, 3.0);
        let mut sets = Vec::new();
        // Hesai: 1.5 turns (at most 600 packets), so that the run crosses the cut.
        for model in [
            HesaiModel::PandarXt32,
            HesaiModel::Pandar64,
            HesaiModel::PandarQt128,
        ] {
            let calib = hesai_correction(model);
            let mut sim = HesaiSim::new(model, calib.clone(), FAMILY_T0);
            let period = sim.period_ns();
            let n = (150_000_000 / period).min(600) as usize;
            let mut truth = Vec::new();
            let packets = (0..n)
                .map(|_| {
                    truth.clear();
                    let (h, p) = sim.next_packet(&scene, &mut truth);
                    (h, 2368, p)
                })
                .collect();
            let l = &model.spec().layout;
            let per_packet = l.blocks * l.channels;
            sets.push(FamilySet {
                family: "hesai",
                model_id: model.id(),
                packets,
                calib: Some(family_calibration("hesai", "fuzz.csv", calib)),
                max_range_m: model.spec().max_range_m * 1.001 + 1e-3,
                rings: model.channels() as u16,
                max_ret: 2,
                per_packet,
                nominal_sweep_points: per_packet * (100_000_000 / period as usize + 1),
                // `max_sweep_ns` (1 s), and at most twice the packets 1 s holds.
                sweeps_per_cap: 21,
                max_t_ns: 1_010_000_000,
            });
        }
        // Robosense spinning: its DIFOP first, then 1.5 turns (at most 600 packets).
        for model in [RobosenseModel::Helios16P, RobosenseModel::Rs32] {
            let angles = robosense_angles(model);
            let mut sim = RobosenseSim::new(model, angles.clone(), FAMILY_T0);
            let period = model.spec().packet_period_ns(false);
            let n = ((150e6 / period) as usize).min(600);
            let mut truth = Vec::new();
            let mut packets = vec![(FAMILY_T0, 7788, sim.difop())];
            packets.extend((0..n).map(|_| {
                truth.clear();
                let (h, p) = sim.next_packet(&scene, &mut truth);
                (h, 6699, p)
            }));
            let shape = model.spec().shape;
            let per_packet = shape.blocks() * shape.slots();
            sets.push(FamilySet {
                family: "robosense",
                model_id: model.id(),
                packets,
                calib: Some(family_calibration("robosense", "fuzz.csv", angles)),
                max_range_m: model.spec().max_range_m + 0.2,
                rings: model.lasers() as u16,
                max_ret: 1,
                per_packet,
                nominal_sweep_points: per_packet * ((1e8 / period) as usize + 1),
                // `max_sweep_ns` (1 s).
                sweeps_per_cap: 11,
                max_t_ns: 1_010_000_000,
            });
        }
        // M1: its DIFOP, then a frame and a tenth (the counter restarts once).
        {
            let mut sim = M1Sim::new(FAMILY_T0);
            let mut truth = Vec::new();
            let mut packets = vec![(FAMILY_T0, 7788, sim.difop())];
            packets.extend((0..700).map(|_| {
                truth.clear();
                let (h, p) = sim.next_packet(&scene, &mut truth);
                (h, 6699, p)
            }));
            let per_packet = M1_BLOCKS * M1_CHANNELS;
            sets.push(FamilySet {
                family: "robosense",
                model_id: RobosenseModel::M1.id(),
                packets,
                calib: None,
                max_range_m: 200.01,
                rings: M1_CHANNELS as u16,
                max_ret: 1,
                per_packet,
                nominal_sweep_points: per_packet * usize::from(M1_PACKETS_PER_FRAME),
                // `M1_MAX_SWEEP_NS` (1.5 frames); dual return sends twice the packets.
                sweeps_per_cap: 4,
                max_t_ns: 151_000_000,
            });
        }
        // Livox: 150 ms of point and IMU packets, in the order they arrive.
        for model in [LivoxModel::Mid360, LivoxModel::Avia] {
            let mut sim = LivoxSim::new(model, FAMILY_T0);
            let (mut truth, mut imu) = (Vec::new(), Vec::new());
            let packets = sim.run_until(&scene, FAMILY_T0 + 150_000_000, &mut truth, &mut imu);
            let period = sim.packet_period_ns() as usize;
            sets.push(FamilySet {
                family: "livox",
                model_id: model.id(),
                packets,
                calib: None,
                // Records carry i32 millimetres (or a u32 depth): nothing nearer bounds them.
                max_range_m: 3.8e6,
                rings: model.lines(),
                max_ret: 2,
                // Two returns a record at most, a record 14 bytes or more: bounded per push
                // by the datagram's length instead (see `family_stream`).
                per_packet: 0,
                nominal_sweep_points: 2 * 96 * (100_000_000 / period + 1),
                // A sweep is cut at two periods (of 100 ms at least).
                sweeps_per_cap: 5,
                max_t_ns: 210_000_000,
            });
        }
        sets
    })
}

/// Most points one datagram of `len` bytes can give a Livox stream: 36 header bytes, then
/// records of at least 8 bytes (SDK2 cm Cartesian), two returns a record at most (0x11).
fn livox_points_bound(len: usize) -> usize {
    2 * len / 8
}

/// `family_stream`: whole packet sequences through the Hesai, Robosense and Livox streams, as
/// the CLI builds them (`sensor::claim` with a `CalibrationPool`). Byte 0 picks the model (of a
/// simulated run built once) and the settings; then ops: push the next packet, a run of them,
/// any packet (reorders, repeats, skips), a packet with bytes patched or a byte nudged
/// (sequence numbers, times, azimuths, counters), host time moved, a truncated packet or
/// garbage; at most 4 096 pushes. No panic; every datagram counted once; points finite,
/// within the model's range, on its rings and returns, at most its per-packet count per
/// packet of the sweep; point times within the sweep's time cap; sweeps within their caps;
/// sweeps and points counted = handed over; the summary serialises.
pub fn family_stream(data: &[u8]) {
    let mut b = Bytes::new(data);
    let sel = b.u8();
    let sets = family_sets();
    let set = &sets[usize::from(sel & 7) % sets.len()];
    let livox = set.family == "livox";
    let settings = StreamSettings {
        model: (sel & 0x08 != 0).then(|| set.model_id.to_string()),
        // Off, so that patched packets reach the sequence logic (on: their CRCs catch them).
        crc: (sel & 0x10 == 0).then_some(false),
        cut_angle: if sel & 0x40 != 0 { 18_000 } else { 0 },
        keep_columns: sel & 0x80 != 0,
        integration_ns: (livox && sel & 0x80 != 0).then_some(50_000_000),
        ..StreamSettings::default()
    };
    // Robosense without its angle file: the DIFOP supplies the angles (packets held till then).
    let calibs = match &set.calib {
        Some(c) if !(set.family == "robosense" && sel & 0x20 != 0) => vec![c.clone()],
        _ => Vec::new(),
    };
    // Without an angle file or `--model`, a Robosense stream tells the Helios-16P from the
    // Helios (32 lasers, same header) by the DIFOP's angle table, which the ops may patch: its
    // points are then on the Helios's 32 rings, as the DIFOP says.
    let rings = if set.family == "robosense" && calibs.is_empty() && settings.model.is_none() {
        set.rings.max(32)
    } else {
        set.rings
    };
    let mut pool = CalibrationPool::new(calibs, settings);
    // As the demultiplexer does: the source's first datagram some family claims makes its
    // stream (and goes into it); datagrams before it are left unclaimed.
    let mut stream: Option<Box<dyn SensorStream>> = None;
    let mut unclaimed = 0u64;
    let n = set.packets.len();
    let sweeps = Cell::new(0u64);
    let points = Cell::new(0u64);
    let max_sweep_points = set.nominal_sweep_points * set.sweeps_per_cap;
    let mut on_sweep = |sw: &mut Sweep, _: &dyn Facts| {
        sweeps.set(sweeps.get() + 1);
        points.set(points.get() + sw.points.len() as u64);
        let per_packet = if livox {
            livox_points_bound(1500)
        } else {
            set.per_packet
        };
        assert!(
            sw.points.len() <= per_packet * sw.packets as usize,
            "{} points from {} packets",
            sw.points.len(),
            sw.packets
        );
        if check("family-sweep-points-cap") {
            assert!(
                sw.points.len() <= max_sweep_points,
                "{}: a sweep of {} points ({} packets), cap {max_sweep_points}",
                set.model_id,
                sw.points.len(),
                sw.packets
            );
        }
        if !sw.columns.is_empty() {
            assert_eq!(sw.columns.len(), sw.points.len());
        }
        for p in &sw.points {
            assert!(
                p.x.is_finite() && p.y.is_finite() && p.z.is_finite(),
                "{p:?}"
            );
            let r = (p.x * p.x + p.y * p.y + p.z * p.z).sqrt();
            assert!(r <= set.max_range_m, "{p:?} beyond {} m", set.max_range_m);
            assert!(p.ring < rings && p.ret <= set.max_ret, "{p:?}");
            assert!((0.0..=255.0).contains(&p.intensity), "{p:?}");
            if check("family-point-time") {
                assert!(
                    p.t <= set.max_t_ns,
                    "{}: point at {} ns in a sweep of {} packets, bound {}",
                    set.model_id,
                    p.t,
                    sw.packets,
                    set.max_t_ns
                );
            }
        }
    };

    let mut cursor = 0usize;
    let mut host_off = 0i64;
    let mut pushed = 0u64;
    let mut bound_points = 0u64;
    let mut buf: Vec<u8> = Vec::new();
    let mut failed = false;
    'ops: while !b.is_empty() && pushed < 4096 {
        let op = b.u8();
        // Which packets this op pushes (from the simulated run), and how each is changed.
        let (first_i, count) = match op & 7 {
            0 | 3 | 4 | 6 => (cursor, 1),
            1 => (cursor, 1 + usize::from(b.u8())),
            2 => (usize::from(b.u16()) % n, 1),
            5 => {
                if op & 8 != 0 {
                    host_off = b.i64();
                } else {
                    host_off = host_off.saturating_add(i64::from(b.u16() as i16) * 50_000);
                }
                continue;
            }
            _ => (cursor, 1),
        };
        for k in 0..count {
            if pushed >= 4096 {
                break 'ops;
            }
            let i = (first_i + k) % n;
            cursor = (i + 1) % n;
            let (host, port, packet) = &set.packets[i];
            buf.clear();
            buf.extend_from_slice(packet);
            let len = buf.len();
            match op & 7 {
                3 => {
                    // Bytes written at an offset from the start or the end (the tails of
                    // Hesai packets hold their time and sequence number).
                    let at = usize::from(b.u16()) % len;
                    let at = if op & 8 != 0 { len - 1 - at } else { at };
                    let bytes = b.take(1 + usize::from((op >> 4) & 7));
                    let m = bytes.len().min(len - at);
                    buf[at..at + m].copy_from_slice(&bytes[..m]);
                }
                4 => {
                    // One byte nudged by a small signed amount (a time or counter stepping).
                    let at = usize::from(b.u16()) % len;
                    let at = if op & 8 != 0 { len - 1 - at } else { at };
                    buf[at] = buf[at].wrapping_add(b.u8());
                }
                6 => buf.truncate(usize::from(b.u16()) % len),
                7 => {
                    buf.clear();
                    let len = usize::from(b.u8());
                    buf.extend_from_slice(b.take(len));
                }
                _ => {}
            }
            bound_points += if livox {
                livox_points_bound(buf.len()) as u64
            } else {
                set.per_packet as u64
            };
            if stream.is_none() {
                let d = FirstDatagram {
                    src: Ipv4Addr::new(192, 168, 1, 201),
                    port: *port,
                    payload: &buf,
                };
                match ringscan::sensor::claim(&d, &mut pool) {
                    Some(Ok(s)) => stream = Some(s),
                    // Recognised, not decodable with what the run has (as the CLI reports
                    // it): nothing more to drive.
                    Some(Err(_)) => return,
                    None => {
                        unclaimed += 1;
                        continue;
                    }
                }
            }
            let Some(s) = stream.as_mut() else {
                unreachable!("claimed above")
            };
            pushed += 1;
            if s.push(host.saturating_add(host_off), &buf, &mut on_sweep)
                .is_err()
            {
                // The stream cannot decode at all (its model told from a changed packet
                // does not fit the calibration): the run stops there, as the CLI's does.
                failed = true;
                break 'ops;
            }
        }
    }
    let Some(mut stream) = stream else {
        assert!(unclaimed > 0 || pushed == 0);
        return;
    };
    stream.finish(&mut on_sweep).expect("finish");
    let (summary, counts) = stream.summary();
    serde_json::to_string(&summary).expect("the summary serialises");
    assert!(counts.decoded <= pushed, "{counts:?}, {pushed} pushed");
    assert!(points.get() <= bound_points, "{} points", points.get());

    let any = stream.as_any();
    let (st_sweeps, st_points, counted, what) = if let Some(s) = any.downcast_ref::<HesaiStream>() {
        let st = s.stats();
        let c = st.packets + st.malformed + st.duplicates + st.late_dropped;
        (st.sweeps, st.points, c, format!("{st:?}"))
    } else if let Some(s) = any.downcast_ref::<RobosenseStream>() {
        let st = s.stats();
        assert_eq!(s.held(), 0, "finish drops what is held");
        let c = st.packets + st.malformed + st.difop + st.dropped + st.duplicates + st.late_dropped;
        // While "robosense-difop-counted-twice" is open, a DIFOP may be counted twice: any
        // excess up to `difop` is let through.
        let c = if check("robosense-difop-counted-twice") || c <= pushed {
            c
        } else {
            c.saturating_sub(st.difop).max(pushed)
        };
        (st.sweeps, st.points, c, format!("{st:?}"))
    } else if let Some(s) = any.downcast_ref::<LivoxStream>() {
        let st = s.stats();
        let c = st.packets
            + st.imu_packets
            + st.frames
            + st.malformed
            + st.duplicates
            + st.late_dropped;
        (st.sweeps, st.points, c, format!("{st:?}"))
    } else {
        // A changed packet another family claimed first: not this target's stream.
        return;
    };
    // The datagram a failed push was given may be counted or not.
    assert!(
        counted == pushed || (failed && counted + 1 == pushed),
        "every datagram counted once: {pushed} pushed, {what}"
    );
    assert_eq!(st_sweeps, sweeps.get(), "{what}");
    assert_eq!(st_points, points.get(), "{what}");
}
