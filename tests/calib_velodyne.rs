//! Velodyne calibration parsers and built-in tables against the real calibration files in
//! `../shared/captures` (skipped with `SKIP:` when absent) and against hostile input.

use std::path::{Path, PathBuf};

use ringscan::sensor::calib::CalibError;
use ringscan::sensor::calib::MAX_CALIB_BYTES;
use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::calib::parse_velodyne_bytes;
use ringscan::sensor::velodyne::calib::ros_yaml;
use ringscan::sensor::velodyne::calib::veloview_xml;
use ringscan::sensor::velodyne::calib::LaserCalibration;
use ringscan::sensor::velodyne::calib::VelodyneCalibration;
use ringscan::sensor::velodyne::model::VelodyneModel;

fn captures() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/captures");
    if dir.is_dir() {
        Some(dir)
    } else {
        println!("SKIP: {} not found", dir.display());
        None
    }
}

const ROS: &str = "ros-drivers__velodyne/velodyne_pointcloud";
const VELOVIEW: &str = "Kitware__VeloView/Plugins/VelodynePlugin/CalibrationsFiles";
const NEBULA: &str = "tier4__nebula/src/nebula_velodyne/nebula_velodyne_decoders/calibration";
const VALGUR: &str = "valgur__velodyne_decoder/src/velodyne_decoder/calibrations";

/// Reads and parses one capture file (format sniffed from the text); `None` when absent.
fn load(rel: &str) -> Option<VelodyneCalibration> {
    let path = captures()?.join(rel);
    let Ok(bytes) = std::fs::read(&path) else {
        println!("SKIP: {} not found", path.display());
        return None;
    };
    match parse_velodyne_bytes(&bytes, rel) {
        Ok(c) => Some(c),
        Err(e) => panic!("{rel}: {e}"),
    }
}

fn text(rel: &str) -> Option<String> {
    let path = captures()?.join(rel);
    match std::fs::read_to_string(&path) {
        Ok(t) => Some(t),
        Err(_) => {
            println!("SKIP: {} not found", path.display());
            None
        }
    }
}

