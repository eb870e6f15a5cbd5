//! `ringscan decode` on every Ouster capture in `../shared/captures`, with its metadata: the
//! sensors found, their points and sweeps, against ouster-sdk's goldens (per-point fidelity is
//! `tests/ouster_golden.rs`; this checks the whole path: pcap, reassembly, sensor matching,
//! frame assembly, MCAP).

mod common;

use std::process::Command;

use serde_json::Value;

#[test]
fn every_ouster_capture_decodes_to_the_goldens_points_and_frames() {
    let Some(root) = common::captures() else {
        return;
    };
    let idx: Value =
        serde_json::from_slice(&std::fs::read(root.join("golden/index.json")).unwrap()).unwrap();
    let out_dir = std::env::temp_dir().join(format!("ringscan-ouster-cli-{}", std::process::id()));
    std::fs::create_dir_all(&out_dir).unwrap();
    let mut checked = 0;
    println!("| capture | sensors | sweeps | points (ringscan = ouster-sdk) |");
    println!("|---|---|---|---|");
    for g in idx["goldens"].as_array().unwrap() {
        if g["reference"] != "ouster-sdk" || !g["capture"].as_str().unwrap().ends_with(".pcap") {
            continue;
        }
        let golden: Value = serde_json::from_slice(
            &std::fs::read(root.join("golden").join(g["golden"].as_str().unwrap())).unwrap(),
        )
        .unwrap();
        let capture = root.join(golden["capture"].as_str().unwrap());
        let sensors = golden["sensors"].as_array().unwrap();
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_ringscan"));
        let out = out_dir.join(format!("{checked}.mcap"));
        cmd.arg("decode")
            .arg(&capture)
            .arg("--json")
            .arg("--out")
            .arg(&out);
        for s in sensors {
            cmd.arg("--calib")
                .arg(root.join(s["metadata"].as_str().unwrap()));
        }
        let o = cmd.output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        let name = capture.file_name().unwrap().to_string_lossy().to_string();
        let no_packet = sensors
            .iter()
            .all(|s| s["frames"].as_array().is_none_or(|f| f.is_empty()));
        if no_packet {
            // ouster-sdk read no packet (an empty capture): no sensor, so decode fails and
            // writes nothing.
            assert_eq!(o.status.code(), Some(1), "{name}: {stderr}");
            assert!(
                stderr.contains("no sensor found: no datagram was read"),
                "{name}: {stderr}"
            );
            assert!(!out.exists(), "{name}: an output was written");
            println!("| {name} | {} | 0 | 0 (no sensor: exit 1) |", sensors.len());
            checked += 1;
            continue;
        }
        assert!(o.status.success(), "{}: {stderr}", capture.display());
        let j: Value = serde_json::from_slice(&o.stdout).unwrap();
        let mut want_points = 0u64;
        let mut want_sweeps = 0u64;
        for s in sensors {
            let sn = s["sn"]
                .as_str()
                .and_then(|v| v.parse::<u64>().ok())
                .unwrap_or(0);
            let frames = s["frames"].as_array().unwrap();
            let points: u64 = frames
                .iter()
                .filter(|f| f["lidar_data"] != false)
                .flat_map(|f| f["returns"].as_array().cloned().unwrap_or_default())
                .map(|r| r["points"].as_u64().unwrap())
                .sum();
            let lidar_frames = frames.iter().filter(|f| f["lidar_data"] != false).count() as u64;
            want_points += points;
            want_sweeps += lidar_frames;
            if frames.is_empty() {
                // No packet at all (empty capture): no sensor to report.
                continue;
            }
            // The sensor with that serial (or the only one) reports the same numbers.
            let ours = j["sensors"]
                .as_array()
                .unwrap()
                .iter()
                .find(|x| sn == 0 || x["serial"].as_u64() == Some(sn))
                .unwrap_or_else(|| panic!("{name}: sensor {sn} not found in {j}"));
            assert_eq!(
                ours["points"].as_u64(),
                Some(points),
                "{name} sensor {sn}: points"
            );
            assert_eq!(
                ours["sweeps"].as_u64(),
                Some(lidar_frames),
                "{name} sensor {sn}: sweeps"
            );
            // With its own metadata, the rate the column timestamps give is the metadata's.
            assert_eq!(
                ours["warnings"],
                serde_json::json!([]),
                "{name} sensor {sn}"
            );
        }
        assert_eq!(j["points"].as_u64(), Some(want_points), "{name}");
        assert_eq!(j["sweeps"].as_u64(), Some(want_sweeps), "{name}");
        // The MCAP holds one points message per sweep.
        let bytes = std::fs::read(&out).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let stats = summary.stats.unwrap();
        let topics = &j["output"]["topics"];
        let total: u64 = topics
            .as_object()
            .unwrap()
            .values()
            .map(|v| v.as_u64().unwrap())
            .sum();
        assert_eq!(stats.message_count, total, "{name}");
        println!(
            "| {name} | {} | {want_sweeps} | {want_points} |",
            sensors.len()
        );
        checked += 1;
    }
    assert!(checked >= 12, "only {checked} Ouster captures checked");
    let _ = std::fs::remove_dir_all(&out_dir);
}

