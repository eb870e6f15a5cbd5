//! Ouster metadata parser (`calib::ouster`) against every metadata file of ouster-sdk's test
//! data in `../shared/captures` (skipped with `SKIP:` when absent), against the values
//! ouster-sdk 1.0.1 parsed from them (`as_parsed_by_sdk` in the goldens), and against hand-made
//! and hostile JSON.

use std::path::{Path, PathBuf};

use ringscan::sensor::calib::CalibError;
use ringscan::sensor::calib::MAX_CALIB_BYTES;
use ringscan::sensor::ouster::calib as ouster;
use ringscan::sensor::ouster::calib::default_pixel_shift_by_row;
use ringscan::sensor::ouster::calib::parse;
use ringscan::sensor::ouster::calib::parse_firmware_version;
use ringscan::sensor::ouster::calib::prod_line_beam_count;
use ringscan::sensor::ouster::calib::ImuProfile;
use ringscan::sensor::ouster::calib::OusterInfo;
use ringscan::sensor::ouster::calib::TimestampMode;
use ringscan::sensor::ouster::calib::DEFAULT_IMU_TO_SENSOR;
use ringscan::sensor::ouster::calib::DEFAULT_LIDAR_TO_SENSOR;
use ringscan::sensor::ouster::calib::DEFAULT_UDP_PORT_IMU;
use ringscan::sensor::ouster::calib::DEFAULT_UDP_PORT_LIDAR;
use ringscan::sensor::ouster::calib::LAYOUT_LEGACY;
use ringscan::sensor::ouster::calib::LAYOUT_NESTED;
use ringscan::sensor::ouster::calib::LAYOUT_NESTED_1_12;
use ringscan::sensor::ouster::model::Profile;
use serde_json::{json, Value};

const SDK_TESTS: &str = "ouster-lidar__ouster-sdk/tests";

fn captures() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/captures");
    if dir.is_dir() {
        Some(dir)
    } else {
        println!("SKIP: {} not found", dir.display());
        None
    }
}

// ---------------------------------------------------------------------------------------------
// The outcome table: every file under tests/metadata/ (incl. malformed/) and every *.json under
// tests/pcaps/ of ouster-sdk.

#[derive(Clone, Copy, Debug)]
enum Expect {
    Accepted,
    /// Rejected; the message contains this text (naming the key at fault).
    Rejected(&'static str),
}
use Expect::{Accepted, Rejected};

struct Row {
    /// Path under `ouster-lidar__ouster-sdk/tests/`.
    file: &'static str,
    /// ringscan's outcome.
    expect: Expect,
    /// Whether ouster-sdk 1.0.1's `SensorInfo` accepts the file (INVENTORY.md, checked with
    /// ouster-sdk 1.0.1 for the `pcaps/` files).
    sdk_accepts: bool,
    /// Why; starts with "DIFFERS FROM SDK:" where ringscan decides otherwise.
    reason: &'static str,
}

const fn row(file: &'static str, expect: Expect, sdk_accepts: bool, reason: &'static str) -> Row {
    Row {
        file,
        expect,
        sdk_accepts,
        reason,
    }
}

const TABLE: &[Row] = &[
    // --- tests/metadata/
    row("metadata/1_12_os1-991913000010-64.json", Accepted, true,
        "FW 1.12 nested: lidar_data_format is the sensor's error string; W, H, shifts from lidar_mode and prod_line"),
    row("metadata/1_12_os1-991937000062-16A0_legacy.json", Rejected("beam_altitude_angles"), false,
        "OS-1-16 with 64 angles (zeros for absent beams); H = 16 from prod_line; which 16 rows the packets carry is not written"),
    row("metadata/1_12_os1-991937000062-64_legacy.json", Accepted, true,
        "FW 1.12 flat without data_format: the SDK's default data format for 1024x10"),
    row("metadata/1_13_os1-991913000010-64.json", Accepted, true,
        "FW 1.13 nested, lidar_data_format a string"),
    row("metadata/1_13_os1-991937000062-16A0_legacy.json", Rejected("beam_altitude_angles"), false,
        "OS-1-16 with 64 angles, as the FW 1.12 file"),
    row("metadata/1_13_os1-991937000062-32A02_legacy.json", Rejected("expected 32 entries, found 64"), false,
        "OS-1-32 with 64 angles (zeros for absent beams)"),
    row("metadata/1_14_6cccd_os-882002000138-128_legacy.json", Accepted, true,
        "FW 1.14 OS-0-128 flat with data_format, no ports (defaults 7502/7503)"),
    row("metadata/1_14_6cccd_os-882002000138-32U0_legacy.json", Accepted, true,
        "FW 1.14 OS-0-32 flat, 32 angles"),
    row("metadata/1_14_beta_os1-991937000062-16A0_legacy.json", Accepted, true,
        "FW 1.14 lists 16 angles for the OS-1-16"),
    row("metadata/1_14_beta_os1-991937000062-64_legacy.json", Accepted, true,
        "FW 1.14 OS-1-64 flat"),
    row("metadata/2_0_0_os1-991913000010-64.json", Accepted, true,
        "FW 2.0 nested; the file's own beam-origin offset 12.163 mm on an OS-1 wins over the product-line default"),
    row("metadata/2_0_0_os1-992008000494-128_col_win_legacy.json", Accepted, true,
        "2048x10 with column window [2014, 2036]"),
    row("metadata/2_0_rc2_os-992011000121-32U0_legacy.json", Accepted, true,
        "512x10 flat"),
    row("metadata/2_1_2_os1-991913000010-64.json", Accepted, true,
        "udp_dest is empty: the lidar stream is OFF, as the SDK says"),
    row("metadata/2_1_2_os1-991913000010-64_legacy.json", Accepted, true,
        "flat twin of the above; flat files carry no udp_dest, so the stream is on"),
    row("metadata/2_2_os-992119000444-128.json", Accepted, true,
        "FW 2.2 nested, profile LEGACY named"),
    row("metadata/2_2_os-992119000444-128_legacy.json", Accepted, true,
        "FW 2.2 flat"),
    row("metadata/2_3_1_os-992146000760-128.json", Accepted, true,
        "RNG15_RFL8_NIR8 (low data rate)"),
    row("metadata/2_3_1_os-992146000760-128_legacy.json", Accepted, true,
        "RNG15_RFL8_NIR8, flat"),
    row("metadata/2_4_0_os-992146000760-128.json", Accepted, true,
        "RNG19_RFL8_SIG16_NIR16, timestamp mode sync pulse"),
    row("metadata/2_4_0_os-992146000760-128_legacy.json", Accepted, true,
        "RNG19_RFL8_SIG16_NIR16, flat"),
    row("metadata/2_5_0_os-992146000760-128.json", Accepted, true,
        "column window [912, 1022]; FW 2.5: CRC in the footer"),
    row("metadata/2_5_0_os-992146000760-128_legacy.json", Accepted, true,
        "column window [912, 1022], flat"),
    row("metadata/3_0_1_os-122246000293-128.json", Accepted, true,
        "RNG19_RFL8_SIG16_NIR16_DUAL, beam origin 16.721 mm"),
    row("metadata/3_0_1_os-122246000293-128_legacy.json", Accepted, true,
        "dual profile, flat"),
    row("metadata/ouster-studio-reduced-config-v1.json", Accepted, true,
        "only beam angles and 2048x10: gen-1 beam origin 12.163 mm, shifts 36/24/12/0, H = 64"),
    // --- tests/metadata/malformed/
    row("metadata/malformed/complete_but_all_zeros_legacy.json", Rejected("beam_altitude_angles"), true,
        "DIFFERS FROM SDK: all 128 altitudes (and azimuths) are 0, an unwritten calibration that puts every beam at one elevation; the SDK only warns"),
    row("metadata/malformed/garbled_legacy_and_nonlegacy.json", Rejected("config_params"), false,
        "flat keys mixed with some nested sections"),
    row("metadata/malformed/incomplete_data_format_legacy.json", Accepted, true,
        "data_format lacks columns_per_frame: taken from lidar_mode"),
    row("metadata/malformed/incomplete_data_format_nonlegacy.json", Accepted, true,
        "lidar_data_format lacks pixels_per_column: 128 from prod_line OS-1-128"),
    row("metadata/malformed/incomplete_no_calref_nonlegacy.json", Rejected("calibration_status"), false,
        "nested, one of the seven sections missing"),
    row("metadata/malformed/incomplete_no_sensor_info_nonlegacy.json", Rejected("sensor_info"), false,
        "nested without sensor_info"),
    row("metadata/malformed/incorrect_nbeam_angles_legacy_113.json", Rejected("beam_altitude_angles"), false,
        "63 altitude angles for an OS-1-16"),
    row("metadata/malformed/legacy_with_calibration_status.json", Rejected("beam_intrinsics"), false,
        "flat file with one nested section (calibration_status)"),
    // --- tests/pcaps/*.json
    row("pcaps/OS-0-128_v3.0.1_1024x10.2.json", Accepted, true,
        "OS-0-128 FW 3.0.1 dual (no capture here)"),
    row("pcaps/OS-0-128_v3.0.1_1024x10.json", Accepted, true,
        "OS-0-128 FW 3.0.1 dual"),
    row("pcaps/OS-0-128_v3.0.1_1024x10_20240321_125947.2.json", Accepted, true,
        "OS-0-128 FW 3.0.1 dual"),
    row("pcaps/OS-0-128_v3.0.1_1024x10_20240321_125947.json", Accepted, true,
        "OS-0-128 FW 3.0.1 dual"),
    row("pcaps/OS-0-32-U1_v2.2.0_1024x10.json", Accepted, true,
        "flat, RNG19 dual, 32 beams (golden)"),
    row("pcaps/OS-0-32-U1_v2.2.0_1024x10_digest.json", Rejected("columns_per_frame"), false,
        "the SDK's MD5 digests of decoded fields, not metadata"),
    row("pcaps/OS-1-128_767798045_1024x10_20230712_120049.json", Accepted, true,
        "FUSA_RNG15_RFL8_NIR8_DUAL, FUSA header (golden)"),
    row("pcaps/OS-1-128_v2.3.0_1024x10.json", Accepted, true,
        "flat, low data rate (golden of the _lb_n3 capture)"),
    row("pcaps/OS-1-32-G_v2.1.1_1024x10.json", Accepted, true,
        "flat LEGACY, no ports in the file (golden)"),
    row("pcaps/OS-1-32-G_v2.1.1_1024x10_digest.json", Rejected("columns_per_frame"), false,
        "digests, not metadata"),
    row("pcaps/OS-1-64_sensor_config_reduced.json", Accepted, true,
        "only beam angles and lidar_mode: every SDK default (golden)"),
    row("pcaps/OS-2-128-U1_v2.3.0_1024x10.json", Accepted, true,
        "flat, OS-2, lidar_to_sensor z 78.296 mm (golden)"),
    row("pcaps/OS-2-128-U1_v2.3.0_1024x10_digest.json", Rejected("columns_per_frame"), false,
        "digests, not metadata"),
    row("pcaps/OS-2-32-U0_v2.0.0_1024x10.json", Accepted, true,
        "1024x20 although the name says 1024x10 (golden)"),
    row("pcaps/OS-2-32-U0_v2.0.0_1024x10_digest.json", Rejected("columns_per_frame"), false,
        "digests, not metadata"),
    row("pcaps/crc_test.json", Accepted, true,
        "512x10, FW 3.2 (CRC), build_rev a git hash: version from image_rev (golden)"),
    row("pcaps/duplicate_id.json", Accepted, true,
        "ports 34636/48887, PTP (golden)"),
    row("pcaps/empty_pcap.json", Accepted, true,
        "512x10 dual (golden with no frames)"),
    row("pcaps/imu_zm_no_lidar_0.json", Accepted, true,
        "udp_port_lidar 0: lidar OFF, so its ZONE16 profile need not be decodable; ACCEL32_GYRO32_NMEA IMU (golden)"),
    row("pcaps/same_ports.1.json", Accepted, true,
        "FUSA, lidar and IMU both on 7502 (golden)"),
    row("pcaps/same_ports.2.json", Accepted, true,
        "LEGACY, window [912, 1022] (golden)"),
    row("pcaps/same_ports.2.non_colliding_imu.json", Accepted, true,
        "as above with IMU port 7503"),
    row("pcaps/same_ports_nonlegacy.1.json", Accepted, true,
        "FUSA (golden)"),
    row("pcaps/same_ports_nonlegacy.2.json", Accepted, true,
        "RNG19 dual FW 2.5.2 (golden)"),
    row("pcaps/same_ports_nonlegacy.2.non_colliding_imu.json", Accepted, true,
        "as above with IMU port 7503"),
    row("pcaps/shot_limiting_test.json", Accepted, true,
        "1024x20, port 7702, ACCEL32_GYRO32_NMEA, header_type STANDARD (golden)"),
    row("pcaps/windowed_frame1_0.json", Accepted, true,
        "512x10, window [1, 256] (golden)"),
];

/// Every file the table must cover: all files under metadata/ and the *.json under pcaps/.
fn files_to_cover(tests: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![tests.join("metadata")];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(rel(tests, &p));
            }
        }
    }
    if let Ok(entries) = std::fs::read_dir(tests.join("pcaps")) {
        for e in entries.flatten() {
            let p = e.path();
            if p.extension().is_some_and(|x| x == "json") {
                out.push(rel(tests, &p));
            }
        }
    }
    out.sort();
    out
}