/// Every yaml / yml / xml under the captures, except nebula's bag `metadata.yaml` files.
fn calibration_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if matches!(
                p.extension().and_then(|x| x.to_str()),
                Some("yaml" | "yml" | "xml")
            ) && p.file_name().and_then(|n| n.to_str()) != Some("metadata.yaml")
            {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

#[test]
fn every_real_calibration_file_parses_and_validates() {
    let Some(dir) = captures() else { return };
    let files = calibration_files(&dir);
    assert!(
        files.len() >= 35,
        "found only {} calibration files",
        files.len()
    );
    for path in &files {
        let rel = path.strip_prefix(&dir).unwrap().display().to_string();
        let bytes = std::fs::read(path).unwrap();
        let c = parse_velodyne_bytes(&bytes, &rel).unwrap_or_else(|e| panic!("{rel}: {e}"));
        assert_eq!(c.source, rel);
        assert_eq!(c.rings().len(), c.num_lasers());
        let hdl64 = c.num_lasers() == 64;
        // Every HDL-64E table here has distance corrections; no other table has any.
        assert_eq!(c.advanced, hdl64, "{rel}: advanced = {}", c.advanced);
        if let Some(r) = c.distance_resolution {
            // nebula's VLS128.yaml says 0.007, a value no decoder reads: the VLS-128's unit is
            // fixed at 4 mm by its packet format (`VelodyneModel::fixed_distance_resolution`).
            let vls128 = c.num_lasers() == 128 && r == 0.007;
            assert!(
                r == 0.002 || r == 0.004 || vls128,
                "{rel}: distance_resolution {r}"
            );
        }
        println!(
            "ok {rel}: {} lasers, advanced {}",
            c.num_lasers(),
            c.advanced
        );
    }
}

#[test]
fn ros_unit_test_values() {
    // The expectations of ros-drivers tests/test_calibration.cpp, for the same files.
    if let Some(c) = load(&format!("{ROS}/params/VLP16db.yaml")) {
        assert_eq!(c.num_lasers(), 16);
        assert!((c.lasers[0].vert_correction - -0.2617993877991494).abs() < 1e-6);
        assert!((c.lasers[15].vert_correction - 0.2617993877991494).abs() < 1e-6);
        assert_eq!(
            (c.lasers[0].min_intensity, c.lasers[0].max_intensity),
            (0, 255)
        );
        assert_eq!(c.distance_resolution, Some(0.002));
    }
    if let Some(c) = load(&format!("{ROS}/params/32db.yaml")) {
        assert_eq!(c.num_lasers(), 32);
        assert!((c.lasers[0].vert_correction - -0.5352924815866609).abs() < 1e-9);
        assert!((c.lasers[31].vert_correction - 0.18622663118779495).abs() < 1e-9);
    }
    if let Some(c) = load(&format!("{ROS}/params/64e_utexas.yaml")) {
        // two_pt_correction_available: true with zero near corrections: kept as written.
        let l = &c.lasers[0];
        assert!((l.vert_correction - -0.124932751059532).abs() < 1e-12);
        assert_eq!((l.dist_correction_x, l.dist_correction_y), (0.0, 0.0));
        assert!((c.lasers[63].vert_correction - -0.209881335496902).abs() < 1e-12);
    }
    if let Some(c) = load(&format!("{ROS}/params/64e_s2.1-sztaki.yaml")) {
        let l = &c.lasers[0];
        assert!((l.vert_correction - -0.15304134919741974).abs() < 1e-12);
        assert!((l.horiz_offset_correction - 0.025999999).abs() < 1e-12);
        assert_eq!((l.min_intensity, l.max_intensity), (30, 235));
        assert_eq!(l.focal_distance, 12.0); // metres (1200 cm in the db.xml)
        assert_eq!(l.dist_correction_x, 1.5500304); // two-point available: kept
        let l = &c.lasers[63];
        assert!((l.horiz_offset_correction - -0.025999999).abs() < 1e-12);
        assert_eq!((l.min_intensity, l.max_intensity), (0, 255));
    }
    if let Some(c) = load(&format!("{ROS}/tests/issue_84_float_intensities.yaml")) {
        assert_eq!(c.num_lasers(), 64);
        let l = &c.lasers[0];
        assert!((l.vert_correction - -0.12118950050089745).abs() < 1e-12);
        assert_eq!((l.min_intensity, l.max_intensity), (40, 255));
        // No two_pt_correction_available: the near corrections are folded to the far one.
        assert_eq!(l.dist_correction_x, l.dist_correction);
        assert_eq!(l.dist_correction_y, l.dist_correction);
        assert_eq!(
            (c.lasers[26].min_intensity, c.lasers[26].max_intensity),
            (0, 245)
        );
        assert!((c.lasers[63].vert_correction - -0.20683046990039078).abs() < 1e-12);
    }
}

/// Same table within float tolerance; `near` includes the two-point near corrections.
fn assert_same_geometry(a: &VelodyneCalibration, b: &VelodyneCalibration, what: &str, near: bool) {
    assert_eq!(a.num_lasers(), b.num_lasers(), "{what}");
    for (x, y) in a.lasers.iter().zip(&b.lasers) {
        let pairs: [(&str, f64, f64, f64); 10] = [
            (
                "vert_correction",
                x.vert_correction,
                y.vert_correction,
                1e-6,
            ),
            ("rot_correction", x.rot_correction, y.rot_correction, 1e-6),
            (
                "dist_correction",
                x.dist_correction,
                y.dist_correction,
                1e-9,
            ),
            (
                "dist_correction_x",
                x.dist_correction_x,
                y.dist_correction_x,
                1e-9,
            ),
            (
                "dist_correction_y",
                x.dist_correction_y,
                y.dist_correction_y,
                1e-9,
            ),
            (
                "vert_offset_correction",
                x.vert_offset_correction,
                y.vert_offset_correction,
                1e-9,
            ),
            (
                "horiz_offset_correction",
                x.horiz_offset_correction,
                y.horiz_offset_correction,
                1e-9,
            ),
            ("focal_distance", x.focal_distance, y.focal_distance, 1e-9),
            ("focal_slope", x.focal_slope, y.focal_slope, 1e-9),
            (
                "laser_id",
                f64::from(x.laser_id),
                f64::from(y.laser_id),
                0.0,
            ),
        ];
        for (name, u, v, tol) in pairs {
            if !near && name.starts_with("dist_correction_") {
                continue;
            }
            assert!(
                (u - v).abs() <= tol,
                "{what}: laser {} {name}: {u} vs {v}",
                x.laser_id
            );
        }
    }
    assert_eq!(a.advanced, b.advanced, "{what}");
}

#[test]
fn sztaki_db_xml_and_yaml_agree() {
    let (Some(xml), Some(yaml)) = (
        load(&format!("{ROS}/tests/64e_s2.1-sztaki.xml")),
        load(&format!("{ROS}/params/64e_s2.1-sztaki.yaml")),
    ) else {
        return;
    };
    assert_same_geometry(&xml, &yaml, "64e_s2.1-sztaki", true);
    // focal distance: 1200 cm in the xml, 12.0 in the yaml -> the yaml unit is metres.
    assert_eq!(xml.lasers[0].focal_distance, 12.0);
    assert_eq!(xml.distance_resolution, yaml.distance_resolution);
    assert_eq!(xml.distance_resolution, Some(0.002));

    // Intensity limits: the xml is the truth. gen_calibration.py appended each non-default
    // minIntensity_ / maxIntensity_ value to the next free laser instead of its own, so the
    // yaml holds the xml's non-zero minimums packed from laser 0 and the one non-255 maximum
    // beyond laser 0 (220, laser 56 in the xml) at laser 44.
    assert_eq!(
        (xml.lasers[0].min_intensity, xml.lasers[0].max_intensity),
        (0, 235)
    );
    assert_eq!(xml.lasers[56].max_intensity, 220);
    let packed: Vec<u8> = xml
        .lasers
        .iter()
        .map(|l| l.min_intensity)
        .filter(|&m| m != 0)
        .collect();
    assert_eq!(packed.len(), 44);
    for (i, l) in yaml.lasers.iter().enumerate() {
        assert_eq!(
            l.min_intensity,
            packed.get(i).copied().unwrap_or(0),
            "yaml laser {i}"
        );
        let expect_max = match i {
            0 => 235,
            44 => 220,
            _ => 255,
        };
        assert_eq!(l.max_intensity, expect_max, "yaml laser {i}");
    }
}

#[test]
fn veloview_files_match_their_yaml_conversions() {
    let pairs = [
        (
            format!("{VELOVIEW}/VLP-16.xml"),
            format!("{ROS}/params/VLP16db.yaml"),
        ),
        (
            format!("{VELOVIEW}/HDL-32.xml"),
            format!("{ROS}/params/32db.yaml"),
        ),
        (
            format!("{ROS}/tests/32db.xml"),
            format!("{ROS}/params/32db.yaml"),
        ),
        (
            format!("{VELOVIEW}/VLP-32c.xml"),
            format!("{ROS}/params/VeloView-VLP-32C.yaml"),
        ),
        (
            format!("{VELOVIEW}/HDL-64.xml"),
            format!("{VALGUR}/HDL-64E_S3-VeloView.yml"),
        ),
        (
            "Kitware__VeloView/share/HDL-64.xml".into(),
            format!("{VALGUR}/HDL-64E_S3-VeloView.yml"),
        ),
        (
            format!("{ROS}/params/VeloView-VLP-32C.yaml"),
            "jerry73204__rust-lidar-utils/velodyne-params/params/VeloView-VLP-32C.yaml".into(),
        ),
    ];
    for (a, b) in pairs {
        let (Some(x), Some(y)) = (load(&a), load(&b)) else {
            continue;
        };
        // velodyne_decoder's yml has no two_pt_correction_available: its near corrections are
        // folded to the far one, where the xml (both near values non-zero) keeps them.
        let folded = b.ends_with("HDL-64E_S3-VeloView.yml");
        assert_same_geometry(&x, &y, &format!("{a} vs {b}"), !folded);
        if folded {
            assert!(x
                .lasers
                .iter()
                .all(|l| l.dist_correction_x != l.dist_correction));
            assert!(y
                .lasers
                .iter()
                .all(|l| l.dist_correction_x == l.dist_correction
                    && l.dist_correction_y == l.dist_correction));
        }
        assert_eq!(x.distance_resolution, y.distance_resolution, "{a} vs {b}");
    }
    if let Some(c) = load(&format!("{VELOVIEW}/VLP-32c.xml")) {
        assert_eq!(c.num_lasers(), 32); // 64 points, 32 enabled
        assert_eq!(c.distance_resolution, Some(0.004));
    }
    if let Some(c) = load(&format!("{VELOVIEW}/VLP-16.xml")) {
        assert_eq!(c.num_lasers(), 16);
    }
}

#[test]
fn db_xml_without_intensities_uses_the_ros_defaults() {
    let Some(c) = load(&format!("{ROS}/tests/test_db_without_intensities.xml")) else {
        return;
    };
    assert_eq!(c.num_lasers(), 64); // no enabled_: every point
    assert_eq!(c.distance_resolution, None); // no distLSB_: model default
    assert!(c.advanced);
    for l in &c.lasers {
        assert_eq!((l.min_intensity, l.max_intensity), (0, 255));
    }
    let l = &c.lasers[0];
    assert!((l.rot_correction - (-5.3328056f64).to_radians()).abs() < 1e-15);
    assert!((l.dist_correction - 1.11).abs() < 1e-12);
    assert!((l.dist_correction_x - 1.18).abs() < 1e-12);
    assert!((l.vert_offset_correction - 0.19736338).abs() < 1e-12);
}

#[test]
fn angles_calibrated_is_not_a_conversion_of_any_db_xml_here() {
    // angles-calibrated.yaml (laser 0: rot −7°, vert −23.02°, dist 0.12 m) derives from upstream's
    // angles.config, not from a db.xml in captures/: no xml here has its laser-0 angles. It must
    // parse (including its repeated `vert_offset_correction: 0` keys).
    let Some(cal) = load(&format!("{ROS}/tests/angles-calibrated.yaml")) else {
        return;
    };
    assert!((cal.lasers[0].rot_correction.to_degrees() - -7.0).abs() < 1e-6);
    assert!((cal.lasers[0].dist_correction - 0.12).abs() < 1e-6);
    for rel in [
        format!("{ROS}/tests/32db.xml"),
        format!("{ROS}/tests/64e_s2.1-sztaki.xml"),
        format!("{ROS}/tests/test_db_without_intensities.xml"),
        format!("{VELOVIEW}/HDL-64.xml"),
        "Kitware__VeloView/share/HDL-64.xml".to_string(),
    ] {
        let Some(x) = load(&rel) else { continue };
        let same = x.lasers.iter().zip(&cal.lasers).all(|(a, b)| {
            (a.vert_correction - b.vert_correction).abs() < 1e-6
                && (a.rot_correction - b.rot_correction).abs() < 1e-6
        });
        assert!(
            !same || x.num_lasers() != cal.num_lasers(),
            "{rel} matches angles-calibrated"
        );
    }
}

#[test]
fn builtins_match_the_manufacturer_files() {
    // Tolerances in radians. ros-drivers' VLP16_hires_db.yaml uses exact multiples of 2/3°
    // (0.66667°) where Velodyne's VeloView file, velodyne_decoder and the built-in use 0.667°.
    let cases = [
        (
            VelodyneModel::Vlp16,
            format!("{ROS}/params/VLP16db.yaml"),
            2e-6,
        ),
        (
            VelodyneModel::Vlp16,
            format!("{VELOVIEW}/VLP-16.xml"),
            1e-12,
        ),
        (
            VelodyneModel::PuckHiRes,
            format!("{VALGUR}/Puck Hi-Res.yml"),
            2e-6,
        ),
        (
            VelodyneModel::PuckHiRes,
            format!("{ROS}/params/VLP16_hires_db.yaml"),
            6e-6,
        ),
        (
            VelodyneModel::Hdl32e,
            format!("{VELOVIEW}/HDL-32.xml"),
            1e-6,
        ),
        (
            VelodyneModel::Hdl32e,
            format!("{ROS}/params/32db.yaml"),
            2e-6,
        ),
        (
            VelodyneModel::Vlp32c,
            format!("{VELOVIEW}/VLP-32c.xml"),
            1e-12,
        ),
        (VelodyneModel::Vlp32c, format!("{NEBULA}/VLP32.yaml"), 2e-6),
        (VelodyneModel::Vlp32c, format!("{VALGUR}/VLP-32C.yml"), 2e-6),
    ];
    for (model, rel, tol) in cases {
        let Some(file) = load(&rel) else { continue };
        let b = builtin(model).unwrap();
        assert_eq!(b.num_lasers(), file.num_lasers(), "{rel}");
        for (x, y) in b.lasers.iter().zip(&file.lasers) {
            let (dv, dr) = (
                x.vert_correction - y.vert_correction,
                x.rot_correction - y.rot_correction,
            );
            assert!(
                dv.abs() <= tol && dr.abs() <= tol,
                "{rel} laser {}: {dv} {dr}",
                x.laser_id
            );
        }
        assert_eq!(b.rings(), file.rings(), "{rel}");
    }
    assert!(builtin(VelodyneModel::Hdl64eS2).is_none());
    assert!(builtin(VelodyneModel::Hdl64eS3).is_none());
    assert!(builtin(VelodyneModel::Vls128).is_none());
}

// ------------------------------------------------------------------------------------------
// Hostile and malformed input. Every case must be an error naming what is wrong, never a panic.

fn yaml_table(n: usize) -> String {
    let mut s = format!("num_lasers: {n}\ndistance_resolution: 0.002\nlasers:\n");
    for i in 0..n {
        s.push_str(&format!(
            "- laser_id: {i}\n  rot_correction: 0.0\n  vert_correction: {}\n",
            (10.0 * i as f64 - 200.0) / 1000.0
        ));
    }
    s
}

fn err(text: &str) -> String {
    match parse_velodyne(text, "hostile") {
        Ok(c) => panic!("accepted: {} lasers", c.num_lasers()),
        Err(e) => e.to_string(),
    }
}

fn expect(text: &str, needles: &[&str]) {
    let e = err(text);
    for n in needles {
        assert!(e.contains(n), "error {e:?} does not mention {n:?}");
    }
}

#[test]
fn the_synthetic_table_is_fine() {
    assert_eq!(
        parse_velodyne(&yaml_table(16), "ok").unwrap().num_lasers(),
        16
    );
}

#[test]
fn empty_and_garbage_texts_are_errors() {
    expect("", &["lasers", "no YAML document"]);
    expect("   \n\n", &["lasers"]);
    expect("42", &["mapping", "number `42`"]);
    expect("just some words", &["mapping", "string"]);
    expect("- 1\n- 2\n", &["mapping", "a list"]);
    expect("foo: bar\n", &["missing key `lasers`"]);
    expect("lasers: 3\n", &["`lasers`", "a list"]);
    expect("lasers: [1, 2", &["YAML syntax error at line"]);
    expect(
        "a: 1\nb: c: d\n",
        &["YAML syntax error at line 2, column 5"],
    );
    expect("a: b: c\n", &["syntax error", "line 1"]);
    expect("\t- x: [\n", &["syntax error"]);
    // Garbage bytes: not UTF-8, with the position of the first bad byte.
    let e = parse_velodyne_bytes(b"lasers:\n  - \xff\xfe\x00", "bin").unwrap_err();
    assert!(
        matches!(
            e,
            CalibError::Syntax {
                line: 2,
                column: 5,
                ..
            }
        ),
        "{e}"
    );
    // Control characters and random printable noise.
    for seed in 0..200u64 {
        let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let bytes: Vec<u8> = (0..200)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                (x >> 24) as u8
            })
            .collect();
        let _ = parse_velodyne_bytes(&bytes, "noise");
        let _ = parse_velodyne(&String::from_utf8_lossy(&bytes), "noise");
    }
}