#[test]
fn info_names_serial_firmware_profile_mode_window_timestamps_and_packets_per_port() {
    let Some(root) = common::captures() else {
        return;
    };
    let idx: Value =
        serde_json::from_slice(&std::fs::read(root.join("golden/index.json")).unwrap()).unwrap();
    let (mut checked, mut firmware_checked) = (0, 0);
    for g in idx["goldens"].as_array().unwrap() {
        if g["reference"] != "ouster-sdk" || !g["capture"].as_str().unwrap().ends_with(".pcap") {
            continue;
        }
        let golden: Value = serde_json::from_slice(
            &std::fs::read(root.join("golden").join(g["golden"].as_str().unwrap())).unwrap(),
        )
        .unwrap();
        let capture = root.join(golden["capture"].as_str().unwrap());
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_ringscan"));
        cmd.arg("info").arg(&capture).arg("--json");
        for s in golden["sensors"].as_array().unwrap() {
            cmd.arg("--calib")
                .arg(root.join(s["metadata"].as_str().unwrap()));
        }
        let o = cmd.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let j: Value = serde_json::from_slice(&o.stdout).unwrap();
        for s in golden["sensors"].as_array().unwrap() {
            if s["frames"].as_array().is_none_or(|f| f.is_empty()) {
                continue;
            }
            let sn: u64 = s["sn"].as_str().unwrap().parse().unwrap();
            let ours = j["sensors"]
                .as_array()
                .unwrap()
                .iter()
                .find(|x| x["serial"].as_u64() == Some(sn))
                .unwrap();
            let name = capture.file_name().unwrap().to_string_lossy();
            assert_eq!(ours["lidar_mode"], s["lidar_mode"], "{name}");
            assert_eq!(ours["columns_per_frame"], s["columns_per_frame"], "{name}");
            assert_eq!(ours["pixels_per_column"], s["pixels_per_column"], "{name}");
            assert_eq!(ours["column_window"], s["column_window"], "{name}");
            if s["udp_profile_lidar"] != "OFF" {
                assert_eq!(ours["profile"], s["udp_profile_lidar"], "{name}");
            }
            // Empty only where the metadata has no firmware (the reduced OS-1-64 file).
            assert!(ours["firmware"].is_string(), "{name}");
            // `build_rev` is ouster-sdk's `fw_rev`; FW 3.x writes a git hash there, so the
            // firmware shown is the version its `image_rev` names (read by hand from the
            // files: crc_test.json `ousteros-image-dev-bootes-v3.2.0-alpha.1+20240812193256`).
            if s.get("fw_rev").is_some_and(|v| !v.is_null()) {
                assert_eq!(ours["build_rev"], s["fw_rev"], "{name}");
            }
            let want = match name.as_ref() {
                "crc_test.pcap" => Some("v3.2.0-alpha.1"),
                "shot_limiting_test.pcap" => Some("v3.2.0"),
                "OS-1-128_767798045_1024x10_20230712_120049.pcap" => Some("v3.1.0-alpha.1"),
                "OS-0-32-U1_v2.2.0_1024x10.pcap" => Some("v2.2.0-rc.2-17-gbc0879e"),
                "OS-2-128-U1_v2.3.0_1024x10.pcap" => Some("v2.3.0"),
                _ => None,
            };
            if let Some(w) = want {
                assert_eq!(ours["firmware"], w, "{name}");
                firmware_checked += 1;
            }
            assert!(ours["timestamp_mode"].is_string(), "{name}");
            let per_port = ours["packets_per_port"].as_object().unwrap();
            let total: u64 = per_port.values().map(|v| v.as_u64().unwrap()).sum();
            assert_eq!(
                total,
                ours["lidar_packets"].as_u64().unwrap()
                    + ours["imu_packets"].as_u64().unwrap()
                    + ours["zone_packets"].as_u64().unwrap()
                    + ours["malformed"].as_u64().unwrap()
                    + ours["crc_failures"].as_u64().unwrap()
                    + ours["wrong_sensor"].as_u64().unwrap()
                    + ours["late"].as_u64().unwrap(),
                "{name}: {per_port:?}"
            );
            checked += 1;
        }
    }
    assert!(checked >= 15, "{checked}");
    assert!(firmware_checked >= 4, "{firmware_checked}");
}

