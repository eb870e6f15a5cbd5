//! Livox Viewer recordings (`.lvx`, `.lvx2`) as inputs. The files are written here byte by
//! byte from the published layouts (Livox "LVX Specifications" 1.1, "LVX2 Specifications"
//! 2.0: public header, private header, device info, frames of packages), not by anything in
//! `src`. Hand-built files decode to the values written into them; files made from the
//! simulator's MID-360 (`.lvx2`) and Avia (`.lvx`) packets — the bytes `simulate` writes into
//! a pcap — decode to the same points, times, lines, reflectivities, tags and IMU samples as
//! the packets themselves; every truncation and every flipped byte of a small file ends in an
//! error or a counted drop, never a panic.
#![cfg(all(feature = "sim", feature = "pcap", feature = "bag"))]

mod common;
use common::Scratch;

use ringscan::point::Point;
use ringscan::sensor::livox::model::LivoxModel;
use ringscan::sensor::livox::sim::LivoxSim;
use ringscan::sensor::livox::{LivoxConfig, LivoxStream};
use ringscan::sensor::ImuSample;
use ringscan::sim::motion::{Route, Trajectory};
use ringscan::sim::scenes;
use ringscan::source::bag::BagOptions;
use ringscan::source::input::{self, Input};
use ringscan::source::lvx::LvxSource;
use ringscan::sweep::Sweep;

const T0: i64 = 1_714_564_800_000_000_000;
const MAGIC: u32 = 0xAC0E_A767;

/// Datagrams as (time, destination port, payload).
type Datagrams = Vec<(i64, u16, Vec<u8>)>;

// ----- a writer from the specification -------------------------------------------------------

fn public_header(version: [u8; 4]) -> Vec<u8> {
    let mut b = b"livox_tech".to_vec();
    b.resize(16, 0);
    b.extend_from_slice(&version);
    b.extend_from_slice(&MAGIC.to_le_bytes());
    b
}

fn private_header(duration_ms: u32, devices: u8) -> Vec<u8> {
    let mut b = duration_ms.to_le_bytes().to_vec();
    b.push(devices);
    b
}

fn sn(s: &str) -> Vec<u8> {
    let mut b = s.as_bytes().to_vec();
    b.resize(16, 0);
    b
}

/// `.lvx2` device info: lidar SN, hub SN, lidar id u32, lidar type, device type, extrinsic
/// enable, roll pitch yaw x y z.
fn device_lvx2(lidar_id: u32, device_type: u8) -> Vec<u8> {
    let mut b = sn("47MDL9T0020193");
    b.extend(sn(""));
    b.extend_from_slice(&lidar_id.to_le_bytes());
    b.push(8);
    b.push(device_type);
    b.push(0);
    b.extend([0u8; 24]);
    assert_eq!(b.len(), 63);
    b
}

/// `.lvx` device info: lidar SN, hub SN, device index, device type, extrinsic enable, six f32.
fn device_lvx1(index: u8, device_type: u8) -> Vec<u8> {
    let mut b = sn("3GGDJ6K00100101");
    b.extend(sn(""));
    b.push(index);
    b.push(device_type);
    b.push(1);
    for v in [0.0f32, 0.0, 90.0, 1.5, 0.0, 0.25] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    assert_eq!(b.len(), 59);
    b
}

/// `.lvx2` package: version, lidar id, lidar type, timestamp type, timestamp, udp counter,
/// data type, length, frame counter, reserved, records.
#[allow(clippy::too_many_arguments)]
fn package_lvx2(
    lidar_id: u32,
    time_type: u8,
    stamp_ns: u64,
    udp_cnt: u16,
    data_type: u8,
    frame_cnt: u8,
    data: &[u8],
) -> Vec<u8> {
    let mut b = vec![0u8];
    b.extend_from_slice(&lidar_id.to_le_bytes());
    b.push(8);
    b.push(time_type);
    b.extend_from_slice(&stamp_ns.to_le_bytes());
    b.extend_from_slice(&udp_cnt.to_le_bytes());
    b.push(data_type);
    b.extend_from_slice(&(data.len() as u32).to_le_bytes());
    b.push(frame_cnt);
    b.extend([0u8; 4]);
    assert_eq!(b.len(), 27);
    b.extend_from_slice(data);
    b
}