#[test]
fn laser_entries_are_checked_with_their_position() {
    let t = yaml_table(16);
    // Missing key: names the key and the laser.
    let s = t.replacen("  vert_correction: -0.15\n", "", 1);
    expect(
        &s,
        &[
            "missing key `vert_correction`",
            "lasers[5] (laser_id 5)",
            "line",
        ],
    );
    let s = t.replacen("- laser_id: 3\n", "- rot_correction_typo: 3\n", 1);
    expect(&s, &["missing key `laser_id`", "lasers[3]"]);
    // Wrong types.
    let s = t.replacen("vert_correction: -0.2\n", "vert_correction: abc\n", 1);
    expect(
        &s,
        &[
            "`vert_correction`",
            "lasers[0] (laser_id 0)",
            "line 6",
            "a number",
            "string \"abc\"",
        ],
    );
    let s = t.replacen("vert_correction: -0.2\n", "vert_correction: \"-0.2\"\n", 1);
    expect(&s, &["`vert_correction`", "a number", "string"]);
    let s = t.replacen("vert_correction: -0.2\n", "vert_correction: [1, 2]\n", 1);
    expect(&s, &["`vert_correction`", "a list"]);
    let s = t.replacen("vert_correction: -0.2\n", "vert_correction:\n", 1);
    expect(&s, &["`vert_correction`", "null"]);
    let s = t.replacen("laser_id: 2\n", "laser_id: 2.5\n", 1);
    expect(&s, &["`laser_id`", "lasers[2]", "an integer"]);
    let s = t.replacen("laser_id: 2\n", "laser_id: -2\n", 1);
    expect(&s, &["`laser_id`", "0..=65535"]);
    let s = t.replacen(
        "- laser_id: 4\n",
        "- laser_id: 4\n  two_pt_correction_available: maybe\n",
        1,
    );
    expect(&s, &["`two_pt_correction_available`", "true or false"]);
    let s = t.replacen(
        "- laser_id: 4\n",
        "- laser_id: 4\n  max_intensity: 300\n",
        1,
    );
    expect(&s, &["`max_intensity`", "laser_id 4", "0..=255"]);
    let s = t.replacen(
        "- laser_id: 4\n",
        "- laser_id: 4\n  min_intensity: 50\n  max_intensity: 10\n",
        1,
    );
    expect(&s, &["laser 4", "min_intensity 50 > max_intensity 10"]);
    let s = t.replacen(
        "- laser_id: 7\n  rot_correction: 0.0\n  vert_correction: -0.13\n",
        "- 7\n",
        1,
    );
    expect(&s, &["lasers[7]", "a mapping"]);
}