/// `--crc on` checks every footer: FW 2.3 writes footers that are not CRCs (INVENTORY.md: 64 of
/// 64 invalid), so every packet is a counted drop; `crc_test.pcap` (FW 3.2, 34 valid CRCs) loses
/// none. `auto` leaves FW 2.3 unchecked.
#[test]
fn crc_on_drops_and_counts_packets_whose_footer_is_not_a_crc() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let run = |name: &str, meta: &str, crc: &str| -> Value {
        let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
            .arg("decode")
            .arg(dir.join(name))
            .arg("--calib")
            .arg(dir.join(meta))
            .args(["--crc", crc, "--json"])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let j = run(
        "OS-2-128-U1_v2.3.0_1024x10.pcap",
        "OS-2-128-U1_v2.3.0_1024x10.json",
        "on",
    );
    assert_eq!(j["sensors"][0]["crc_failures"], 64);
    assert_eq!(j["points"], 0);
    let j = run(
        "OS-2-128-U1_v2.3.0_1024x10.pcap",
        "OS-2-128-U1_v2.3.0_1024x10.json",
        "auto",
    );
    assert_eq!(j["sensors"][0]["crc_failures"], 0);
    assert_eq!(j["points"], 119_682);
    let j = run("crc_test.pcap", "crc_test.json", "on");
    assert_eq!(j["sensors"][0]["crc_failures"], 0);
    assert_eq!(j["points"], 29_692);
}

