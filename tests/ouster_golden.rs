//! Fidelity against ouster-sdk 1.0.1 on every real Ouster pcap in `../shared/captures`.
//!
//! For every golden (`golden/index.json`, reference `ouster-sdk`: the pcap captures, and the ROS 1
//! bag `512x10_raw.bag` read by `source::bag` with the metadata it holds), for every sensor of
//! the golden:
//! - the metadata named by `sensors[i].metadata` is parsed with `calib::ouster::parse` and
//!   checked against the golden's `as_parsed_by_sdk` values;
//! - the capture is read with `PcapSource` (IPv4 reassembly); the sensor's lidar packets are
//!   the datagrams to its lidar port with the format's size that pass ouster-sdk's sensor
//!   check (init_id / serial, [`OusterDecoder::packet`]); the counts of wrong-size and
//!   wrong-sensor datagrams equal the golden's `size_error_count` / `id_error_count`;
//! - packets are grouped by `frame_id` in arrival order, as the SDK's frame batcher emits
//!   them on these captures; the frame ids and count must be the golden's;
//! - per frame, on every column: columns the SDK holds valid (status bit 0) must be valid in
//!   ringscan's frame with the same timestamp, measurement id and status, and every pixel of
//!   both returns must have the same range, reflectivity, signal, near-IR (integers, exact) and
//!   xyz within 1 mm (the golden's xyz are float32 of the SDK's float64); columns the SDK zeroed
//!   must be invalid and zero in ringscan's frame;
//! - per frame: points per return, sums of every integer field (over points and over all
//!   pixels) equal; xyz sums within points × 1 mm; valid columns, first/last column
//!   timestamps, shot limiting and thermal status equal;
//! - the point stream ([`OusterDecoder::decode_with`]) of the same packets gives the same
//!   points per return, each equal to the frame's pixel, with `t` = column time − the frame's
//!   first valid column time and the ring of its row;
//! - CRC-64: enforced where the firmware has one (≥ 2.5, standard header) and every packet of
//!   those captures passes; FW 2.3 / 2.4 footers are not valid CRCs and are not rejected.
//!
//! `cargo test --test ouster_golden -- --nocapture` prints the figures.

mod common;

use std::net::SocketAddrV4;
use std::path::{Path, PathBuf};

use ringscan::sensor::ouster::calib::parse;
use ringscan::sensor::ouster::calib::ImuProfile;
use ringscan::sensor::ouster::calib::OusterInfo;
use ringscan::sensor::ouster::model::Profile;
use ringscan::sensor::ouster::wire::imu_nmea_packet_bytes;
use ringscan::sensor::ouster::wire::shot_limiting_name;
use ringscan::sensor::ouster::wire::thermal_shutdown_name;
use ringscan::sensor::ouster::wire::ImuPacketLegacy;
use ringscan::sensor::ouster::wire::ImuPacketNmea;
use ringscan::sensor::ouster::wire::LidarPacket;
use ringscan::sensor::ouster::wire::IMU_LEGACY_BYTES;
use ringscan::sensor::ouster::OusterDecoder;
use ringscan::sensor::ouster::OusterFrame;
use ringscan::sensor::DecodeError;
use ringscan::source::pcap::PcapSource;
use serde_json::Value;

/// One datagram of a capture.
struct Dgram {
    src: SocketAddrV4,
    port: u16,
    payload: Vec<u8>,
}

fn read_capture(path: &Path) -> Vec<Dgram> {
    let mut src = PcapSource::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut out = Vec::new();
    while let Some(d) = src
        .next_datagram()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    {
        out.push(Dgram {
            src: d.src,
            port: d.dst.port(),
            payload: d.payload.to_vec(),
        });
    }
    out
}