fn rel(base: &Path, p: &Path) -> String {
    p.strip_prefix(base)
        .unwrap_or(p)
        .to_string_lossy()
        .replace('\\', "/")
}

#[test]
fn every_sdk_metadata_file_has_a_row_and_the_expected_outcome() {
    let Some(dir) = captures() else { return };
    let tests = dir.join(SDK_TESTS);

    // The table covers the directory exactly.
    let files = files_to_cover(&tests);
    assert!(!files.is_empty(), "no files under {}", tests.display());
    let missing: Vec<&String> = files
        .iter()
        .filter(|f| !TABLE.iter().any(|r| r.file == f.as_str()))
        .collect();
    assert!(
        missing.is_empty(),
        "files without a row in TABLE: {missing:?}"
    );
    let stale: Vec<&str> = TABLE
        .iter()
        .map(|r| r.file)
        .filter(|f| !files.iter().any(|x| x == f))
        .collect();
    assert!(stale.is_empty(), "rows whose file is gone: {stale:?}");
    for (i, r) in TABLE.iter().enumerate() {
        assert!(
            !TABLE[..i].iter().any(|o| o.file == r.file),
            "duplicate row {}",
            r.file
        );
    }

    let (mut accepted, mut rejected, mut differ) = (0, 0, 0);
    for r in TABLE {
        let agrees = matches!(r.expect, Accepted) == r.sdk_accepts;
        assert_eq!(
            !agrees,
            r.reason.starts_with("DIFFERS FROM SDK:"),
            "{}: a row that departs from SDK 1.0.1 (and only such a row) says why, starting \
             with \"DIFFERS FROM SDK:\"",
            r.file
        );
        differ += usize::from(!agrees);
        let text = std::fs::read_to_string(tests.join(r.file))
            .unwrap_or_else(|e| panic!("{}: {e}", r.file));
        match (parse(&text, r.file), r.expect) {
            (Ok(info), Accepted) => {
                accepted += 1;
                assert_eq!(info.source, r.file);
                check_invariants(&info, r.file);
            }
            (Err(e), Rejected(needle)) => {
                rejected += 1;
                let msg = e.to_string();
                assert!(
                    msg.contains(needle),
                    "{}: rejected as expected, but the message lacks {needle:?}: {msg}",
                    r.file
                );
            }
            (Ok(_), Rejected(needle)) => {
                panic!(
                    "{}: accepted, expected a rejection naming {needle:?} ({})",
                    r.file, r.reason
                )
            }
            (Err(e), Accepted) => panic!(
                "{}: rejected ({e}), expected accepted ({})",
                r.file, r.reason
            ),
        }
    }
    println!(
        "ouster metadata table: {} files, {accepted} accepted, {rejected} rejected, {differ} \
         decided differently from ouster-sdk 1.0.1",
        TABLE.len()
    );
}