/// The real zone-monitor packet (FW 3.2) into both MCAP formats: one `/zones` message equal to
/// ouster-sdk 1.0.1's reading of it (`fixtures/references/`, made by
/// `tools/ouster_zone_reference.sh`), every zone slot and field.
#[test]
fn zone_monitor_packet_decodes_to_ouster_sdks_zone_states() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let reference: Value = serde_json::from_slice(
        &std::fs::read(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("fixtures/references/ouster-zones-imu_zm_no_lidar.json"),
        )
        .unwrap(),
    )
    .unwrap();
    assert_eq!(reference.as_array().map(Vec::len), Some(1));
    let scratch = common::Scratch::dir("ouster-zones");
    for format in ["foxglove", "ros2"] {
        let out = scratch.join(format!("zones-{format}.mcap"));
        let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
            .arg("decode")
            .arg(dir.join("imu_zm_no_lidar.pcap"))
            .arg("--calib")
            .arg(dir.join("imu_zm_no_lidar_0.json"))
            .args(["--format", format, "--json", "--out"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let j: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(j["zone_reports"], 1, "{format}");
        assert_eq!(j["packets"]["malformed"], 0, "{format}");
        assert_eq!(j["output"]["topics"]["/zones"], 1, "{format}");
        let s = &j["sensors"][0];
        assert_eq!(
            (&s["zone_packets"], &s["crc_failures"]),
            (&1.into(), &0.into())
        );
        assert_eq!(s["ports"], serde_json::json!([7513, 7514]));

        let bytes = std::fs::read(&out).unwrap();
        let mut got = Vec::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            if m.channel.topic != "/zones" {
                continue;
            }
            let schema = m.channel.schema.as_ref().unwrap();
            let text = match format {
                "foxglove" => {
                    assert_eq!(
                        (schema.name.as_str(), schema.encoding.as_str()),
                        ("ringscan.ZoneStates", "jsonschema")
                    );
                    assert_eq!(m.channel.message_encoding, "json");
                    String::from_utf8(m.data.to_vec()).unwrap()
                }
                _ => {
                    assert_eq!(schema.name, "std_msgs/msg/String");
                    assert_eq!(m.channel.message_encoding, "cdr");
                    // CDR: 4-byte encapsulation header, u32 length (with the NUL), text, NUL.
                    let n = u32::from_le_bytes(m.data[4..8].try_into().unwrap()) as usize;
                    String::from_utf8(m.data[8..8 + n - 1].to_vec()).unwrap()
                }
            };
            got.push(serde_json::from_str::<Value>(&text).unwrap());
        }
        assert_eq!(Value::Array(got), reference, "{format}");
    }
}

/// Two sensors on one port (`same_ports*.pcap`); in `same_ports.pcap` both send an IMU packet
/// before their first lidar packet, in `same_ports_nonlegacy.pcap` one does. A legacy IMU
/// packet names no sensor, so it can only be decoded once its address's lidar packet has
/// matched a metadata file. Every 48-byte datagram (the legacy IMU packet's size, on the
/// metadata's `udp_port_imu`), counted here from the pcap per source address, must be one IMU
/// packet of that address's sensor, and `--raw` must keep every datagram; before the
/// demultiplexer held them, the early ones were ignored.
#[test]
fn imu_packets_before_the_first_lidar_packet_are_decoded() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    for name in ["same_ports", "same_ports_nonlegacy"] {
        let pcap = dir.join(format!("{name}.pcap"));
        // Per source address: 48-byte datagrams, and those of them before its first lidar
        // packet.
        let mut want: std::collections::BTreeMap<String, u64> = Default::default();
        let mut early = 0u64;
        let mut started = std::collections::BTreeSet::new();
        let mut src = ringscan::source::pcap::PcapSource::open(&pcap).unwrap();
        while let Some(d) = src.next_datagram().unwrap() {
            let addr = d.src.ip().to_string();
            let imu = d.payload.len() == 48 && d.dst.port() == 7502;
            if imu && !started.contains(&addr) {
                early += 1;
            }
            if !imu {
                started.insert(addr.clone());
            }
            *want.entry(addr).or_default() += u64::from(imu);
        }
        assert!(early > 0, "{name}: a sensor starts with an IMU packet");
        let scratch = common::Scratch::dir("ouster-early-imu");
        let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
            .arg("decode")
            .arg(&pcap)
            .arg("--json")
            .args(["--raw", "--out"])
            .arg(scratch.join("out.mcap"))
            .arg("--calib")
            .arg(dir.join(format!("{name}.1.json")))
            .arg("--calib")
            .arg(dir.join(format!("{name}.2.json")))
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let j: Value = serde_json::from_slice(&o.stdout).unwrap();
        let sensors = j["sensors"].as_array().unwrap();
        assert_eq!(sensors.len(), 2, "{name}");
        for s in sensors {
            let addr = s["address"].as_str().unwrap();
            assert_eq!(
                s["imu_packets"].as_u64(),
                want.get(addr).copied(),
                "{name}: IMU packets of {addr}"
            );
        }
        assert_eq!(j["imu_samples"], want.values().sum::<u64>(), "{name}");
        assert_eq!(j["packets"]["ignored"], 0, "{name}");
        assert_eq!(j["packets"]["early"], early, "{name}");
        // `--raw` keeps every datagram of both sensors, the early ones too.
        let raw: u64 = j["output"]["topics"]
            .as_object()
            .unwrap()
            .iter()
            .filter(|(t, _)| t.ends_with("/raw"))
            .map(|(_, n)| n.as_u64().unwrap())
            .sum();
        assert_eq!(
            raw,
            common::datagrams(&pcap).len() as u64,
            "{name}: /raw messages"
        );
    }
}