#[test]
fn non_finite_and_absurd_numbers_are_refused() {
    let t = yaml_table(16);
    for v in [".nan", ".inf", "-.inf", "1e400", "NaN", "inf"] {
        let s = t.replacen(
            "vert_correction: -0.19\n",
            &format!("vert_correction: {v}\n"),
            1,
        );
        expect(&s, &["`vert_correction`", "lasers[1] (laser_id 1)"]);
    }
    let s = t.replacen("vert_correction: -0.19\n", "vert_correction: 1e300\n", 1);
    // The value as written, not in 301 digits.
    expect(&s, &["laser 1", "vert_correction = 1e300 is outside"]);
    let s = t.replacen("rot_correction: 0.0\n", "rot_correction: -1e300\n", 1);
    expect(&s, &["laser 0", "rot_correction"]);
    let s = t.replacen(
        "- laser_id: 9\n",
        "- laser_id: 9\n  dist_correction: 1e300\n",
        1,
    );
    expect(&s, &["laser 9", "dist_correction"]);
    let s = t.replace("distance_resolution: 0.002", "distance_resolution: -1");
    expect(&s, &["distance_resolution"]);
    let s = t.replace("distance_resolution: 0.002", "distance_resolution: .nan");
    expect(&s, &["distance_resolution", "finite"]);
}