/// What every accepted calibration satisfies.
fn check_invariants(info: &OusterInfo, name: &str) {
    let w = info.columns_per_frame;
    let h = info.format.pixels_per_column;
    assert!([512, 1024, 2048, 4096].contains(&w), "{name}: W {w}");
    assert!([16, 32, 64, 128].contains(&h), "{name}: H {h}");
    assert_eq!(info.beam_altitude_angles.len(), h, "{name}");
    assert_eq!(info.beam_azimuth_angles.len(), h, "{name}");
    assert_eq!(info.pixel_shift_by_row.len(), h, "{name}");
    assert!(info
        .pixel_shift_by_row
        .iter()
        .all(|s| s.unsigned_abs() < w as u32));
    assert!(
        info.column_window.0 < w && info.column_window.1 < w,
        "{name}"
    );
    assert_eq!(w % info.format.columns_per_packet, 0, "{name}");
    let in_window = (0..w).filter(|&c| info.is_column_in_window(c)).count();
    assert_eq!(in_window, info.columns_in_window(), "{name}");
    if !info.lidar_off {
        // Brute force: the packets that hold a window column.
        let cpp = info.format.columns_per_packet;
        let packets = (0..w / cpp)
            .filter(|p| (p * cpp..(p + 1) * cpp).any(|c| info.is_column_in_window(c)))
            .count();
        assert_eq!(packets, info.expected_packets_per_frame(), "{name}");
        assert_eq!(
            info.lidar_packet_bytes(),
            info.format.packet_bytes(),
            "{name}"
        );
    } else {
        assert_eq!(info.expected_packets_per_frame(), 0, "{name}");
    }
}