/// An `.lvx2` package from an SDK2 datagram (offsets of the 36-byte header: udp_cnt 7,
/// frame_cnt 9, data type 10, time type 11, timestamp 28).
fn package_from_sdk2(lidar_id: u32, d: &[u8]) -> Vec<u8> {
    let u16_at = |o: usize| u16::from_le_bytes([d[o], d[o + 1]]);
    let ts = u64::from_le_bytes(d[28..36].try_into().unwrap());
    package_lvx2(lidar_id, d[11], ts, u16_at(7), d[10], d[9], &d[36..])
}

/// Frames of packages, starting at file offset `at`: each frame header's current offset is
/// its own position, its next offset the next header's.
fn frames(mut at: u64, frames: &[Vec<Vec<u8>>]) -> Vec<u8> {
    let mut out = Vec::new();
    for (i, pkgs) in frames.iter().enumerate() {
        let len: usize = 24 + pkgs.iter().map(Vec::len).sum::<usize>();
        out.extend_from_slice(&at.to_le_bytes());
        out.extend_from_slice(&(at + len as u64).to_le_bytes());
        out.extend_from_slice(&(i as u64).to_le_bytes());
        for p in pkgs {
            out.extend_from_slice(p);
        }
        at += len as u64;
    }
    out
}

fn lvx2_file(devices: &[Vec<u8>], frame_list: &[Vec<Vec<u8>>]) -> Vec<u8> {
    let mut f = public_header([2, 0, 0, 0]);
    f.extend(private_header(50, devices.len() as u8));
    for d in devices {
        f.extend_from_slice(d);
    }
    let at = f.len() as u64;
    f.extend(frames(at, frame_list));
    f
}

fn lvx1_file(devices: &[Vec<u8>], frame_list: &[Vec<Vec<u8>>]) -> Vec<u8> {
    let mut f = public_header([1, 1, 0, 0]);
    f.extend(private_header(50, devices.len() as u8));
    for d in devices {
        f.extend_from_slice(d);
    }
    let at = f.len() as u64;
    f.extend(frames(at, frame_list));
    f
}

fn temp_file(name: &str, bytes: &[u8]) -> Scratch {
    let p = Scratch::file("lvx", name);
    std::fs::write(&p, bytes).unwrap();
    p
}

// ----- reading -------------------------------------------------------------------------------

/// Every datagram of a file through `input::open` (the path the command line takes).
fn read_all(path: &std::path::Path) -> (Datagrams, Option<&'static str>) {
    let mut src = input::open(path, BagOptions::default()).unwrap();
    assert!(matches!(src, Input::Lvx(_)), "not opened as a recording");
    let hint = src.model_hint();
    let mut out = Vec::new();
    while let Some(d) = src.next_datagram().unwrap() {
        out.push((d.time_ns, d.dst.port(), d.payload.to_vec()));
    }
    (out, hint)
}

fn stream(
    model: LivoxModel,
    datagrams: &[(i64, u16, Vec<u8>)],
) -> (Vec<Sweep>, Vec<ImuSample>, LivoxStream) {
    let mut s = LivoxStream::new(LivoxConfig::new(Some(model), model.protocol()));
    let (mut sweeps, mut imu) = (Vec::new(), Vec::new());
    for (host, _, b) in datagrams {
        s.push(*host, b, &mut |sw, _| sweeps.push(sw.clone()));
        imu.extend(s.drain_imu());
    }
    s.finish(&mut |sw, _| sweeps.push(sw.clone()));
    (sweeps, imu, s)
}

/// Points with their absolute device time.
fn points(sweeps: &[Sweep]) -> Vec<(i64, Point)> {
    sweeps
        .iter()
        .flat_map(|w| {
            w.points
                .iter()
                .map(move |p| (w.device_time_ns + i64::from(p.t), *p))
        })
        .collect()
}

/// Coordinates equal to the metres written, to f32 rounding.
fn assert_xyz(p: &Point, m: [f64; 3]) {
    for (a, b) in [p.x, p.y, p.z].into_iter().zip(m) {
        assert!(
            (f64::from(a) - b).abs() <= 1e-6 * (1.0 + b.abs()),
            "{p:?} vs {m:?}"
        );
    }
}