#[test]
fn laser_sets_must_be_complete() {
    let t = yaml_table(16);
    // Duplicate id.
    let s = t.replacen("laser_id: 5\n", "laser_id: 4\n", 1);
    expect(&s, &["duplicate laser_id 4", "lasers[5]", "line"]);
    // Gap: ids 0..14 and 16.
    let s = t.replacen("laser_id: 15\n", "laser_id: 16\n", 1);
    expect(&s, &["without gaps", "laser_id 16"]);
    // 17 lasers, with and without a matching num_lasers.
    let s17 = yaml_table(17);
    expect(&s17, &["17", "16, 32, 64 or 128"]);
    expect(
        &s17.replace("num_lasers: 17", "num_lasers: 16"),
        &["`num_lasers`", "17", "found 16"],
    );
    // num_lasers mismatch / wrong type.
    expect(
        &t.replace("num_lasers: 16", "num_lasers: 32"),
        &["`num_lasers`", "expected 16", "found 32"],
    );
    expect(
        &t.replace("num_lasers: 16", "num_lasers: sixteen"),
        &["`num_lasers`", "an integer"],
    );
    // Empty list.
    expect("num_lasers: 0\nlasers: []\n", &["0 entries"]);
}

#[test]
fn yaml_structure_tricks_are_refused() {
    let t = yaml_table(16);
    // Conflicting duplicate keys (identical repeats are accepted, as in angles-calibrated.yaml).
    let s = t.replacen(
        "  rot_correction: 0.0\n",
        "  rot_correction: 0.0\n  rot_correction: 0.1\n",
        1,
    );
    expect(&s, &["`rot_correction` is given twice", "line"]);
    let s = t.replacen(
        "  rot_correction: 0.0\n",
        "  rot_correction: 0.0\n  rot_correction: 0.0\n",
        1,
    );
    assert!(parse_velodyne(&s, "dup").is_ok());
    // Aliases (the billion-laughs vector) and anchors.
    expect("a: &x [1, 2]\nb: *x\n", &["anchors"]);
    let mut laughs = String::from("l0: &l0 [lol, lol]\n");
    for i in 1..30 {
        laughs.push_str(&format!("l{i}: &l{i} [*l{p}, *l{p}, *l{p}]\n", p = i - 1));
    }
    expect(&laughs, &["anchors"]);
    // Two documents.
    expect(&format!("{t}---\n{t}"), &["one YAML document"]);
    // Deep nesting, block and flow.
    let deep_flow = format!("lasers: {}{}", "[".repeat(100_000), "]".repeat(100_000));
    expect(&deep_flow, &["line 1"]);
    let mut deep_block = String::from("lasers:\n");
    for i in 0..2000 {
        deep_block.push_str(&" ".repeat(i));
        deep_block.push_str("- \n");
    }
    expect(&deep_block, &["nesting deeper than 16 levels", "line 17"]);
    let deep_map = (0..2000)
        .map(|i| format!("{}k:\n", " ".repeat(i)))
        .collect::<String>();
    expect(&deep_map, &["nesting deeper than 16 levels"]);
    // Wide: many keys or many nodes in a text under the size cap.
    let wide_map: String = (0..300_000).map(|i| format!("k{i}: 1\n")).collect();
    assert!(wide_map.len() < MAX_CALIB_BYTES);
    expect(
        &wide_map,
        &["more than 256 keys in one mapping", "line 257"],
    );
    let long_list = format!("lasers:\n{}", "- 1\n".repeat(1_000_000));
    expect(&long_list, &["more than 100000 YAML nodes"]);
    // Complex keys.
    expect("? [a, b]\n: c\n", &["keys"]);
    // Tags are ignored, the value still has to be a number.
    let s = t.replacen("vert_correction: -0.2\n", "vert_correction: !!str abc\n", 1);
    expect(&s, &["`vert_correction`"]);
}