/// `same_ports.pcap` through a port offset (as `replay --port-offset` sends it): the LEGACY
/// sensor's packets carry no serial, so an unbound metadata file can only know them by the
/// metadata's lidar port, and misses them; a file bound to the sender's address
/// (`--calib ADDR=FILE`) takes them on any port. The points per sensor are ouster-sdk's
/// golden counts.
#[test]
fn a_metadata_file_bound_to_an_address_takes_legacy_packets_on_any_port() {
    use ringscan::sensor::{claim, parse_calibration, CalibrationPool, StreamSettings};
    use ringscan::sweep::Demux;
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let golden: Value = serde_json::from_slice(
        &std::fs::read(
            root.join("golden/ouster-lidar__ouster-sdk/tests/pcaps/same_ports.golden.json"),
        )
        .unwrap(),
    )
    .unwrap();
    // The golden's points per serial.
    let want: std::collections::BTreeMap<u64, u64> = golden["sensors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            let n = s["frames"]
                .as_array()
                .unwrap()
                .iter()
                .flat_map(|f| f["returns"].as_array().cloned().unwrap_or_default())
                .map(|r| r["points"].as_u64().unwrap())
                .sum();
            (s["sn"].as_str().unwrap().parse().unwrap(), n)
        })
        .collect();
    assert_eq!(want.len(), 2);
    // Which address sends which metadata's packets (INVENTORY.md).
    let bindings = [
        ("169.254.92.158", "same_ports.1.json"),
        ("169.254.238.111", "same_ports.2.json"),
    ];
    for bound in [false, true] {
        let calibs = bindings
            .iter()
            .map(|(a, f)| {
                let addr = bound.then(|| a.parse().unwrap());
                parse_calibration(&std::fs::read(dir.join(f)).unwrap(), f, addr).unwrap()
            })
            .collect();
        let mut pool = CalibrationPool::new(calibs, StreamSettings::default());
        let mut demux = Demux::new(Box::new(move |d| claim(d, &mut pool)), None);
        let mut points = [0u64; 2];
        let mut src =
            ringscan::source::pcap::PcapSource::open(&dir.join("same_ports.pcap")).unwrap();
        while let Some(d) = src.next_datagram().unwrap() {
            let port = d.dst.port() + 20000;
            demux
                .push(d.time_ns, *d.src.ip(), port, d.payload, &mut |i, s, _| {
                    points[i] += s.points.len() as u64
                })
                .unwrap();
        }
        demux
            .finish(&mut |i, s, _| points[i] += s.points.len() as u64)
            .unwrap();
        let got: std::collections::BTreeMap<u64, u64> = demux
            .sensors()
            .enumerate()
            .map(|(i, (_, s, _))| (s.summary().0["serial"].as_u64().unwrap(), points[i]))
            .collect();
        if bound {
            assert_eq!(got, want, "bound files: both sensors, the golden's points");
        } else {
            let profile_based: Vec<u64> = got.keys().copied().collect();
            assert_eq!(
                profile_based,
                [122247000785],
                "unbound: the LEGACY sensor is not known"
            );
            assert_eq!(got[&122247000785], want[&122247000785]);
        }
    }
}