// ----- hand-built files ----------------------------------------------------------------------

/// Cartesian mm records (type 1): x, y, z i32, reflectivity, tag.
fn type1(records: &[([i32; 3], u8, u8)]) -> Vec<u8> {
    let mut b = Vec::new();
    for (xyz, r, t) in records {
        for v in xyz {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.push(*r);
        b.push(*t);
    }
    b
}

#[test]
fn handbuilt_lvx2_decodes_to_the_values_written() {
    let lidar_id = 0xC0A8_01C8; // any id; packages name it
    let recs_a: Vec<([i32; 3], u8, u8)> = (0..8)
        .map(|i| {
            (
                [1000 + i, -2000 - 3 * i, 500 + 7 * i],
                10 + i as u8,
                0x10 | i as u8,
            )
        })
        .collect();
    // Type 2: i16 cm.
    let mut data_b = Vec::new();
    for (x, y, z, r, t) in [(123i16, -45i16, 6i16, 200u8, 1u8), (-1, 2, -3, 0, 0)] {
        for v in [x, y, z] {
            data_b.extend_from_slice(&v.to_le_bytes());
        }
        data_b.push(r);
        data_b.push(t);
    }
    let ts_a = T0 as u64;
    let ts_b = ts_a + 40_000;
    let f = lvx2_file(
        &[device_lvx2(lidar_id, 9)],
        &[
            vec![package_lvx2(lidar_id, 1, ts_a, 0, 1, 0, &type1(&recs_a))],
            vec![package_lvx2(lidar_id, 1, ts_b, 1, 2, 0, &data_b)],
        ],
    );
    let path = temp_file("hand.lvx2", &f);
    let (dgrams, hint) = read_all(&path);
    assert_eq!(hint, Some("mid360"), "device type 9 is the MID-360");
    assert_eq!(dgrams.len(), 2);
    assert!(dgrams.iter().all(|d| d.1 == 56_301), "MID-360 points port");
    assert_eq!(
        dgrams[0].0, T0,
        "a datagram's time is its package's timestamp"
    );
    let (sweeps, _, s) = stream(LivoxModel::Mid360, &dgrams);
    assert_eq!(s.stats().malformed, 0);
    assert_eq!(s.stats().crc_failures, 0);
    let pts = points(&sweeps);
    assert_eq!(pts.len(), 10);
    for (i, ((t, p), (xyz, r, tag))) in pts.iter().zip(&recs_a).enumerate() {
        assert_xyz(p, xyz.map(|v| f64::from(v) / 1000.0));
        assert_eq!(p.intensity, f32::from(*r));
        assert_eq!(p.pad, *tag);
        assert_eq!(p.ring, (i % 4) as u16);
        // The MID-360's 200 000 points/s: records 5 µs apart.
        assert_eq!(*t, T0 + 5_000 * i as i64, "record {i}");
    }
    let (t, p) = pts[8];
    assert_xyz(&p, [1.23, -0.45, 0.06]);
    assert_eq!((p.intensity, p.pad, t), (200.0, 1, ts_b as i64));
    let (t, p) = pts[9];
    assert_xyz(&p, [-0.01, 0.02, -0.03]);
    assert_eq!(t, ts_b as i64 + 5_000);
}

/// SDK1 data type 2 (96 records of x, y, z i32 mm, reflectivity, tag) with its 18-byte header.
fn sdk1_type2(stamp_ns: u64, rec: impl Fn(usize) -> ([i32; 3], u8, u8)) -> Vec<u8> {
    let mut b = vec![5, 1, 1, 0];
    b.extend_from_slice(&0u32.to_le_bytes());
    b.push(1); // PTP
    b.push(2);
    b.extend_from_slice(&stamp_ns.to_le_bytes());
    let recs: Vec<_> = (0..96).map(rec).collect();
    b.extend(type1(&recs));
    assert_eq!(b.len(), 1362);
    b
}

#[test]
fn handbuilt_lvx_decodes_to_the_values_written() {
    let rec = |i: usize| {
        let i32i = i as i32;
        (
            [20_000 + i32i, -i32i * 11, 3 * i32i - 100],
            (i * 2) as u8,
            (i % 3) as u8,
        )
    };
    let mut pkg = vec![3u8]; // device index 3
    pkg.extend(sdk1_type2(T0 as u64, rec));
    let f = lvx1_file(&[device_lvx1(3, 7)], &[vec![pkg.clone(), pkg.clone()]]);
    let path = temp_file("hand.lvx", &f);
    let (dgrams, hint) = read_all(&path);
    assert_eq!(hint, Some("avia"), "device type 7 is the Avia");
    assert_eq!(dgrams.len(), 2);
    assert_eq!(
        dgrams[0].2,
        pkg[1..],
        "an .lvx package is the SDK1 datagram"
    );
    assert_eq!(dgrams[0].1, 56_001);
    // The recording's devices, as the file lists them.
    let src = LvxSource::new(std::fs::File::open(&path).unwrap()).unwrap();
    let d = &src.devices()[0];
    assert_eq!(
        (d.id, d.device_type, d.model),
        (3, 7, Some(LivoxModel::Avia))
    );
    assert_eq!(d.lidar_sn, "3GGDJ6K00100101");
    assert_eq!(d.extrinsic, Some([0.0, 0.0, 90.0, 1.5, 0.0, 0.25]));
    let (sweeps, _, s) = stream(LivoxModel::Avia, &dgrams[..1]);
    assert_eq!(s.stats().malformed, 0);
    let pts = points(&sweeps);
    assert_eq!(pts.len(), 96);
    for (i, (t, p)) in pts.iter().enumerate() {
        let (xyz, r, tag) = rec(i);
        assert_xyz(p, xyz.map(|v| f64::from(v) / 1000.0));
        assert_eq!(
            (p.intensity, p.pad, p.ring),
            (f32::from(r), tag, (i % 6) as u16)
        );
        // SDK1: 4167 ns between records at 240 000 points/s.
        assert_eq!(*t, T0 + 4_167 * i as i64);
    }
}

// ----- the simulator's packets ---------------------------------------------------------------

fn simulated(model: LivoxModel, seconds: f64) -> Datagrams {
    let mut sim = LivoxSim::new(model, T0);
    sim.trajectory = Trajectory::route(T0, Route::urban());
    let (mut truth, mut imu_truth) = (Vec::new(), Vec::new());
    sim.run_until(
        &scenes::urban(),
        T0 + (seconds * 1e9) as i64,
        &mut truth,
        &mut imu_truth,
    )
}

/// Cuts `packages` into frames of `per` packages.
fn framed(packages: Vec<Vec<u8>>, per: usize) -> Vec<Vec<Vec<u8>>> {
    packages.chunks(per).map(<[Vec<u8>]>::to_vec).collect()
}

fn same_output(
    model: LivoxModel,
    from_pcap: &[(i64, u16, Vec<u8>)],
    from_file: &[(i64, u16, Vec<u8>)],
) {
    let (sw_a, imu_a, sa) = stream(model, from_pcap);
    let (sw_b, imu_b, sb) = stream(model, from_file);
    let (a, b) = (points(&sw_a), points(&sw_b));
    assert!(a.len() > 10_000, "{model:?}: {} points", a.len());
    assert_eq!(a.len(), b.len(), "{model:?}: point count");
    for (k, (pa, pb)) in a.iter().zip(&b).enumerate() {
        assert_eq!(pa, pb, "{model:?}: point {k}");
    }
    assert_eq!(sw_a.len(), sw_b.len());
    assert!(!imu_a.is_empty(), "{model:?}: IMU samples");
    assert_eq!(imu_a.len(), imu_b.len());
    for (x, y) in imu_a.iter().zip(&imu_b) {
        assert_eq!(
            (x.sensor_ns, x.gyro, x.accel),
            (y.sensor_ns, y.gyro, y.accel)
        );
    }
    assert_eq!(sb.stats().malformed, 0);
    assert_eq!(sb.stats().missing, sa.stats().missing);
}

#[test]
fn simulated_mid360_lvx2_gives_the_packets_points() {
    let packets = simulated(LivoxModel::Mid360, 0.3);
    let lidar_id = 0x0C01_A8C0;
    let pkgs: Vec<Vec<u8>> = packets
        .iter()
        .map(|(_, _, d)| package_from_sdk2(lidar_id, d))
        .collect();
    let f = lvx2_file(&[device_lvx2(lidar_id, 9)], &framed(pkgs, 100));
    let (dgrams, hint) = read_all(&temp_file("sim.lvx2", &f));
    assert_eq!(hint, Some("mid360"));
    assert_eq!(dgrams.len(), packets.len());
    for ((_, pa, _), (_, pb, _)) in packets.iter().zip(&dgrams) {
        assert_eq!(pa, pb, "points to 56301, IMU to 56401");
    }
    same_output(LivoxModel::Mid360, &packets, &dgrams);
}

#[test]
fn simulated_avia_lvx_gives_the_packets_points() {
    let packets = simulated(LivoxModel::Avia, 0.3);
    let pkgs: Vec<Vec<u8>> = packets
        .iter()
        .map(|(_, _, d)| {
            let mut p = vec![0u8];
            p.extend_from_slice(d);
            p
        })
        .collect();
    let f = lvx1_file(&[device_lvx1(0, 7)], &framed(pkgs, 120));
    let (dgrams, hint) = read_all(&temp_file("sim.lvx", &f));
    assert_eq!(hint, Some("avia"));
    assert_eq!(dgrams.len(), packets.len());
    for ((_, _, a), (_, _, b)) in packets.iter().zip(&dgrams) {
        assert_eq!(a, b, "an .lvx package is the datagram");
    }
    same_output(LivoxModel::Avia, &packets, &dgrams);
}

// ----- hostile files -------------------------------------------------------------------------

/// Reads everything the source gives; the datagram count, or the error.
fn drain(bytes: &[u8]) -> Result<(usize, ringscan::source::lvx::LvxStats), String> {
    let mut src = LvxSource::new(bytes).map_err(|e| e.to_string())?;
    let mut n = 0;
    let mut s = LivoxStream::new(LivoxConfig::new(src.model(), LivoxModel::Mid360.protocol()));
    loop {
        match src.next_datagram() {
            Ok(Some(d)) => {
                assert!(d.payload.len() <= 1500);
                s.push(d.time_ns, d.payload, &mut |_, _| {});
                n += 1;
            }
            Ok(None) => return Ok((n, src.stats().clone())),
            Err(e) => return Err(e.to_string()),
        }
    }
}

fn small_lvx2() -> Vec<u8> {
    let recs: Vec<([i32; 3], u8, u8)> = (0..4).map(|i| ([i, i, i], 1, 0)).collect();
    let id = 7;
    lvx2_file(
        &[device_lvx2(id, 9)],
        &[
            vec![
                package_lvx2(id, 1, 10, 0, 1, 0, &type1(&recs)),
                package_lvx2(id, 1, 20, 1, 1, 0, &type1(&recs)),
            ],
            vec![package_lvx2(id, 1, 30, 2, 1, 0, &type1(&recs))],
        ],
    )
}

#[test]
fn every_truncation_is_an_error_or_a_shorter_stream() {
    for f in [small_lvx2(), {
        let mut pkg = vec![0u8];
        pkg.extend(sdk1_type2(5, |_| ([1, 2, 3], 4, 5)));
        lvx1_file(&[device_lvx1(0, 7)], &[vec![pkg]])
    }] {
        let (whole, st) = drain(&f).unwrap();
        assert!(whole > 0 && st.truncated_at.is_none());
        // Where the frames start, from the next offsets the writer put in the frame headers.
        let header_len = if f[16] == 2 { 24 + 5 + 63 } else { 24 + 5 + 59 };
        let mut boundaries = vec![header_len];
        while let Some(b) = f
            .get(boundaries[boundaries.len() - 1] + 8..)
            .and_then(|b| b.get(..8))
        {
            boundaries.push(u64::from_le_bytes(b.try_into().unwrap()) as usize);
        }
        for cut in 0..f.len() {
            match drain(&f[..cut]) {
                Err(_) => {}
                Ok((n, st)) => {
                    assert!(n < whole, "cut at {cut}: {n} of {whole}");
                    // Cut at a frame's start: a clean end; anywhere else: said where.
                    let want = (!boundaries.contains(&cut)).then_some(cut as u64);
                    assert_eq!(st.truncated_at, want, "cut at {cut}");
                }
            }
        }
    }
}

#[test]
fn flipped_bytes_are_errors_or_counted_drops() {
    let f = small_lvx2();
    let (whole, _) = drain(&f).unwrap();
    let mut outcomes = [0usize; 3];
    for i in 0..f.len() {
        for bit in [0x01u8, 0x80, 0xff] {
            let mut g = f.clone();
            g[i] ^= bit;
            match drain(&g) {
                Err(_) => outcomes[0] += 1,
                Ok((n, st)) if n < whole => {
                    assert!(
                        st.malformed_packages + st.unknown_device > 0 || st.truncated_at.is_some(),
                        "byte {i} ^ {bit:#x}: {n} of {whole} datagrams, no drop counted: {st:?}"
                    );
                    outcomes[1] += 1;
                }
                Ok((n, _)) => {
                    assert_eq!(
                        n, whole,
                        "byte {i} ^ {bit:#x}: datagrams are never invented"
                    );
                    outcomes[2] += 1;
                }
            }
        }
    }
    assert!(outcomes.iter().all(|&c| c > 0), "{outcomes:?}");
}

#[test]
fn not_a_recording_is_read_as_something_else() {
    let mut f = small_lvx2();
    f[0] = b'L';
    let path = temp_file("not.lvx2", &f);
    assert!(input::open(&path, BagOptions::default()).is_err());
    // A version ringscan does not read is named, not guessed at.
    let mut g = small_lvx2();
    g[16] = 1;
    g[17] = 0;
    let e = LvxSource::new(&g[..]).err().unwrap().to_string();
    assert!(e.contains("1.0.0.0"), "{e}");
}

/// A recording's header may list 255 devices, one more than the synthetic addresses
/// 127.0.0.1 … 127.0.0.254: the 255th device's packages are counted and dropped (old: given
/// 127.0.0.1, the first device's address, merging the two devices' streams).
#[test]
fn a_device_beyond_the_254_addresses_is_counted_not_merged() {
    let recs: Vec<([i32; 3], u8, u8)> = (0..4).map(|i| ([i, i, i], 1, 0)).collect();
    let devices: Vec<Vec<u8>> = (0..255).map(|id| device_lvx2(id, 9)).collect();
    let f = lvx2_file(
        &devices,
        &[vec![
            package_lvx2(0, 1, 10, 0, 1, 0, &type1(&recs)),
            package_lvx2(254, 1, 20, 0, 1, 0, &type1(&recs)),
            package_lvx2(253, 1, 30, 0, 1, 0, &type1(&recs)),
        ]],
    );
    let mut src = LvxSource::new(&f[..]).unwrap();
    assert_eq!(src.devices().len(), 255);
    let mut from = Vec::new();
    while let Some(d) = src.next_datagram().unwrap() {
        from.push(d.src.to_string());
    }
    assert_eq!(from, ["127.0.0.1:56301", "127.0.0.254:56301"]);
    assert_eq!(src.stats().device_limit, 1);
    assert_eq!(LvxSource::<&[u8]>::address(254), None);
}

// ----- the command line ----------------------------------------------------------------------

#[cfg(feature = "cli")]
#[test]
fn info_reads_a_recording_and_names_its_model() {
    let packets = simulated(LivoxModel::Avia, 0.25);
    let pkgs: Vec<Vec<u8>> = packets
        .iter()
        .map(|(_, _, d)| {
            let mut p = vec![0u8];
            p.extend_from_slice(d);
            p
        })
        .collect();
    let path = temp_file(
        "cli.lvx",
        &lvx1_file(&[device_lvx1(0, 7)], &framed(pkgs, 120)),
    );
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_ringscan"))
        .args(["info", "--json"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let text = v.to_string();
    assert!(text.contains("Livox Avia"), "{text}");
    assert_eq!(v["capture"]["lvx"]["version"], "lvx 1.1");
    assert_eq!(v["capture"]["datagrams"], packets.len() as u64);
}