#[test]
fn oversized_input_is_refused_before_parsing() {
    let mut big = yaml_table(16);
    while big.len() <= 10 << 20 {
        big.push_str("# padding padding padding padding padding padding padding padding\n");
    }
    let n = big.len();
    assert!(
        matches!(parse_velodyne(&big, "big"), Err(CalibError::TooLarge(len, max)) if len == n && max == MAX_CALIB_BYTES)
    );
    assert!(matches!(
        ros_yaml::parse(&big, "big"),
        Err(CalibError::TooLarge(..))
    ));
    assert!(matches!(
        veloview_xml::parse(&big, "big"),
        Err(CalibError::TooLarge(..))
    ));
    assert!(matches!(
        parse_velodyne_bytes(big.as_bytes(), "big"),
        Err(CalibError::TooLarge(..))
    ));
    let xml = format!("<DB>{}</DB>", " ".repeat(10 << 20));
    assert!(matches!(
        parse_velodyne(&xml, "big"),
        Err(CalibError::TooLarge(..))
    ));
    // Just under the cap, a long but otherwise valid file is fine.
    let mut padded = yaml_table(16);
    while padded.len() < MAX_CALIB_BYTES - 100 {
        padded.push_str("# padding\n");
    }
    assert!(parse_velodyne(&padded, "padded").is_ok());
}