/// LEGACY packets carry no serial, so another unit's metadata of the same packet size is
/// taken: `OS-2-32-U0_v2.0.0_1024x10.pcap` (INVENTORY.md: 1024x20, its frame spans 49.9 ms)
/// read with `OS-1-32-G_v2.1.1_1024x10.json` (1024x10) was decoded and relabelled without a
/// word. Now its column timestamps tell a 20 Hz sensor, and decode and info warn.
#[test]
fn another_units_metadata_at_another_rate_is_warned_of() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let run = |calib: &str, json: bool| {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_ringscan"));
        cmd.arg("info")
            .arg(dir.join("OS-2-32-U0_v2.0.0_1024x10.pcap"))
            .arg("--calib")
            .arg(dir.join(calib));
        if json {
            cmd.arg("--json");
        }
        let o = cmd.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8(o.stdout).unwrap()
    };
    let j: Value = serde_json::from_str(&run("OS-1-32-G_v2.1.1_1024x10.json", true)).unwrap();
    let s = &j["sensors"][0];
    assert_eq!(s["lidar_mode"], "1024x10", "{s}");
    // 1024 columns in 49.9 ms: 20.0 Hz.
    let fps = s["measured_fps"].as_f64().unwrap();
    assert!((fps - 1000.0 / 49.9).abs() < 0.2, "{fps}");
    let w = s["warnings"][0]
        .as_str()
        .unwrap_or_else(|| panic!("no warning: {s}"));
    assert!(
        w.contains("give 20.0 frames/s") && w.contains("1024x10 says 10"),
        "{w}"
    );
    let text = run("OS-1-32-G_v2.1.1_1024x10.json", false);
    assert!(
        text.contains(&format!(
            "  warning: sensor os-1-32-g-992101000280 (127.0.0.1): {w}"
        )),
        "{text}"
    );
    // Its own metadata (1024x20): no warning.
    let j: Value = serde_json::from_str(&run("OS-2-32-U0_v2.0.0_1024x10.json", true)).unwrap();
    assert_eq!(j["sensors"][0]["lidar_mode"], "1024x20");
    assert_eq!(j["sensors"][0]["warnings"], serde_json::json!([]));
}

/// A reduced (legacy `sensor_config`) metadata file has no model, serial or firmware: `info`
/// says so instead of printing gaps and a serial 0 (`ports [7502,7503]:  sn 0  LEGACY 1024x10`).
#[test]
fn a_reduced_metadata_file_is_described_without_gaps() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
        .arg("info")
        .arg(dir.join("OS-1-64_1024x10_fw20.pcap"))
        .arg("--calib")
        .arg(dir.join("OS-1-64_sensor_config_reduced.json"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).unwrap();
    let line = text
        .lines()
        .find(|l| l.starts_with("  sensor "))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(
        line.ends_with(
            "ports [7502,7503]: Ouster (model and serial not in the metadata) LEGACY 1024x10, \
             window [0, 1023]"
        ),
        "{line}"
    );
}