#[test]
fn layouts_firmware_and_lidar_off_of_real_files() {
    let Some(dir) = captures() else { return };
    let tests = dir.join(SDK_TESTS);
    let load = |f: &str| {
        let text = std::fs::read_to_string(tests.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        parse(&text, f).unwrap_or_else(|e| panic!("{f}: {e}"))
    };
    /// File, layout, firmware version, lidar off, CRC in lidar packets.
    type Case = (
        &'static str,
        &'static str,
        Option<(u32, u32, u32)>,
        bool,
        bool,
    );
    let cases: &[Case] = &[
        (
            "metadata/1_12_os1-991913000010-64.json",
            LAYOUT_NESTED_1_12,
            Some((1, 12, 0)),
            false,
            false,
        ),
        (
            "metadata/1_13_os1-991913000010-64.json",
            LAYOUT_NESTED_1_12,
            Some((1, 13, 0)),
            false,
            false,
        ),
        (
            "metadata/1_12_os1-991937000062-64_legacy.json",
            LAYOUT_LEGACY,
            Some((1, 12, 0)),
            false,
            false,
        ),
        (
            "metadata/2_1_2_os1-991913000010-64.json",
            LAYOUT_NESTED,
            Some((2, 1, 2)),
            true,
            false,
        ),
        (
            "metadata/2_5_0_os-992146000760-128.json",
            LAYOUT_NESTED,
            Some((2, 5, 0)),
            false,
            true,
        ),
        (
            "pcaps/OS-1-64_sensor_config_reduced.json",
            LAYOUT_LEGACY,
            None,
            false,
            false,
        ),
        (
            "pcaps/OS-1-128_v2.3.0_1024x10.json",
            LAYOUT_LEGACY,
            Some((2, 3, 0)),
            false,
            false,
        ),
        (
            "pcaps/crc_test.json",
            LAYOUT_NESTED,
            Some((3, 2, 0)),
            false,
            true,
        ),
        (
            "pcaps/shot_limiting_test.json",
            LAYOUT_NESTED,
            Some((3, 2, 0)),
            false,
            true,
        ),
        (
            "pcaps/same_ports_nonlegacy.2.json",
            LAYOUT_NESTED,
            Some((2, 5, 2)),
            false,
            true,
        ),
        (
            "pcaps/same_ports.2.json",
            LAYOUT_NESTED,
            Some((2, 5, 2)),
            false,
            false,
        ), // LEGACY: no CRC
        (
            "pcaps/same_ports.1.json",
            LAYOUT_NESTED,
            Some((3, 1, 0)),
            false,
            false,
        ), // FUSA: no CRC
        (
            "pcaps/OS-0-32-U1_v2.2.0_1024x10.json",
            LAYOUT_LEGACY,
            Some((2, 2, 0)),
            false,
            false,
        ),
        (
            "pcaps/imu_zm_no_lidar_0.json",
            LAYOUT_NESTED,
            Some((3, 2, 0)),
            true,
            false,
        ),
    ];
    for &(f, layout, version, off, crc) in cases {
        let info = load(f);
        assert_eq!(info.layout, layout, "{f}");
        assert_eq!(info.firmware_version(), version, "{f}");
        assert_eq!(info.lidar_off, off, "{f}");
        assert_eq!(info.lidar_packets_have_crc(), crc, "{f}");
    }
    let crc = load("pcaps/crc_test.json");
    assert_eq!(crc.firmware, "035522cb7ffa0b1f8c4adff238e03ca3397973c8");
    assert_eq!(crc.imu_to_sensor[3], -2.441);
    let zm = load("pcaps/imu_zm_no_lidar_0.json");
    assert_eq!(zm.lidar_profile_name, "RNG19_RFL8_SIG16_NIR16_ZONE16");
    assert_eq!(zm.imu_profile, ImuProfile::Accel32Gyro32Nmea);
    assert_eq!(zm.imu_measurements_per_packet, 8);
    assert_eq!(zm.lidar_packet_bytes(), 0);
    let dup = load("pcaps/duplicate_id.json");
    assert_eq!(dup.timestamp_mode, TimestampMode::Ptp1588);
    assert_eq!((dup.udp_port_lidar, dup.udp_port_imu), (34636, 48887));
    let fw1 = load("metadata/1_14_beta_os1-991937000062-16A0_legacy.json");
    assert_eq!((fw1.udp_port_lidar, fw1.udp_port_imu), (7502, 7503));
    assert_eq!(fw1.imu_to_sensor, DEFAULT_IMU_TO_SENSOR);
}

// ---------------------------------------------------------------------------------------------
// Against the goldens: ouster-sdk 1.0.1's parse of each capture's metadata.

fn num(v: &Value, what: &str) -> f64 {
    v.as_f64()
        .unwrap_or_else(|| panic!("{what}: not a number: {v}"))
}

fn floats(v: &Value, what: &str) -> Vec<f64> {
    match v {
        Value::Array(a) => a.iter().flat_map(|x| flatten(x, what)).collect(),
        _ => panic!("{what}: not an array"),
    }
}

fn flatten(v: &Value, what: &str) -> Vec<f64> {
    match v {
        Value::Array(a) => a.iter().flat_map(|x| flatten(x, what)).collect(),
        x => vec![num(x, what)],
    }
}

fn assert_close(ours: &[f64], theirs: &[f64], what: &str) {
    assert_eq!(ours.len(), theirs.len(), "{what}: length");
    for (i, (a, b)) in ours.iter().zip(theirs).enumerate() {
        assert!(
            (a - b).abs() <= 1e-9,
            "{what}[{i}]: ringscan {a}, ouster-sdk {b}"
        );
    }
}

/// The metadata string of a ROS 1 bag: a `std_msgs/String` is a u32 length and the text, so
/// look for a `{` preceded by a length whose text parses as metadata.
fn metadata_in_bag(bytes: &[u8]) -> Option<String> {
    (4..bytes.len()).find_map(|i| {
        if bytes[i] != b'{' || !matches!(bytes.get(i + 1), Some(b'\n' | b' ' | b'"')) {
            return None;
        }
        let n = u32::from_le_bytes([bytes[i - 4], bytes[i - 3], bytes[i - 2], bytes[i - 1]]);
        let end = i.checked_add(n as usize)?;
        let text = std::str::from_utf8(bytes.get(i..end)?).ok()?;
        parse(text, "bag").ok().map(|_| text.to_owned())
    })
}

#[test]
fn goldens_metadata_as_parsed_by_ouster_sdk() {
    let Some(dir) = captures() else { return };
    let golden_root = dir.join("golden").join(SDK_TESTS);
    let mut goldens = Vec::new();
    for sub in ["pcaps", "bags"] {
        if let Ok(entries) = std::fs::read_dir(golden_root.join(sub)) {
            for e in entries.flatten() {
                let p = e.path();
                if p.to_string_lossy().ends_with(".golden.json") {
                    goldens.push(p);
                }
            }
        }
    }
    goldens.sort();
    if goldens.is_empty() {
        println!("SKIP: no Ouster goldens under {}", golden_root.display());
        return;
    }
    let mut sensors = 0;
    for g in &goldens {
        let gname = g
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let golden: Value = serde_json::from_str(&std::fs::read_to_string(g).expect("golden"))
            .unwrap_or_else(|e| panic!("{gname}: {e}"));
        let capture = golden["capture"].as_str().unwrap_or_default();
        for (si, s) in golden["sensors"]
            .as_array()
            .expect("sensors")
            .iter()
            .enumerate()
        {
            let what = format!("{gname} sensor {si}");
            let (text, name) = match s["metadata"].as_str() {
                Some(m) => (
                    std::fs::read_to_string(dir.join(m)).unwrap_or_else(|e| panic!("{m}: {e}")),
                    m.to_owned(),
                ),
                None => {
                    let bytes = std::fs::read(dir.join(capture)).expect("bag");
                    let text = metadata_in_bag(&bytes)
                        .unwrap_or_else(|| panic!("{what}: no metadata found in {capture}"));
                    (text, format!("{capture} (embedded)"))
                }
            };
            let info = parse(&text, &name).unwrap_or_else(|e| panic!("{what}: {name}: {e}"));
            compare_with_golden(&info, s, &text, &what);
            sensors += 1;
        }
    }
    println!("ouster metadata: {sensors} golden sensors match ouster-sdk 1.0.1's parse");
    assert!(
        sensors >= 17,
        "expected every Ouster golden sensor, found {sensors}"
    );
}

fn compare_with_golden(info: &OusterInfo, s: &Value, text: &str, what: &str) {
    let sdk = &s["as_parsed_by_sdk"];
    let sn: u64 = s["sn"].as_str().and_then(|v| v.parse().ok()).expect("sn");
    assert_eq!(info.serial, sn, "{what}: serial");
    assert_eq!(
        info.prod_line,
        s["prod_line"].as_str().unwrap_or_default(),
        "{what}: prod_line"
    );
    assert_eq!(
        info.firmware,
        s["fw_rev"].as_str().unwrap_or_default(),
        "{what}: fw_rev"
    );
    assert_eq!(
        u64::from(info.init_id),
        s["init_id"].as_u64().expect("init_id"),
        "{what}: init_id"
    );
    assert_eq!(
        format!("{}x{}", info.columns_per_frame, info.fps),
        s["lidar_mode"].as_str().unwrap_or_default(),
        "{what}: lidar_mode"
    );
    assert_eq!(
        Some(info.columns_per_frame as u64),
        s["columns_per_frame"].as_u64(),
        "{what}: W"
    );
    assert_eq!(
        Some(info.format.pixels_per_column as u64),
        s["pixels_per_column"].as_u64(),
        "{what}: H"
    );
    assert_eq!(
        Some(info.format.columns_per_packet as u64),
        s["columns_per_packet"].as_u64(),
        "{what}: cpp"
    );
    assert_eq!(Some(u64::from(info.fps)), s["fps"].as_u64(), "{what}: fps");
    let window: Vec<u64> = s["column_window"]
        .as_array()
        .expect("window")
        .iter()
        .filter_map(Value::as_u64)
        .collect();
    assert_eq!(
        vec![info.column_window.0 as u64, info.column_window.1 as u64],
        window,
        "{what}: column_window"
    );
    let shifts: Vec<i64> = s["pixel_shift_by_row"]
        .as_array()
        .expect("shifts")
        .iter()
        .filter_map(Value::as_i64)
        .collect();
    let ours: Vec<i64> = info
        .pixel_shift_by_row
        .iter()
        .map(|&v| i64::from(v))
        .collect();
    assert_eq!(ours, shifts, "{what}: pixel_shift_by_row");
    let profile = if info.lidar_off {
        "OFF"
    } else {
        info.format.profile.name()
    };
    assert_eq!(
        profile,
        s["udp_profile_lidar"].as_str().unwrap_or_default(),
        "{what}: lidar profile"
    );
    assert_eq!(
        info.imu_profile.name(),
        s["udp_profile_imu"].as_str().unwrap_or_default(),
        "{what}: IMU profile"
    );
    // Ports: where the metadata names one, it must match. Where it names none, ringscan uses
    // 7502 / 7503 and the SDK's pcap source took the port from the traffic (0 = no IMU packets
    // in the capture: OS-1-32-G_v2.1.1, OS-2-32-U0_v2.0.0).
    for (key, ours, default) in [
        (
            "udp_port_lidar",
            info.udp_port_lidar,
            DEFAULT_UDP_PORT_LIDAR,
        ),
        ("udp_port_imu", info.udp_port_imu, DEFAULT_UDP_PORT_IMU),
    ] {
        let golden = s[key].as_u64().expect("port");
        if text.contains(&format!("\"{key}\"")) {
            assert_eq!(u64::from(ours), golden, "{what}: {key}");
        } else {
            assert_eq!(ours, default, "{what}: {key} default");
            assert!(
                golden == u64::from(default) || golden == 0,
                "{what}: {key}: golden {golden}"
            );
        }
    }
    assert_close(
        &info.beam_altitude_angles,
        &floats(&sdk["beam_altitude_angles_deg"], what),
        &format!("{what}: altitude"),
    );
    assert_close(
        &info.beam_azimuth_angles,
        &floats(&sdk["beam_azimuth_angles_deg"], what),
        &format!("{what}: azimuth"),
    );
    assert_close(
        &[info.lidar_origin_to_beam_origin_mm],
        &[num(&sdk["lidar_origin_to_beam_origin_mm"], what)],
        &format!("{what}: lidar_origin_to_beam_origin_mm"),
    );
    assert_close(
        &info.beam_to_lidar,
        &floats(&sdk["beam_to_lidar_transform"], what),
        &format!("{what}: beam_to_lidar"),
    );
    assert_close(
        &info.lidar_to_sensor,
        &floats(&sdk["lidar_to_sensor_transform"], what),
        &format!("{what}: lidar_to_sensor"),
    );
    check_invariants(info, what);
}

// ---------------------------------------------------------------------------------------------
// Hand-made metadata, one per layout, and each error.

fn angles(h: usize) -> (Vec<f64>, Vec<f64>) {
    let alt = (0..h).map(|i| 20.0 - 40.0 * i as f64 / h as f64).collect();
    let az = (0..h).map(|i| [3.1, 1.0, -1.1, -3.2][i % 4]).collect();
    (alt, az)
}

/// A complete current nested file: OS-1-32, 1024x10, RNG19 single.
fn nested() -> Value {
    let (alt, az) = angles(32);
    json!({
        "sensor_info": {
            "prod_line": "OS-1-32-U2", "prod_sn": "992233000123", "initialization_id": 123456,
            "build_rev": "v2.5.2", "image_rev": "ousteros-image-prod-aries-v2.5.2+20230714195410",
            "status": "RUNNING"
        },
        "config_params": {
            "lidar_mode": "1024x10", "udp_port_lidar": 7600, "udp_port_imu": 7601,
            "timestamp_mode": "TIME_FROM_PTP_1588", "udp_dest": "192.168.1.2",
            "udp_profile_lidar": "RNG19_RFL8_SIG16_NIR16"
        },
        "lidar_data_format": {
            "columns_per_frame": 1024, "columns_per_packet": 16, "pixels_per_column": 32,
            "column_window": [10, 500], "pixel_shift_by_row": vec![-12; 32], "fps": 10,
            "udp_profile_lidar": "RNG19_RFL8_SIG16_NIR16", "udp_profile_imu": "LEGACY"
        },
        "beam_intrinsics": {
            "beam_altitude_angles": alt, "beam_azimuth_angles": az,
            "lidar_origin_to_beam_origin_mm": 15.806,
            "beam_to_lidar_transform": [1, 0, 0, 15.806, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
        },
        "lidar_intrinsics": {
            "lidar_to_sensor_transform": [-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 36.18, 0, 0, 0, 1]
        },
        "imu_intrinsics": {
            "imu_to_sensor_transform": [1, 0, 0, 6.253, 0, 1, 0, -11.775, 0, 0, 1, 7.645, 0, 0, 0, 1]
        },
        "calibration_status": {"reflectivity": {"valid": true, "timestamp": "2023-01-01T00:00:00"}},
        "user_data": ""
    })
}

/// The same sensor in the legacy flat layout.
fn legacy() -> Value {
    let n = nested();
    let mut flat = serde_json::Map::new();
    for sec in ["sensor_info", "beam_intrinsics"] {
        for (k, v) in n[sec].as_object().expect("section") {
            flat.insert(k.clone(), v.clone());
        }
    }
    for k in ["lidar_mode", "udp_port_lidar", "udp_port_imu"] {
        flat.insert(k.into(), n["config_params"][k].clone());
    }
    flat.insert("data_format".into(), n["lidar_data_format"].clone());
    flat.insert(
        "lidar_to_sensor_transform".into(),
        n["lidar_intrinsics"]["lidar_to_sensor_transform"].clone(),
    );
    flat.insert(
        "imu_to_sensor_transform".into(),
        n["imu_intrinsics"]["imu_to_sensor_transform"].clone(),
    );
    Value::Object(flat)
}

fn ok(v: &Value) -> OusterInfo {
    parse(&v.to_string(), "test.json").unwrap_or_else(|e| panic!("{e}\n{v}"))
}

fn err(v: &Value) -> CalibError {
    match parse(&v.to_string(), "test.json") {
        Ok(_) => panic!("accepted: {v}"),
        Err(e) => e,
    }
}

/// Rejected with a message that contains `needle`.
fn rejects(v: &Value, needle: &str) {
    let msg = err(v).to_string();
    assert!(msg.contains(needle), "message lacks {needle:?}: {msg}");
}

fn with(mut v: Value, path: &[&str], new: Value) -> Value {
    let mut at = &mut v;
    for (i, key) in path.iter().enumerate() {
        if i + 1 == path.len() {
            at.as_object_mut()
                .expect("object")
                .insert((*key).into(), new);
            break;
        }
        at = at.get_mut(*key).expect("path");
    }
    v
}

fn without(mut v: Value, path: &[&str]) -> Value {
    let mut at = &mut v;
    for (i, key) in path.iter().enumerate() {
        if i + 1 == path.len() {
            at.as_object_mut().expect("object").remove(*key);
            break;
        }
        at = at.get_mut(*key).expect("path");
    }
    v
}

#[test]
fn current_nested_layout_takes_every_value_from_the_file() {
    let info = ok(&nested());
    assert_eq!(info.layout, LAYOUT_NESTED);
    assert_eq!(info.prod_line, "OS-1-32-U2");
    assert_eq!(info.serial, 992_233_000_123);
    assert_eq!(info.init_id, 123_456);
    assert_eq!(info.firmware, "v2.5.2");
    assert_eq!(info.firmware_version(), Some((2, 5, 2)));
    assert_eq!((info.columns_per_frame, info.fps), (1024, 10));
    assert_eq!(info.format.profile, Profile::Rng19Rfl8Sig16Nir16);
    assert_eq!(
        (
            info.format.columns_per_packet,
            info.format.pixels_per_column
        ),
        (16, 32)
    );
    assert_eq!(info.lidar_packet_bytes(), 6400);
    assert_eq!(info.column_window, (10, 500));
    assert_eq!(info.pixel_shift_by_row, vec![-12; 32]);
    assert_eq!((info.udp_port_lidar, info.udp_port_imu), (7600, 7601));
    assert_eq!(info.timestamp_mode, TimestampMode::Ptp1588);
    assert_eq!(info.imu_profile, ImuProfile::Legacy);
    assert_eq!(info.beam_to_lidar[3], 15.806);
    assert_eq!(info.lidar_to_sensor, DEFAULT_LIDAR_TO_SENSOR);
    assert!(!info.lidar_off);
    assert!(info.lidar_packets_have_crc());
    // Window [10, 500] of 16-column packets: packets 0..=31.
    assert_eq!(info.expected_packets_per_frame(), 32);
    assert_eq!(info.columns_in_window(), 491);
    assert!(!info.is_column_in_window(9) && info.is_column_in_window(10));
    assert!(info.is_column_in_window(500) && !info.is_column_in_window(501));
}

#[test]
fn legacy_layout_reads_the_same_sensor() {
    let flat = ok(&legacy());
    let mut nested = ok(&nested());
    assert_eq!(flat.layout, LAYOUT_LEGACY);
    // A flat file's timestamp mode and udp_dest are not read (as the SDK's conversion).
    assert_eq!(flat.timestamp_mode, TimestampMode::InternalOsc);
    nested.layout = LAYOUT_LEGACY;
    nested.timestamp_mode = TimestampMode::InternalOsc;
    assert_eq!(flat, nested);
    // A flat `timestamp_mode` or `udp_dest` is ignored, as in the SDK.
    let v = with(
        with(legacy(), &["udp_dest"], json!("")),
        &["timestamp_mode"],
        json!(7),
    );
    assert!(!ok(&v).lidar_off);
}

#[test]
fn fw_1_12_nested_layout_with_a_string_data_format() {
    let v = with(
        nested(),
        &["lidar_data_format"],
        json!("error: Command not recognized."),
    );
    let v = with(
        v,
        &["calibration_status"],
        json!("error: Command not recognized."),
    );
    let info = ok(&v);
    assert_eq!(info.layout, LAYOUT_NESTED_1_12);
    // Everything from the lidar mode and the product line: H = 32 from OS-1-32-U2.
    assert_eq!(info.format.pixels_per_column, 32);
    assert_eq!(info.format.columns_per_packet, 16);
    assert_eq!(info.column_window, (0, 1023));
    assert_eq!(info.format.profile, Profile::Legacy);
    assert_eq!(
        info.pixel_shift_by_row,
        default_pixel_shift_by_row(1024, 32)
    );
    assert_eq!(&info.pixel_shift_by_row[..4], &[18, 12, 6, 0]);
    // The nested config is read: ports and timestamp mode.
    assert_eq!(info.udp_port_lidar, 7600);
    assert_eq!(info.timestamp_mode, TimestampMode::Ptp1588);
}

#[test]
fn reduced_legacy_metadata_gets_every_sdk_default() {
    // Only beam angles and the lidar mode, as OS-1-64_sensor_config_reduced.json.
    let (alt, az) = angles(64);
    let info = ok(
        &json!({"beam_altitude_angles": alt, "beam_azimuth_angles": az, "lidar_mode": "1024x10"}),
    );
    assert_eq!(info.layout, LAYOUT_LEGACY);
    assert_eq!(
        (info.prod_line.as_str(), info.serial, info.init_id),
        ("", 0, 0)
    );
    assert_eq!(
        (
            info.columns_per_frame,
            info.fps,
            info.format.pixels_per_column
        ),
        (1024, 10, 64)
    );
    assert_eq!(info.format.columns_per_packet, 16);
    assert_eq!(info.format.profile, Profile::Legacy);
    assert_eq!(info.imu_profile, ImuProfile::Legacy);
    assert_eq!(info.column_window, (0, 1023));
    assert_eq!(info.pixel_shift_by_row, [18, 12, 6, 0].repeat(16));
    assert_eq!((info.udp_port_lidar, info.udp_port_imu), (7502, 7503));
    assert_eq!(info.lidar_origin_to_beam_origin_mm, 12.163);
    let mut b2l = [0.0; 16];
    for i in 0..4 {
        b2l[i * 5] = 1.0;
    }
    b2l[3] = 12.163;
    assert_eq!(info.beam_to_lidar, b2l);
    assert_eq!(info.lidar_to_sensor, DEFAULT_LIDAR_TO_SENSOR);
    assert_eq!(info.lidar_to_sensor[11], 36.18);
    assert_eq!(info.imu_to_sensor, DEFAULT_IMU_TO_SENSOR);
    assert_eq!(
        (
            info.imu_to_sensor[3],
            info.imu_to_sensor[7],
            info.imu_to_sensor[11]
        ),
        (6.253, -11.775, 7.645)
    );
    assert_eq!(info.firmware_version(), None);
    assert!(!info.lidar_packets_have_crc());
    assert_eq!(info.expected_packets_per_frame(), 64);
}

#[test]
fn beam_origin_default_follows_the_product_line() {
    for (line, mm) in [
        ("OS-0-32-U1", 27.67),
        ("OS-1-32-G", 15.806),
        ("OS-2-32-U0", 13.762),
        ("OS1-32", 12.163),
        ("OSDome-32", 12.163),
        ("", 12.163),
    ] {
        let v = without(
            without(
                nested(),
                &["beam_intrinsics", "lidar_origin_to_beam_origin_mm"],
            ),
            &["beam_intrinsics", "beam_to_lidar_transform"],
        );
        let info = ok(&with(v, &["sensor_info", "prod_line"], json!(line)));
        assert_eq!(info.lidar_origin_to_beam_origin_mm, mm, "{line}");
        assert_eq!(info.beam_to_lidar[3], mm, "{line}");
        assert_eq!(ouster::default_beam_to_lidar(line)[3], mm);
    }
    // The file's offset builds the default beam_to_lidar_transform.
    let v = without(nested(), &["beam_intrinsics", "beam_to_lidar_transform"]);
    let info = ok(&with(
        v,
        &["beam_intrinsics", "lidar_origin_to_beam_origin_mm"],
        json!(20.5),
    ));
    assert_eq!(info.beam_to_lidar[3], 20.5);
}

#[test]
fn pixels_per_column_default_comes_from_the_product_line() {
    let (alt, az) = angles(128);
    let v = without(nested(), &["lidar_data_format", "pixels_per_column"]);
    let v = without(v, &["lidar_data_format", "pixel_shift_by_row"]);
    let v = with(v, &["sensor_info", "prod_line"], json!("OS-1-128"));
    let v = with(v, &["beam_intrinsics", "beam_altitude_angles"], json!(alt));
    let v = with(v, &["beam_intrinsics", "beam_azimuth_angles"], json!(az));
    let info = ok(&v);
    assert_eq!(info.format.pixels_per_column, 128);
    // The SDK's default shifts: 64 rows of 18/12/6/0, then zeros.
    assert_eq!(
        &info.pixel_shift_by_row[..64],
        &[18, 12, 6, 0].repeat(16)[..]
    );
    assert!(info.pixel_shift_by_row[64..].iter().all(|&s| s == 0));
    // A product line without a beam count cannot give H.
    rejects(
        &with(v, &["sensor_info", "prod_line"], json!("OS-1")),
        "pixels_per_column",
    );
}

#[test]
fn lidar_stream_off_as_the_sdk_decides() {
    let off = |v: Value| ok(&v).lidar_off;
    assert!(off(with(
        nested(),
        &["config_params", "udp_port_lidar"],
        json!(0)
    )));
    assert!(off(with(
        nested(),
        &["config_params", "udp_dest"],
        json!("")
    )));
    assert!(off(with(
        nested(),
        &["lidar_data_format", "udp_profile_lidar"],
        json!("OFF")
    )));
    // udp_ip stands in for a missing udp_dest.
    let v = without(nested(), &["config_params", "udp_dest"]);
    assert!(off(with(
        v.clone(),
        &["config_params", "udp_ip"],
        json!("")
    )));
    assert!(!off(with(
        v,
        &["config_params", "udp_ip"],
        json!("10.0.0.1")
    )));
    // A profile ringscan does not decode (ouster-sdk's UNKNOWN) is fine while the stream is
    // off, refused otherwise.
    let unknown = with(
        nested(),
        &["lidar_data_format", "udp_profile_lidar"],
        json!("UNKNOWN"),
    );
    let info = ok(&with(
        unknown.clone(),
        &["config_params", "udp_port_lidar"],
        json!(0),
    ));
    assert!(info.lidar_off);
    assert_eq!(info.lidar_profile_name, "UNKNOWN");
    assert_eq!(
        (info.lidar_packet_bytes(), info.expected_packets_per_frame()),
        (0, 0)
    );
    rejects(&unknown, "ringscan does not decode it");
    // The zone-monitoring and colour profiles are decoded (their zone mask and colour
    // channels are not read).
    for name in [
        "RNG19_RFL8_SIG16_NIR16_ZONE16",
        "RNG15_RFL8_NIR8_ZONE16",
        "RNG19_RFL8_SIG16_ZONE16_DUAL",
        "RNG19_RFL8_SIG16_NIR16_RGB16",
        "RNG19_RFL8_SIG16_NIR16_RGB16_DUAL",
    ] {
        let info = ok(&with(
            nested(),
            &["lidar_data_format", "udp_profile_lidar"],
            json!(name),
        ));
        assert!(!info.lidar_off, "{name}");
        assert_eq!(info.format.profile.name(), name);
    }
    // The IMU profile check does not apply to an OFF lidar.
    let v = with(
        nested(),
        &["lidar_data_format", "udp_profile_imu"],
        json!("ACCEL32_GYRO32_NMEA"),
    );
    let v = with(v, &["lidar_data_format", "udp_profile_lidar"], json!("OFF"));
    assert!(off(v));
}

#[test]
fn windows_that_wrap_through_zero() {
    let info = ok(&with(
        nested(),
        &["lidar_data_format", "column_window"],
        json!([1000, 10]),
    ));
    assert!(
        info.is_column_in_window(1023)
            && info.is_column_in_window(0)
            && info.is_column_in_window(10)
    );
    assert!(!info.is_column_in_window(11) && !info.is_column_in_window(999));
    assert!(!info.is_column_in_window(1024));
    assert_eq!(info.columns_in_window(), 24 + 11);
    // Packets 62, 63 and 0 (the SDK's lidar_packets_per_frame).
    assert_eq!(info.expected_packets_per_frame(), 3);
    // Start and end in the same packet, wrapping: every packet (the SDK's rule).
    let info = ok(&with(
        nested(),
        &["lidar_data_format", "column_window"],
        json!([1005, 1000]),
    ));
    assert_eq!(info.expected_packets_per_frame(), 64);
    assert_eq!(info.columns_in_window(), 1020);
    // The SDK's windowed capture: [1, 256] of 512 → packets 0..=16.
    let v = with(nested(), &["config_params", "lidar_mode"], json!("512x10"));
    let v = with(v, &["lidar_data_format", "columns_per_frame"], json!(512));
    let v = with(v, &["lidar_data_format", "column_window"], json!([1, 256]));
    assert_eq!(ok(&v).expected_packets_per_frame(), 17);
}

#[test]
fn each_error_names_its_key() {
    let n = nested;
    let df = |k: &str, v: Value| with(nested(), &["lidar_data_format", k], v);
    let cases: Vec<(Value, &str)> = vec![
        // layout
        (without(n(), &["calibration_status"]), "calibration_status"),
        (without(n(), &["sensor_info"]), "sensor_info"),
        (
            with(legacy(), &["calibration_status"], json!({})),
            "beam_intrinsics",
        ),
        (with(n(), &["config_params"], json!([])), "config_params"),
        (
            with(n(), &["lidar_data_format"], json!(5)),
            "lidar_data_format",
        ),
        (with(legacy(), &["data_format"], json!("x")), "data_format"),
        // beam angles
        (
            without(n(), &["beam_intrinsics", "beam_altitude_angles"]),
            "beam_intrinsics.beam_altitude_angles",
        ),
        (
            without(n(), &["beam_intrinsics", "beam_azimuth_angles"]),
            "beam_intrinsics.beam_azimuth_angles",
        ),
        (
            with(
                n(),
                &["beam_intrinsics", "beam_altitude_angles"],
                json!(vec![1.0; 31]),
            ),
            "expected 32 entries, found 31",
        ),
        (
            with(
                n(),
                &["beam_intrinsics", "beam_azimuth_angles"],
                json!(null),
            ),
            "beam_azimuth_angles",
        ),
        (
            with(
                n(),
                &["beam_intrinsics", "beam_altitude_angles"],
                json!(vec![vec![1.0; 1024]; 32]),
            ),
            "beam_altitude_angles",
        ),
        (
            with(
                n(),
                &["beam_intrinsics", "beam_altitude_angles"],
                json!(vec![91.0; 32]),
            ),
            "within ±90",
        ),
        (
            with(
                n(),
                &["beam_intrinsics", "beam_azimuth_angles"],
                json!(vec![-181.0; 32]),
            ),
            "within ±180",
        ),
        (
            with(
                n(),
                &["beam_intrinsics", "beam_altitude_angles"],
                json!(vec![0.0; 32]),
            ),
            "beam_altitude_angles",
        ),
        (
            with(
                n(),
                &["beam_intrinsics", "lidar_origin_to_beam_origin_mm"],
                json!("15"),
            ),
            "lidar_origin_to_beam_origin_mm",
        ),
        (
            with(
                n(),
                &["beam_intrinsics", "lidar_origin_to_beam_origin_mm"],
                json!(1e9),
            ),
            "lidar_origin_to_beam_origin_mm",
        ),
        // transforms
        (
            with(
                n(),
                &["beam_intrinsics", "beam_to_lidar_transform"],
                json!([1, 2]),
            ),
            "beam_to_lidar_transform",
        ),
        (
            with(
                n(),
                &["lidar_intrinsics", "lidar_to_sensor_transform"],
                json!([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
            ),
            "lidar_to_sensor_transform",
        ),
        (
            with(
                n(),
                &["imu_intrinsics", "imu_to_sensor_transform"],
                json!([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 1, 1]),
            ),
            "last row",
        ),
        (
            with(
                n(),
                &["imu_intrinsics", "imu_to_sensor_transform"],
                json!([1, 0, 0, 1e6, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]),
            ),
            "translation",
        ),
        (
            with(
                n(),
                &["imu_intrinsics", "imu_to_sensor_transform"],
                json!([2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]),
            ),
            "rotation",
        ),
        // mode, W, H, fps
        (
            with(n(), &["config_params", "lidar_mode"], json!("1024x15")),
            "config_params.lidar_mode",
        ),
        (
            with(n(), &["config_params", "lidar_mode"], json!(1024)),
            "config_params.lidar_mode",
        ),
        (
            df("columns_per_frame", json!(2048)),
            "does not match config_params.lidar_mode",
        ),
        (df("fps", json!(20)), "lidar_data_format.fps"),
        (
            without(
                df("columns_per_frame", json!(1000)),
                &["config_params", "lidar_mode"],
            ),
            "512, 1024, 2048 or 4096",
        ),
        (
            without(
                without(n(), &["config_params", "lidar_mode"]),
                &["lidar_data_format", "columns_per_frame"],
            ),
            "columns_per_frame",
        ),
        (
            without(
                without(n(), &["config_params", "lidar_mode"]),
                &["lidar_data_format", "fps"],
            ),
            "lidar_mode",
        ),
        (
            without(df("fps", json!(15)), &["config_params", "lidar_mode"]),
            "lidar_data_format.fps",
        ),
        (df("pixels_per_column", json!(24)), "16, 32, 64 or 128"),
        (df("pixels_per_column", json!(32.0)), "pixels_per_column"),
        (df("columns_per_packet", json!(0)), "columns_per_packet"),
        (df("columns_per_packet", json!(24)), "columns_per_packet"),
        (df("columns_per_packet", json!(5000)), "columns_per_packet"),
        // window and shifts
        (df("column_window", json!([0, 1024])), "column_window"),
        (df("column_window", json!([5])), "column_window"),
        (df("column_window", json!([-1, 5])), "column_window"),
        (df("column_window", json!("0,1023")), "column_window"),
        (
            df("pixel_shift_by_row", json!([1, 2, 3])),
            "pixel_shift_by_row",
        ),
        (
            df("pixel_shift_by_row", json!(vec![1024; 32])),
            "pixel_shift_by_row",
        ),
        (
            df("pixel_shift_by_row", json!(vec![1.5; 32])),
            "pixel_shift_by_row",
        ),
        // profiles
        (
            df("udp_profile_lidar", json!("FOO")),
            "lidar_data_format.udp_profile_lidar",
        ),
        (df("udp_profile_lidar", json!(3)), "udp_profile_lidar"),
        (df("udp_profile_imu", json!("FOO")), "udp_profile_imu"),
        (
            with(
                df("udp_profile_lidar", json!("LEGACY")),
                &["lidar_data_format", "udp_profile_imu"],
                json!("ACCEL32_GYRO32_NMEA"),
            ),
            "LEGACY",
        ),
        (df("header_type", json!("FUSA")), "header_type"),
        (df("header_type", json!("BIG")), "header_type"),
        (
            with(
                df("udp_profile_lidar", json!("FIVE_WORD_PIXEL")),
                &["lidar_data_format", "columns_per_packet"],
                json!(128),
            ),
            "UDP datagram",
        ),
        (
            with(
                n(),
                &["imu_data_format"],
                json!({"imu_measurements_per_packet": 100000}),
            ),
            "imu_measurements_per_packet",
        ),
        // sensor info and config
        (
            with(n(), &["sensor_info", "prod_sn"], json!("99x")),
            "sensor_info.prod_sn",
        ),
        (
            with(
                n(),
                &["sensor_info", "prod_sn"],
                json!("99999999999999999999"),
            ),
            "prod_sn",
        ),
        (
            with(n(), &["sensor_info", "prod_sn"], json!(1u64 << 41)),
            "prod_sn",
        ),
        (
            with(n(), &["sensor_info", "prod_sn"], json!(null)),
            "prod_sn",
        ),
        (
            with(n(), &["sensor_info", "initialization_id"], json!(1 << 24)),
            "initialization_id",
        ),
        (
            with(n(), &["sensor_info", "initialization_id"], json!(-5)),
            "initialization_id",
        ),
        (
            with(n(), &["sensor_info", "prod_line"], json!(5)),
            "prod_line",
        ),
        (
            with(n(), &["sensor_info", "build_rev"], json!(null)),
            "build_rev",
        ),
        (
            with(n(), &["config_params", "udp_port_lidar"], json!(70000)),
            "udp_port_lidar",
        ),
        (
            with(n(), &["config_params", "udp_port_imu"], json!("7503")),
            "udp_port_imu",
        ),
        (
            with(n(), &["config_params", "udp_dest"], json!(false)),
            "udp_dest",
        ),
        (
            with(n(), &["config_params", "timestamp_mode"], json!(1)),
            "timestamp_mode",
        ),
        (
            with(legacy(), &["udp_port_lidar"], json!(-1)),
            "udp_port_lidar",
        ),
    ];
    for (v, needle) in &cases {
        let e = err(v);
        let msg = e.to_string();
        assert!(msg.contains(needle), "message lacks {needle:?}: {msg}");
        assert!(
            matches!(
                e,
                CalibError::MissingKey { .. }
                    | CalibError::BadValue { .. }
                    | CalibError::Invalid(_)
            ),
            "{msg}"
        );
    }
}

#[test]
fn valid_variants_are_accepted() {
    let df = |k: &str, v: Value| with(nested(), &["lidar_data_format", k], v);
    // Serial as a number, an empty serial (0), unknown timestamp modes, IMU off, FUSA header.
    assert_eq!(
        ok(&with(
            nested(),
            &["sensor_info", "prod_sn"],
            json!(992233000123u64)
        ))
        .serial,
        992_233_000_123
    );
    assert_eq!(
        ok(&with(nested(), &["sensor_info", "prod_sn"], json!(""))).serial,
        0
    );
    assert_eq!(
        ok(&with(
            nested(),
            &["config_params", "timestamp_mode"],
            json!("TIME_FROM_UNSPEC")
        ))
        .timestamp_mode,
        TimestampMode::Unknown
    );
    assert_eq!(
        ok(&with(
            nested(),
            &["config_params", "timestamp_mode"],
            json!("TIME_FROM_SYNC_PULSE_IN")
        ))
        .timestamp_mode,
        TimestampMode::SyncPulseIn
    );
    assert_eq!(
        ok(&df("udp_profile_imu", json!("OFF"))).imu_profile,
        ImuProfile::Off
    );
    let v = with(
        df("udp_profile_lidar", json!("FUSA_RNG15_RFL8_NIR8_DUAL")),
        &["lidar_data_format", "header_type"],
        json!("FUSA"),
    );
    assert_eq!(ok(&v).format.profile, Profile::FusaRng15Rfl8Nir8Dual);
    assert!(!ok(&v).lidar_packets_have_crc());
    // LEGACY lidar with an IMU that is OFF is fine (only ACCEL32_GYRO32_NMEA is refused).
    let v = with(
        df("udp_profile_lidar", json!("LEGACY")),
        &["lidar_data_format", "udp_profile_imu"],
        json!("OFF"),
    );
    assert_eq!(ok(&v).lidar_packet_bytes(), 6464);
    // Columns per packet 8; every mode.
    assert_eq!(
        ok(&df("columns_per_packet", json!(8))).expected_packets_per_frame(),
        62
    );
    for (mode, w, fps) in ouster::LIDAR_MODES {
        let v = with(nested(), &["config_params", "lidar_mode"], json!(mode));
        let v = without(
            without(
                without(v, &["lidar_data_format", "columns_per_frame"]),
                &["lidar_data_format", "fps"],
            ),
            &["lidar_data_format", "column_window"],
        );
        let v = with(
            v,
            &["lidar_data_format", "pixel_shift_by_row"],
            json!(vec![3; 32]),
        );
        let info = ok(&v);
        assert_eq!((info.columns_per_frame, info.fps), (w, fps), "{mode}");
        assert_eq!(info.column_window, (0, w - 1));
        assert_eq!(info.expected_packets_per_frame(), w / 16);
    }
    // Without a lidar mode, columns_per_frame and fps carry the frame; default shifts are zero.
    let v = without(
        without(nested(), &["config_params", "lidar_mode"]),
        &["lidar_data_format", "pixel_shift_by_row"],
    );
    let info = ok(&v);
    assert_eq!((info.columns_per_frame, info.fps), (1024, 10));
    assert!(info.pixel_shift_by_row.iter().all(|&s| s == 0));
    // A byte-order mark and surrounding whitespace.
    let text = format!("\u{feff}\n  {}\n\n", nested());
    assert!(parse(&text, "bom.json").is_ok());
}

// ---------------------------------------------------------------------------------------------
// Helpers and hostile input.

#[test]
fn default_shifts_are_the_sdks() {
    assert_eq!(default_pixel_shift_by_row(512, 8), [9, 6, 3, 0, 9, 6, 3, 0]);
    assert_eq!(default_pixel_shift_by_row(1024, 4), [18, 12, 6, 0]);
    assert_eq!(default_pixel_shift_by_row(2048, 4), [36, 24, 12, 0]);
    assert_eq!(default_pixel_shift_by_row(4096, 4), [72, 48, 24, 0]);
    let s = default_pixel_shift_by_row(1024, 128);
    assert_eq!(s.len(), 128);
    assert_eq!(&s[60..68], &[18, 12, 6, 0, 0, 0, 0, 0]);
}

#[test]
fn product_lines_and_firmware_versions() {
    for (line, count) in [
        ("OS-1-128", Some(128)),
        ("OS-0-32-U1", Some(32)),
        ("OS-1-64-AH", Some(64)),
        ("OS-1-32-G", Some(32)),
        ("OS-1-16-A0", Some(16)),
        ("OS-DOME-128", Some(128)),
        ("OS-1-MAX-128", Some(128)),
        ("OS-1", Some(0)),
        ("OSDome-128", Some(0)),
        ("OS1", None),
        ("", None),
        ("-1-64", None),
    ] {
        assert_eq!(prod_line_beam_count(line), count, "{line}");
    }
    for (s, v) in [
        (
            "ousteros-image-prod-aries-v2.5.0-omega.8+20230318213158.staging",
            Some((2, 5, 0)),
        ),
        (
            "ousteros-image-dev-bootes-v3.2.0-alpha.1+20240812193256",
            Some((3, 2, 0)),
        ),
        ("v2.3.0", Some((2, 3, 0))),
        ("v1.14.0-beta.1-928-g6cccd78", Some((1, 14, 0))),
        ("035522cb7ffa0b1f8c4adff238e03ca3397973c8", None),
        ("v2.3", None),
        ("dev2.3.4", None),
        ("v99999999999.1.1", None),
        ("", None),
    ] {
        assert_eq!(parse_firmware_version(s), v, "{s}");
    }
}

#[test]
fn syntax_errors_carry_line_and_column() {
    let e = parse(
        "{\n  \"lidar_mode\": \"1024x10\",\n  \"beam_altitude_angles\": [1, 2,, 3]\n}",
        "x.json",
    )
    .unwrap_err();
    match e {
        CalibError::Syntax {
            format,
            line,
            column,
            ..
        } => {
            assert_eq!((format, line), ("JSON", 3));
            assert!(column > 20, "column {column}");
        }
        other => panic!("{other}"),
    }
    for bad in [
        "",
        "   ",
        "{",
        "{\"a\": 1} x",
        "nul",
        "{\"a\": 1e400}",
        "{\"a\": NaN}",
        "[1, 2",
    ] {
        assert!(
            matches!(parse(bad, "x"), Err(CalibError::Syntax { .. })),
            "{bad:?}"
        );
    }
    for top in ["[]", "3", "\"metadata\"", "null", "true"] {
        let msg = parse(top, "x").unwrap_err().to_string();
        assert!(msg.contains("a JSON object"), "{top}: {msg}");
    }
    let msg = parse("{}", "x").unwrap_err().to_string();
    assert!(msg.contains("columns_per_frame"), "{msg}");
}

#[test]
fn hostile_input_is_an_error_never_a_panic() {
    // Too large.
    let big = " ".repeat(MAX_CALIB_BYTES + 1);
    assert!(matches!(parse(&big, "x"), Err(CalibError::TooLarge(..))));
    // Deep nesting: serde_json's recursion limit, not the stack.
    let deep = format!("{}{}", "[".repeat(200_000), "]".repeat(200_000));
    assert!(matches!(parse(&deep, "x"), Err(CalibError::Syntax { .. })));
    let deep_obj = format!("{}1{}", "{\"a\":".repeat(100_000), "}".repeat(100_000));
    assert!(matches!(
        parse(&deep_obj, "x"),
        Err(CalibError::Syntax { .. })
    ));
    // 10^6-element arrays.
    let million = format!("[{}0]", "0,".repeat(999_999));
    let text = format!("{{\"lidar_mode\": \"1024x10\", \"beam_altitude_angles\": {million}, \"beam_azimuth_angles\": {million}}}");
    assert!(text.len() < MAX_CALIB_BYTES);
    let msg = parse(&text, "x").unwrap_err().to_string();
    assert!(
        msg.contains("beam_altitude_angles") && msg.contains("1000000 entries"),
        "{msg}"
    );
    let text = format!(
        "{{\"lidar_mode\": \"1024x10\", \"data_format\": {{\"pixel_shift_by_row\": {million}}}}}"
    );
    assert!(parse(&text, "x").is_err());
    // Huge integers and floats in every numeric slot.
    for v in [
        json!(u64::MAX),
        json!(i64::MIN),
        json!(1.0e308),
        json!(-1.0e308),
        json!(1e-320),
    ] {
        for path in [
            &["sensor_info", "initialization_id"][..],
            &["sensor_info", "prod_sn"],
            &["config_params", "udp_port_lidar"],
            &["lidar_data_format", "columns_per_frame"],
            &["lidar_data_format", "pixels_per_column"],
            &["lidar_data_format", "columns_per_packet"],
            &["lidar_data_format", "fps"],
            &["beam_intrinsics", "lidar_origin_to_beam_origin_mm"],
        ] {
            let _ = parse(&with(nested(), path, v.clone()).to_string(), "x");
        }
    }
    // Garbage bytes that are valid UTF-8, and control characters.
    for junk in [
        "\u{0}\u{1}\u{2}",
        "{\"\u{0}\": 1}",
        "\u{feff}\u{feff}{}",
        "{\"a\":\"\\ud800\"}",
    ] {
        assert!(parse(junk, "x").is_err(), "{junk:?}");
    }
}

/// Every value of a valid file replaced, one at a time, by every JSON type: an error or a
/// calibration that still satisfies the invariants, never a panic.
#[test]
fn every_value_replaced_by_every_type() {
    let replacements = [
        json!(null),
        json!(true),
        json!(-1),
        json!(0),
        json!(1.5),
        json!(1e300),
        json!("x"),
        json!(""),
        json!([]),
        json!([0, 0]),
        json!({}),
    ];
    fn paths(v: &Value, prefix: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
        if let Value::Object(m) = v {
            for (k, x) in m {
                prefix.push(k.clone());
                out.push(prefix.clone());
                paths(x, prefix, out);
                prefix.pop();
            }
        }
    }
    for base in [nested(), legacy()] {
        let mut all = Vec::new();
        paths(&base, &mut Vec::new(), &mut all);
        let mut accepted = 0;
        for path in &all {
            let p: Vec<&str> = path.iter().map(String::as_str).collect();
            for r in &replacements {
                if let Ok(info) = parse(&with(base.clone(), &p, r.clone()).to_string(), "x") {
                    check_invariants(&info, &path.join("."));
                    accepted += 1;
                }
            }
            if let Ok(info) = parse(&without(base.clone(), &p).to_string(), "x") {
                check_invariants(&info, &path.join("."));
            }
        }
        assert!(accepted > 0);
    }
}