fn xml_db(n: usize, px_extra: &str) -> String {
    let mut s = String::from(
        "<?xml version=\"1.0\" encoding=\"UTF-8\" standalone=\"yes\" ?>\n\
         <!DOCTYPE boost_serialization>\n\
         <boost_serialization signature=\"serialization::archive\" version=\"4\">\n\
         <DB class_id=\"0\" tracking_level=\"1\" version=\"0\" object_id=\"_0\">\n\
         \t<distLSB_>0.2</distLSB_>\n\t<points_>\n",
    );
    for i in 0..n {
        s.push_str(&format!(
            "\t\t<item><px><id_>{i}</id_><rotCorrection_>0</rotCorrection_>\
             <vertCorrection_>{}</vertCorrection_>{px_extra}</px></item>\n",
            -15.0 + 2.0 * i as f64
        ));
    }
    s.push_str("\t</points_>\n</DB>\n</boost_serialization>\n");
    s
}

#[test]
fn xml_errors_name_element_and_line() {
    assert_eq!(
        parse_velodyne(&xml_db(16, ""), "ok").unwrap().num_lasers(),
        16
    );
    // Missing points_.
    let s = xml_db(16, "");
    let start = s.find("\t<points_>").unwrap();
    let end = s.find("</DB>").unwrap();
    let no_points = format!("{}{}", &s[..start], &s[end..]);
    expect(&no_points, &["missing key `DB/points_`"]);
    // No DB at all.
    expect(
        "<?xml version=\"1.0\"?><foo/>",
        &["missing key `DB`", "<foo>"],
    );
    // Non-numeric values.
    let bad = s.replacen(
        "<vertCorrection_>-11</vertCorrection_>",
        "<vertCorrection_>abc</vertCorrection_>",
        1,
    );
    expect(
        &bad,
        &[
            "`vertCorrection_`",
            "item 2 (laser id 2)",
            "line 9",
            "\"abc\"",
        ],
    );
    let bad = s.replacen(
        "<rotCorrection_>0</rotCorrection_>",
        "<rotCorrection_>NaN</rotCorrection_>",
        1,
    );
    expect(&bad, &["`rotCorrection_`", "laser id 0"]);
    let bad = s.replacen(
        "<rotCorrection_>0</rotCorrection_>",
        "<rotCorrection_></rotCorrection_>",
        1,
    );
    expect(&bad, &["`rotCorrection_`", "nothing"]);
    let bad = s.replacen("<distLSB_>0.2</distLSB_>", "<distLSB_>0.2cm</distLSB_>", 1);
    expect(&bad, &["`DB/distLSB_`", "line 5"]);
    let bad = s.replacen(
        "<rotCorrection_>0</rotCorrection_>",
        "<rotCorrection_>1e300</rotCorrection_>",
        1,
    );
    expect(&bad, &["laser 0", "rot_correction"]);
    // Missing required element, bad id, duplicate id, 17 lasers.
    let bad = s.replacen("<vertCorrection_>-15</vertCorrection_>", "", 1);
    expect(
        &bad,
        &["missing key `vertCorrection_`", "laser id 0", "line"],
    );
    let bad = s.replacen("<id_>3</id_>", "<id_>3.5</id_>", 1);
    expect(&bad, &["`id_`", "whole number"]);
    let bad = s.replacen("<id_>3</id_>", "<id_>2</id_>", 1);
    expect(&bad, &["duplicate laser id 2", "item 3", "line"]);
    expect(&xml_db(17, ""), &["17"]);
    let bad =
        s.replacen("<item><px>", "<item><nopx>", 1)
            .replacen("</px></item>", "</nopx></item>", 1);
    expect(&bad, &["missing key `px`", "item 0"]);
    // Malformed XML reports its position.
    let e = parse_velodyne("<DB>\n  <points_>\n</DB>", "bad").unwrap_err();
    assert!(
        matches!(
            e,
            CalibError::Syntax {
                format: "XML",
                line: 3,
                ..
            }
        ),
        "{e}"
    );
    // enabled_ / intensities shorter than the laser table.
    let bad = s.replacen(
        "\t<points_>",
        "\t<enabled_><count>2</count><item>1</item><item>1</item></enabled_>\n\t<points_>",
        1,
    );
    expect(&bad, &["DB/enabled_", "laser 2"]);
    let bad = s.replacen(
        "\t<points_>",
        "\t<maxIntensity_><count>1</count><item>300</item></maxIntensity_>\n\t<points_>",
        1,
    );
    expect(&bad, &["DB/maxIntensity_", "0..=255"]);
}