fn json(path: &Path) -> Value {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn u64_of(v: &Value) -> u64 {
    v.as_u64()
        .or_else(|| v.as_str().and_then(|s| s.parse().ok()))
        .unwrap_or_else(|| panic!("not an integer: {v}"))
}

fn f64s(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

fn golden_files(root: &Path) -> Vec<PathBuf> {
    let idx = json(&root.join("golden/index.json"));
    idx["goldens"]
        .as_array()
        .expect("goldens")
        .iter()
        .filter(|g| g["reference"].as_str() == Some("ouster-sdk"))
        .filter(|g| g["capture"].as_str().is_some_and(|c| c.ends_with(".pcap")))
        .map(|g| {
            root.join("golden")
                .join(g["golden"].as_str().expect("golden"))
        })
        .collect()
}

/// The figures of one sensor of one capture.
#[derive(Default, Debug)]
struct Figures {
    capture: String,
    sensor: usize,
    profile: String,
    sources: Vec<SocketAddrV4>,
    packets: usize,
    size_errors: usize,
    id_errors: usize,
    frames: usize,
    columns_compared: usize,
    points_compared: [usize; 2],
    max_dxyz_mm: f64,
    mismatches: usize,
    crc: String,
    imu: String,
}

/// The metadata as ringscan parses it against the golden's record of the SDK's parse.
fn check_info(info: &OusterInfo, s: &Value, what: &str) {
    assert_eq!(
        u64::from(info.init_id),
        u64_of(&s["init_id"]),
        "{what}: init_id"
    );
    assert_eq!(info.serial, u64_of(&s["sn"]), "{what}: serial");
    assert_eq!(
        info.udp_port_lidar,
        s["udp_port_lidar"].as_u64().unwrap() as u16
    );
    if s["udp_profile_lidar"].as_str() == Some("OFF") {
        return;
    }
    assert_eq!(
        info.format.profile.name(),
        s["udp_profile_lidar"].as_str().unwrap(),
        "{what}"
    );
    assert_eq!(
        info.columns_per_frame as u64,
        u64_of(&s["columns_per_frame"])
    );
    assert_eq!(
        info.format.pixels_per_column as u64,
        u64_of(&s["pixels_per_column"])
    );
    assert_eq!(
        info.format.columns_per_packet as u64,
        u64_of(&s["columns_per_packet"])
    );
    let win = f64s(&s["column_window"]);
    assert_eq!(
        (info.column_window.0 as f64, info.column_window.1 as f64),
        (win[0], win[1]),
        "{what}: column window"
    );
    let shift: Vec<f64> = info
        .pixel_shift_by_row
        .iter()
        .map(|&x| f64::from(x))
        .collect();
    assert_eq!(shift, f64s(&s["pixel_shift_by_row"]), "{what}: shifts");
    let sdk = &s["as_parsed_by_sdk"];
    assert_eq!(
        info.beam_altitude_angles,
        f64s(&sdk["beam_altitude_angles_deg"]),
        "{what}"
    );
    assert_eq!(
        info.beam_azimuth_angles,
        f64s(&sdk["beam_azimuth_angles_deg"]),
        "{what}"
    );
    let flat = |m: &Value| -> Vec<f64> { m.as_array().unwrap().iter().flat_map(f64s).collect() };
    assert_eq!(
        info.beam_to_lidar.to_vec(),
        flat(&sdk["beam_to_lidar_transform"]),
        "{what}"
    );
    assert_eq!(
        info.lidar_to_sensor.to_vec(),
        flat(&sdk["lidar_to_sensor_transform"]),
        "{what}"
    );
}

/// A frame as ringscan assembled it, with the packets that made it.
struct Assembled {
    frame: OusterFrame,
    packets: Vec<Vec<u8>>,
}

fn assemble(dec: &OusterDecoder, packets: &[Vec<u8>]) -> Vec<Assembled> {
    let mut frames: Vec<Assembled> = Vec::new();
    let mut cur = dec.new_frame();
    let mut cur_packets: Vec<Vec<u8>> = Vec::new();
    for bytes in packets {
        let p = dec.packet(bytes).expect("accepted before");
        match dec.decode_packet_into_frame(&p, &mut cur) {
            Ok(_) => {}
            Err(DecodeError::FrameId { .. }) => {
                frames.push(Assembled {
                    frame: cur.clone(),
                    packets: std::mem::take(&mut cur_packets),
                });
                cur.clear();
                dec.decode_packet_into_frame(&p, &mut cur)
                    .expect("a cleared frame takes any packet");
            }
            Err(e) => panic!("{e}"),
        }
        cur_packets.push(bytes.clone());
    }
    if cur.frame_id.is_some() {
        frames.push(Assembled {
            frame: cur,
            packets: cur_packets,
        });
    }
    frames
}

fn field_index(fields: &[String], name: &str) -> Option<usize> {
    fields.iter().position(|f| f == name)
}

/// Compares one frame with its golden record and binary dump.
fn check_frame(
    dec: &OusterDecoder,
    a: &Assembled,
    gf: &Value,
    golden_dir: &Path,
    what: &str,
    fig: &mut Figures,
) {
    let f = &a.frame;
    let (h, w) = (f.rows, f.columns);
    assert_eq!(
        u64::from(f.frame_id.unwrap()),
        u64_of(&gf["frame_id"]),
        "{what}"
    );
    assert_eq!(f.packets as u64, u64_of(&gf["packets_received"]), "{what}");
    assert_eq!(
        f.valid_columns() as u64,
        u64_of(&gf["valid_columns"]),
        "{what}"
    );
    assert_eq!(
        shot_limiting_name(f.shot_limiting),
        gf["shot_limiting"].as_str().unwrap(),
        "{what}"
    );
    assert_eq!(
        thermal_shutdown_name(f.thermal_shutdown),
        gf["thermal_shutdown"].as_str().unwrap(),
        "{what}"
    );
    let first_valid = (0..w).find(|&c| f.column_valid(c)).expect("a valid column");
    let last_valid = (0..w).rev().find(|&c| f.column_valid(c)).unwrap();
    assert_eq!(
        first_valid as u64,
        u64_of(&gf["first_valid_column"]),
        "{what}"
    );
    assert_eq!(
        last_valid as u64,
        u64_of(&gf["last_valid_column"]),
        "{what}"
    );
    let t_first = f.timestamp_ns[first_valid];
    assert_eq!(
        t_first,
        u64_of(&gf["first_valid_column_timestamp_ns"]),
        "{what}"
    );
    assert_eq!(
        f.timestamp_ns[last_valid],
        u64_of(&gf["last_valid_column_timestamp_ns"]),
        "{what}"
    );

    let fields: Vec<String> = gf["record_fields"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap().to_owned())
        .collect();
    let nrec = fields.len();
    let records = common::read_f32_records(&golden_dir.join(gf["binary"].as_str().unwrap()), nrec);
    assert_eq!(records.len(), h * w, "{what}: binary size");
    let cols = json(&golden_dir.join(gf["columns_file"].as_str().unwrap()));
    assert_eq!(u64_of(&cols["frame_id"]), u64::from(f.frame_id.unwrap()));
    let g_ts: Vec<u64> = cols["timestamp_ns"]
        .as_array()
        .unwrap()
        .iter()
        .map(u64_of)
        .collect();
    let g_mid: Vec<u64> = cols["measurement_id"]
        .as_array()
        .unwrap()
        .iter()
        .map(u64_of)
        .collect();
    let g_status: Vec<u64> = cols["status"]
        .as_array()
        .unwrap()
        .iter()
        .map(u64_of)
        .collect();

    // Record field names of each return.
    let names = [
        ["range_mm", "reflectivity", "signal", "x", "y", "z"],
        ["range2_mm", "reflectivity2", "signal2", "x2", "y2", "z2"],
    ];
    let nir_at = field_index(&fields, "nir");
    let mut mismatch = |msg: String| {
        if fig.mismatches < 10 {
            eprintln!("MISMATCH {what}: {msg}");
        }
        fig.mismatches += 1;
    };
    for c in 0..w {
        let g_valid = g_status[c] & 1 != 0;
        if g_valid != f.column_valid(c) {
            mismatch(format!("column {c}: valid {g_valid} in the SDK"));
            continue;
        }
        fig.columns_compared += usize::from(g_valid);
        if (
            f.timestamp_ns[c],
            u64::from(f.measurement_id[c]),
            u64::from(f.status[c]),
        ) != (g_ts[c], g_mid[c], g_status[c])
        {
            mismatch(format!("column {c}: timestamp / measurement id / status"));
        }
        for row in 0..h {
            let rec = &records[row * w + c];
            if let Some(k) = nir_at {
                if u32::from(f.near_ir[row * w + c]) != rec[k] as u32 {
                    mismatch(format!(
                        "({row}, {c}) nir {} vs {}",
                        f.near_ir[row * w + c],
                        rec[k]
                    ));
                }
            }
            for (ret, n) in names.iter().enumerate().take(f.returns) {
                let i = f.index(ret, row, c).unwrap();
                let get = |name: &str| field_index(&fields, name).map(|k| rec[k]);
                let range = get(n[0]).expect("range field");
                let ours = [
                    (f.range_mm[i], range),
                    (
                        u32::from(f.reflectivity[i]),
                        get(n[1]).expect("reflectivity"),
                    ),
                ];
                for (o, g) in ours {
                    if o != g as u32 {
                        mismatch(format!("({row}, {c}) ret {ret}: {o} vs {g}"));
                    }
                }
                if let Some(g) = get(n[2]) {
                    if u32::from(f.signal[i]) != g as u32 {
                        mismatch(format!("({row}, {c}) ret {ret} signal"));
                    }
                }
                let gx = [get(n[3]).unwrap(), get(n[4]).unwrap(), get(n[5]).unwrap()];
                let d = f.xyz[i]
                    .iter()
                    .zip(gx)
                    .map(|(&o, g)| (f64::from(o) - f64::from(g)).abs())
                    .fold(0f64, f64::max);
                if range > 0.0 {
                    fig.points_compared[ret] += 1;
                    fig.max_dxyz_mm = fig.max_dxyz_mm.max(d * 1e3);
                    if d > 1e-3 {
                        mismatch(format!("({row}, {c}) ret {ret}: |Δxyz| {:.3} mm", d * 1e3));
                    }
                    if !f.valid[i] {
                        mismatch(format!("({row}, {c}) ret {ret}: not a point"));
                    }
                } else if d != 0.0 || f.valid[i] {
                    mismatch(format!("({row}, {c}) ret {ret}: empty pixel not zero"));
                }
            }
        }
    }

    // Per-frame sums.
    let plane = h * w;
    for (ret, gr) in gf["returns"].as_array().unwrap().iter().enumerate() {
        let pts = u64_of(&gr["points"]) as usize;
        assert_eq!(f.points(ret), pts, "{what}: points of return {}", ret + 1);
        let range = ret * plane..(ret + 1) * plane;
        let pix = |i: usize| i - ret * plane;
        let value = |name: &str, i: usize| -> f64 {
            match name.replace('2', "").as_str() {
                "range_mm" | "range" => f64::from(f.range_mm[i]),
                "reflectivity" => f64::from(f.reflectivity[i]),
                "signal" => f64::from(f.signal[i]),
                "nir" => f64::from(f.near_ir[pix(i)]),
                "x" => f64::from(f.xyz[i][0]),
                "y" => f64::from(f.xyz[i][1]),
                "z" => f64::from(f.xyz[i][2]),
                other => panic!("unknown field {other}"),
            }
        };
        for (name, g) in gr["sum"].as_object().unwrap() {
            let g = g.as_f64().unwrap();
            let ours: f64 = range
                .clone()
                .filter(|&i| f.valid[i])
                .map(|i| value(name, i))
                .sum();
            if name.starts_with(['x', 'y', 'z']) {
                assert!(
                    (ours - g).abs() <= pts as f64 * 1e-3,
                    "{what}: sum of {name}: {ours} vs {g}"
                );
            } else {
                assert_eq!(ours, g, "{what}: sum of {name}");
            }
        }
        for (name, g) in gr["sum_all_pixels"].as_object().unwrap() {
            let ours: f64 = range.clone().map(|i| value(name, i)).sum();
            assert_eq!(
                ours,
                g.as_f64().unwrap(),
                "{what}: sum over all pixels of {name}"
            );
        }
    }

    // The point stream of the same packets.
    let rings = dec.rings();
    let mut per_return = [0usize; 2];
    for bytes in &a.packets {
        let p = dec.packet(bytes).unwrap();
        dec.decode_with(&p, t_first, |pt, x, row, col| {
            let r = usize::from(pt.ret);
            per_return[r] += 1;
            let i = f.index(r, row, col).unwrap();
            let ok = [pt.x, pt.y, pt.z] == f.xyz[i]
                && x.range_mm == f.range_mm[i]
                && pt.intensity == f32::from(f.reflectivity[i])
                && u64::from(pt.t) == f.timestamp_ns[col] - t_first
                && pt.ring == rings[row];
            if !ok {
                mismatch(format!("point stream ({row}, {col}) ret {r}"));
            }
        })
        .unwrap();
    }
    for (r, &n) in per_return.iter().enumerate().take(f.returns) {
        assert_eq!(n, f.points(r), "{what}: streamed points of return {r}");
    }
}

/// `metadata`: the metadata text to use (a bag's) instead of the golden's metadata file.
fn check_sensor(
    root: &Path,
    g: &Value,
    si: usize,
    datagrams: &[Dgram],
    golden_dir: &Path,
    metadata: Option<&str>,
) -> Figures {
    let s = &g["sensors"][si];
    let capture = g["capture"].as_str().unwrap();
    let short = Path::new(capture)
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    let what = format!("{short} sensor {si}");
    let (text, meta_name) = match metadata {
        Some(t) => (t.to_string(), "metadata in the bag".to_string()),
        None => {
            let meta = root.join(s["metadata"].as_str().unwrap());
            let text = std::fs::read_to_string(&meta).unwrap();
            (text, meta.to_string_lossy().into_owned())
        }
    };
    let info = parse(&text, &meta_name).unwrap_or_else(|e| panic!("{what}: {e}"));
    check_info(&info, s, &what);
    let mut fig = Figures {
        capture: short,
        sensor: si,
        profile: s["udp_profile_lidar"].as_str().unwrap().to_owned(),
        ..Figures::default()
    };

    // IMU packets on the IMU port, by the metadata's IMU profile.
    let imu_size = match info.imu_profile {
        ImuProfile::Legacy => IMU_LEGACY_BYTES,
        ImuProfile::Accel32Gyro32Nmea => imu_nmea_packet_bytes(info.imu_measurements_per_packet),
        ImuProfile::Off => usize::MAX,
    };
    let (mut imu_n, mut imu_bad) = (0usize, 0usize);
    for d in datagrams
        .iter()
        .filter(|d| d.port == info.udp_port_imu && d.payload.len() == imu_size)
    {
        // |a| ≈ 1 g at rest (LEGACY: g; ACCEL32_GYRO32_NMEA: m/s²).
        let norms: Vec<f32> = match info.imu_profile {
            ImuProfile::Legacy => {
                let a = ImuPacketLegacy::new(&d.payload).unwrap().accel_g();
                vec![(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()]
            }
            _ => ImuPacketNmea::new(&d.payload, info.imu_measurements_per_packet)
                .unwrap()
                .measurements()
                .filter(|m| m.valid())
                .map(|m| {
                    let a = m.accel;
                    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt() / 9.806_65
                })
                .collect(),
        };
        imu_n += 1;
        imu_bad += norms.iter().filter(|n| !(0.8..1.2).contains(*n)).count();
    }
    fig.imu = format!("{imu_n} ({} bad |a|)", imu_bad);
    assert_eq!(imu_bad, 0, "{what}: IMU acceleration not ~1 g at rest");

    if info.lidar_off {
        // No lidar stream: ringscan must find no lidar packet and the SDK no lidar data.
        let lidar = datagrams
            .iter()
            .filter(|d| d.port == info.udp_port_lidar)
            .count();
        assert_eq!(
            lidar, 0,
            "{what}: lidar datagrams although the stream is off"
        );
        for gf in s["frames"].as_array().unwrap() {
            assert_eq!(gf["lidar_data"].as_bool(), Some(false), "{what}");
        }
        // No datagram of the capture is a lidar packet of any profile at this H.
        for d in datagrams {
            for p in ringscan::sensor::ouster::model::ALL_PROFILES {
                let fmt = ringscan::sensor::ouster::model::PacketFormat {
                    profile: p,
                    ..info.format
                };
                assert!(LidarPacket::new(&d.payload, &fmt).is_err(), "{what}");
            }
        }
        fig.crc = "no lidar".to_owned();
        return fig;
    }

    let dec = OusterDecoder::new(&info).unwrap_or_else(|e| panic!("{what}: {e}"));
    let size = info.format.packet_bytes();
    let mut packets = Vec::new();
    let (mut crc_valid, mut crc_invalid, mut crc_zero, mut crc_none) = (0, 0, 0, 0);
    for d in datagrams.iter().filter(|d| d.port == info.udp_port_lidar) {
        if d.payload.len() != size {
            if d.payload.len() != imu_size {
                fig.size_errors += 1;
            }
            continue;
        }
        match dec.packet(&d.payload) {
            Ok(p) => {
                match p.crc() {
                    None => crc_none += 1,
                    Some(0) => crc_zero += 1,
                    Some(_) if p.crc_ok() == Some(true) => crc_valid += 1,
                    Some(_) => crc_invalid += 1,
                }
                if !fig.sources.contains(&d.src) {
                    fig.sources.push(d.src);
                }
                packets.push(d.payload.clone());
            }
            Err(DecodeError::SensorId { .. }) => fig.id_errors += 1,
            Err(e) => panic!("{what}: packet refused: {e}"),
        }
    }
    fig.packets = packets.len();
    assert_eq!(
        fig.size_errors as u64,
        u64_of(&s["size_error_count"]),
        "{what}: size errors"
    );
    assert_eq!(
        fig.id_errors as u64,
        u64_of(&s["id_error_count"]),
        "{what}: id errors"
    );
    let fw = info.firmware_version();
    fig.crc = format!(
        "{} {}v/{}i/{}z/{}n",
        if dec.crc_check() { "checked" } else { "off" },
        crc_valid,
        crc_invalid,
        crc_zero,
        crc_none
    );
    // The CRC rule against INVENTORY's per-capture findings.
    let has_crc_field = info.format.profile.header()
        == ringscan::sensor::ouster::model::HeaderKind::Standard
        && info.format.profile != Profile::FusaRng15Rfl8Nir8Dual;
    if dec.crc_check() {
        assert!(fw.is_some_and(|v| v >= (2, 5, 0)), "{what}");
        assert_eq!(crc_valid, packets.len(), "{what}: every CRC valid");
    } else if has_crc_field && fw.is_some_and(|v| v < (2, 5, 0)) {
        // FW 2.2: zero footers; FW 2.3 / 2.4: non-zero, not a CRC — and not rejected.
        assert_eq!(crc_valid, 0, "{what}");
    }

    let frames = assemble(&dec, &packets);
    let gframes = s["frames"].as_array().unwrap();
    assert_eq!(frames.len(), gframes.len(), "{what}: frames");
    fig.frames = frames.len();
    for (k, (a, gf)) in frames.iter().zip(gframes).enumerate() {
        check_frame(
            &dec,
            a,
            gf,
            golden_dir,
            &format!("{what} frame {k}"),
            &mut fig,
        );
    }
    fig
}

#[test]
fn ouster_goldens_match_ouster_sdk() {
    let Some(root) = common::captures() else {
        return;
    };
    let mut all = Vec::new();
    let goldens = golden_files(&root);
    assert!(goldens.len() >= 16, "expected the 16 Ouster pcap goldens");
    for gp in &goldens {
        let g = json(gp);
        let capture = root.join(g["capture"].as_str().unwrap());
        let datagrams = read_capture(&capture);
        let n = g["sensors"].as_array().unwrap().len();
        for si in 0..n {
            all.push(check_sensor(
                &root,
                &g,
                si,
                &datagrams,
                gp.parent().unwrap(),
                None,
            ));
        }
    }
    println!(
        "\n{:<52} {:>1} {:<27} {:>4} {:>3} {:>3} {:>3} {:>6} {:>8} {:>6} {:>9} {:>3} {:<22} {:<10} sources",
        "capture", "s", "profile", "pkts", "sz", "id", "frm", "cols", "points", "pts2", "max|Δxyz|", "mis", "crc (valid/invalid/zero/none)", "imu"
    );
    for f in &all {
        println!(
            "{:<52} {:>1} {:<27} {:>4} {:>3} {:>3} {:>3} {:>6} {:>8} {:>6} {:>6.4} mm {:>3} {:<22} {:<10} {}",
            f.capture,
            f.sensor,
            f.profile,
            f.packets,
            f.size_errors,
            f.id_errors,
            f.frames,
            f.columns_compared,
            f.points_compared[0],
            f.points_compared[1],
            f.max_dxyz_mm,
            f.mismatches,
            f.crc,
            f.imu,
            f.sources.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(",")
        );
    }
    let total: usize = all
        .iter()
        .map(|f| f.points_compared[0] + f.points_compared[1])
        .sum();
    let max = all.iter().map(|f| f.max_dxyz_mm).fold(0.0, f64::max);
    println!("total: {total} points compared, max |Δxyz| {max:.4} mm");
    let bad: Vec<_> = all.iter().filter(|f| f.mismatches > 0).collect();
    assert!(bad.is_empty(), "mismatches: {bad:#?}");
}

#[test]
fn ouster_bag_golden_matches_ouster_sdk() {
    use ringscan::source::bag::{BagOptions, BagSource};
    let Some(root) = common::captures() else {
        return;
    };
    let idx = json(&root.join("golden/index.json"));
    let g = idx["goldens"]
        .as_array()
        .unwrap()
        .iter()
        .find(|g| g["capture"].as_str().is_some_and(|c| c.ends_with(".bag")))
        .expect("the golden of the ROS 1 bag");
    let gp = root.join("golden").join(g["golden"].as_str().unwrap());
    let g = json(&gp);
    let bag = root.join(g["capture"].as_str().unwrap());
    let mut src = BagSource::open(&bag, BagOptions::default()).unwrap();
    let metadata = src.sensors()[0]
        .metadata
        .clone()
        .expect("metadata in the bag");
    let mut datagrams = Vec::new();
    while let Some(d) = src.next_datagram().unwrap() {
        datagrams.push(Dgram {
            src: d.src,
            port: d.dst.port(),
            payload: d.payload.to_vec(),
        });
    }
    let fig = check_sensor(
        &root,
        &g,
        0,
        &datagrams,
        gp.parent().unwrap(),
        Some(&metadata),
    );
    println!("{fig:?}");
    assert_eq!(fig.frames, 1);
    assert_eq!(fig.packets, 32);
    assert_eq!(fig.points_compared[0], 28_751);
    assert_eq!(fig.mismatches, 0, "{fig:?}");
}