/// A bag's own metadata (an Ouster driver's metadata topic) is the input's, as its attached
/// files are: not warned of as "used by no sensor" when the file attached beside it served
/// instead (a `--raw --format ros2` bag ringscan wrote carries both), nor when `--topic`
/// leaves only IMU packets.
#[test]
fn a_bags_own_metadata_is_not_an_unused_calibration() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests");
    let scratch = std::env::temp_dir().join(format!("ringscan-own-meta-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&scratch);
    std::fs::create_dir_all(&scratch).unwrap();
    let bag = scratch.join("raw");
    let run = |args: &[&std::ffi::OsStr]| {
        let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
            .args(args)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8(o.stdout).unwrap()
    };
    let written: Value = serde_json::from_str(&run(&[
        "decode".as_ref(),
        "--json".as_ref(),
        dir.join("pcaps/OS-1-32-G_v2.1.1_1024x10.pcap").as_os_str(),
        "--calib".as_ref(),
        dir.join("pcaps/OS-1-32-G_v2.1.1_1024x10.json").as_os_str(),
        "--raw".as_ref(),
        "--format".as_ref(),
        "ros2".as_ref(),
        "--out".as_ref(),
        bag.as_os_str(),
    ]))
    .unwrap();
    // The bag decodes to the capture's points, with its own metadata.
    let again: Value = serde_json::from_str(&run(&[
        "decode".as_ref(),
        bag.as_os_str(),
        "--json".as_ref(),
    ]))
    .unwrap();
    assert_eq!(again["points"], written["points"]);
    assert!(again["points"].as_u64() > Some(0));
    let ros1 = dir.join("bags/512x10_raw.bag");
    for args in [
        vec!["info".as_ref(), bag.as_os_str(), "--json".as_ref()],
        vec![
            "info".as_ref(),
            ros1.as_os_str(),
            "--topic".as_ref(),
            "/os_node0/imu_packets".as_ref(),
            "--json".as_ref(),
        ],
    ] {
        let j: Value = serde_json::from_str(&run(&args)).unwrap();
        assert_eq!(
            j["unused_calibrations"],
            serde_json::json!([]),
            "{args:?}: {j}"
        );
    }
    // Its IMU packets alone start no sensor: the reason says the bag's metadata was read (it
    // said Ouster packets need their metadata, as if the bag had none).
    let j: Value = serde_json::from_str(&run(&[
        "info".as_ref(),
        ros1.as_os_str(),
        "--topic".as_ref(),
        "/os_node0/imu_packets".as_ref(),
        "--json".as_ref(),
    ]))
    .unwrap();
    assert!(
        j["no_sensor"].as_str().is_some_and(|w| w.contains(
            "the input's own calibration (os_node0.metadata.json) was read, but none of its \
             sensor's lidar packets came (an Ouster sensor starts on them: does --topic select \
             only its IMU packets?)"
        )),
        "{j}"
    );
    let _ = std::fs::remove_dir_all(&scratch);
}

/// `--port` selects the packets of sensors told by their data port (Velodyne, Hesai,
/// Robosense, Livox); an Ouster sensor is told by its metadata, so the flag did nothing on an
/// Ouster capture, without a word. Now it is an unused option, warned of.
#[test]
fn port_on_an_ouster_capture_is_warned_of() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
        .arg("decode")
        .arg(dir.join("OS-2-128-U1_v2.3.0_1024x10.pcap"))
        .arg("--calib")
        .arg(dir.join("OS-2-128-U1_v2.3.0_1024x10.json"))
        .args(["--port", "9999"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        text.contains("warning: --port 9999 selects nothing on Ouster sensors: they are told by their calibration"),
        "{text}"
    );
}

/// `--cut-angle` on a run of only Ouster sensors is warned of: their sweeps are their frames,
/// so it cut nothing, silently (second audit); the frames are the same with it and without.
#[test]
fn cut_angle_on_an_ouster_capture_is_warned_of() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let run = |extra: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
            .arg("decode")
            .arg(dir.join("OS-2-128-U1_v2.3.0_1024x10.pcap"))
            .arg("--calib")
            .arg(dir.join("OS-2-128-U1_v2.3.0_1024x10.json"))
            .arg("--json")
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    let cut = run(&["--cut-angle", "90"]);
    let plain = run(&[]);
    assert_eq!(
        cut["unused_options"][0]
            .as_str()
            .unwrap_or_default()
            .split(" (")
            .next(),
        Some("--cut-angle applies to Velodyne, Hesai, Robosense sensors only, and none was found"),
        "{cut}"
    );
    assert_eq!(plain["unused_options"], serde_json::json!([]));
    for k in ["sweeps", "points"] {
        assert_eq!(cut[k], plain[k], "{k}");
    }
}

/// A capture read with another unit's metadata whose packets it cannot read finds no sensor,
/// and the reason names the file given (it said Ouster packets need their metadata, as if
/// none had been given; second audit).
#[test]
fn metadata_that_fits_no_packet_is_named() {
    let Some(root) = common::captures() else {
        return;
    };
    let dir = root.join("ouster-lidar__ouster-sdk/tests/pcaps");
    let o = Command::new(env!("CARGO_BIN_EXE_ringscan"))
        .arg("decode")
        .arg(dir.join("OS-2-128-U1_v2.3.0_1024x10.pcap"))
        .arg("--calib")
        .arg(dir.join("OS-0-128_v3.0.1_1024x10.json"))
        .arg("--json")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let why = j["no_sensor"].as_str().unwrap_or_default();
    assert!(
        why.contains("; OS-0-128_v3.0.1_1024x10.json was given, but no packet fits it"),
        "{j}"
    );
}