#[test]
fn hostile_xml_is_refused() {
    // Billion laughs with internal entities.
    let mut dtd = String::from("<?xml version=\"1.0\"?>\n<!DOCTYPE DB [\n<!ENTITY l0 \"lol\">\n");
    for i in 1..12 {
        let p = format!("&l{};", i - 1);
        dtd.push_str(&format!("<!ENTITY l{i} \"{}\">\n", p.repeat(10)));
    }
    dtd.push_str("]>\n<DB><distLSB_>&l11;</distLSB_><points_/></DB>\n");
    let _ = err(&dtd);
    // External entity: never fetched.
    let ext =
        "<?xml version=\"1.0\"?>\n<!DOCTYPE DB [<!ENTITY x SYSTEM \"file:///etc/passwd\">]>\n\
               <DB><distLSB_>&x;</distLSB_></DB>";
    let _ = err(ext);
    // Deep nesting.
    let deep = format!(
        "<DB>{}{}</DB>",
        "<a>".repeat(100_000),
        "</a>".repeat(100_000)
    );
    let _ = err(&deep);
    let deep_points = format!(
        "<DB><points_><item><px>{}{}</px></item></points_></DB>",
        "<id_>".repeat(50_000),
        "</id_>".repeat(50_000)
    );
    let _ = err(&deep_points);
    // Very many nodes.
    let many = format!("<DB>{}</DB>", "<x/>".repeat(300_000));
    expect(&many, &["XML syntax error"]);
    // Text that only looks like XML.
    expect("<", &["XML syntax error"]);
    expect("<DB", &["XML syntax error"]);
    expect("<DB></DB>", &["DB/points_"]);
    expect("<DB><points_/></DB>", &["no enabled laser"]);
}

#[test]
fn mutated_real_files_never_panic() {
    // A deterministic smoke test: flip, drop and duplicate bytes of real files.
    let files = [
        format!("{ROS}/params/64e_s2.1-sztaki.yaml"),
        format!("{ROS}/tests/angles.yaml"),
        format!("{ROS}/tests/64e_s2.1-sztaki.xml"),
        format!("{VELOVIEW}/VLP-16.xml"),
    ];
    for rel in files {
        let Some(orig) = text(&rel) else { continue };
        let orig = orig.into_bytes();
        let mut x: u64 = 0x2545_F491_4F6C_DD1D;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for _ in 0..150 {
            let mut b = orig.clone();
            for _ in 0..1 + next() % 8 {
                let i = (next() as usize) % b.len();
                match next() % 4 {
                    0 => b[i] = next() as u8,
                    1 => {
                        b.remove(i);
                    }
                    2 => {
                        let alphabet = b"<>:-[]{}&*!\"'\n 0.9e";
                        b.insert(i, alphabet[(next() as usize) % alphabet.len()]);
                    }
                    _ => {
                        let j = (i + (next() as usize) % 200).min(b.len());
                        let chunk = b[i..j].to_vec();
                        b.splice(i..i, chunk);
                    }
                }
            }
            let _ = parse_velodyne_bytes(&b, "mutant");
        }
    }
}

#[test]
fn parsed_lasers_are_sorted_by_id() {
    // Entries in reverse order are accepted and sorted.
    let mut s = String::from("lasers:\n");
    for i in (0..16).rev() {
        s.push_str(&format!(
            "- {{laser_id: {i}, rot_correction: 0, vert_correction: {}}}\n",
            i as f64 * 0.01
        ));
    }
    let c = parse_velodyne(&s, "rev").unwrap();
    let ids: Vec<u16> = c
        .lasers
        .iter()
        .map(|l: &LaserCalibration| l.laser_id)
        .collect();
    assert_eq!(ids, (0..16).collect::<Vec<u16>>());
    assert_eq!(c.distance_resolution, None);
}
