//! Fidelity against velodyne_decoder on every real Velodyne capture in `../shared/captures`.
//!
//! For every golden frame, the packets `packet_first..=packet_last` are decoded as one batch
//! (the reference's own frame cut), and compared:
//! - every frame: point count, `ring_counts`, `return_type_counts` (after the DESIGN.md
//!   mapping 1→0, 3→0, 2→1), sums of x, y, z, intensity and time within tolerance;
//! - frames with a binary dump: point by point, in order: xyz within 1 mm + range·sin(0.01°)
//!   (the reference rounds the interpolated azimuth to 0.01°), same ring, same return, time
//!   relative to the frame's last packet within 1 µs; at least 99.9 % of points must match.
//!
//! The same frames are checked with the packets of nebula's `.db3` bags the two converted pcaps
//! come from (read by `source::bag`), so a bag decodes to the reference's points too.
//!
//! The figures are printed (`cargo test --test velodyne_golden -- --nocapture`).

mod common;

use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::VelodyneDecoder;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::DecodeOptions;
use ringscan::time::toh_delta_us;
use serde_json::Value;

const SIN_001_DEG: f64 = 1.745_329_1e-4; // sin(0.01°)

#[derive(Default, Debug)]
struct Figures {
    frames: usize,
    points: usize,
    binary_points: usize,
    binary_matched: usize,
    max_xyz_err_m: f64,
    max_xyz_err_excess_m: f64,
    max_t_err_us: f64,
}

fn golden_files(root: &std::path::Path) -> Vec<std::path::PathBuf> {
    let idx: Value =
        serde_json::from_slice(&std::fs::read(root.join("golden/index.json")).unwrap()).unwrap();
    let mut out = Vec::new();
    let list = idx
        .get("goldens")
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    for g in list {
        if g.get("reference").and_then(Value::as_str) != Some("velodyne_decoder") {
            continue;
        }
        let p = g.get("golden").and_then(Value::as_str).unwrap();
        out.push(root.join("golden").join(p));
    }
    out
}

/// `bag`: take the packets from this bag instead of the golden's capture.
fn check_capture(
    root: &std::path::Path,
    golden_path: &std::path::Path,
    bag: Option<&std::path::Path>,
) -> Figures {
    let g: Value = serde_json::from_slice(&std::fs::read(golden_path).unwrap()).unwrap();
    let capture = root.join(g["capture"].as_str().unwrap());
    let cfg = &g["config"];
    let model = VelodyneModel::from_id(cfg["model"].as_str().unwrap()).expect("model name");
    let calib_path = root.join(cfg["calibration"].as_str().unwrap());
    let calib = parse_velodyne(
        &std::fs::read_to_string(&calib_path).unwrap(),
        "golden calibration",
    )
    .unwrap();

    let datagrams = match bag {
        Some(b) => common::bag_datagrams(b),
        None => common::datagrams(&capture),
    };
    let packets: Vec<(i64, Vec<u8>)> = datagrams
        .into_iter()
        .filter(|(_, _, p)| p.len() == 1206)
        .map(|(t, _, p)| (t, p))
        .collect();
    assert_eq!(
        packets.len() as u64,
        g["input"]["data_packets"].as_u64().unwrap(),
        "{}",
        capture.display()
    );

    let mode = ReturnMode::from_byte(packets[0].1[1204]).unwrap_or(ReturnMode::Strongest);
    let dec = VelodyneDecoder::new(model, mode, &calib, DecodeOptions::default()).unwrap();
    let golden_dir = golden_path.parent().unwrap();
    let mut fig = Figures::default();
    let mut points = Vec::new();
    for f in g["frames"].as_array().unwrap() {
        let first = f["packet_first"].as_u64().unwrap() as usize;
        let last = f["packet_last"].as_u64().unwrap() as usize;
        let toh_first = DataPacket::new(&packets[first].1).unwrap().timestamp_us();
        let toh_last = DataPacket::new(&packets[last].1).unwrap().timestamp_us();
        points.clear();
        for (_, bytes) in &packets[first..=last] {
            let p = DataPacket::new(bytes).unwrap();
            let t_base = toh_delta_us(toh_first, p.timestamp_us()) * 1_000;
            dec.decode(&p, t_base, &mut points);
        }
        // Our time relative to the frame's last packet stamp, seconds.
        let shift_s = toh_delta_us(toh_last, toh_first) as f64 * 1e-6;
        let rel_time = |t: u32| f64::from(t) * 1e-9 + shift_s;
        let idx = f["index"].as_u64().unwrap();
        let n = f["points"].as_u64().unwrap() as usize;
        assert_eq!(
            points.len(),
            n,
            "{} frame {idx}: point count",
            capture.display()
        );
        fig.frames += 1;
        fig.points += n;

        let mut rings = vec![0u64; calib.num_lasers()];
        let (mut ret0, mut ret1) = (0u64, 0u64);
        let (mut sx, mut sy, mut sz, mut si, mut st, mut tol) =
            (0f64, 0f64, 0f64, 0f64, 0f64, 0f64);
        for p in &points {
            rings[usize::from(p.ring)] += 1;
            if p.ret == 0 {
                ret0 += 1
            } else {
                ret1 += 1
            }
            sx += f64::from(p.x);
            sy += f64::from(p.y);
            sz += f64::from(p.z);
            si += f64::from(p.intensity);
            st += rel_time(p.t);
            let r =
                (f64::from(p.x).powi(2) + f64::from(p.y).powi(2) + f64::from(p.z).powi(2)).sqrt();
            tol += 1e-3 + r * SIN_001_DEG;
        }
        let gr: Vec<u64> = f["ring_counts"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        assert_eq!(rings, gr, "{} frame {idx}: ring_counts", capture.display());
        let rtc = &f["return_type_counts"];
        let c = |k: &str| rtc.get(k).and_then(Value::as_u64).unwrap_or(0);
        assert_eq!(
            (ret0, ret1),
            (c("1") + c("3"), c("2")),
            "{} frame {idx}: returns",
            capture.display()
        );
        let sum = &f["sum"];
        for (name, ours, t) in [
            ("x", sx, tol),
            ("y", sy, tol),
            ("z", sz, tol),
            ("time", st, n as f64 * 1e-6),
        ] {
            let theirs = sum[name].as_f64().unwrap();
            assert!(
                (ours - theirs).abs() <= t,
                "{} frame {idx}: sum {name} {ours} vs {theirs} (tol {t})",
                capture.display()
            );
        }
        assert_eq!(
            si,
            sum["intensity"].as_f64().unwrap(),
            "{} frame {idx}: intensity sum",
            capture.display()
        );

        if let Some(bin) = f.get("binary").and_then(Value::as_str) {
            let recs = common::read_f32_records(&golden_dir.join(bin), 8);
            assert_eq!(recs.len(), n);
            for (p, r) in points.iter().zip(&recs) {
                fig.binary_points += 1;
                let d = ((f64::from(p.x) - f64::from(r[0])).powi(2)
                    + (f64::from(p.y) - f64::from(r[1])).powi(2)
                    + (f64::from(p.z) - f64::from(r[2])).powi(2))
                .sqrt();
                let range =
                    (f64::from(r[0]).powi(2) + f64::from(r[1]).powi(2) + f64::from(r[2]).powi(2))
                        .sqrt();
                let allowed = 1e-3 + range * SIN_001_DEG;
                let dt_us = (rel_time(p.t) - f64::from(r[4])).abs() * 1e6;
                let ret = match r[7] as i32 {
                    2 => 1,
                    _ => 0,
                };
                fig.max_xyz_err_m = fig.max_xyz_err_m.max(d);
                fig.max_xyz_err_excess_m = fig.max_xyz_err_excess_m.max(d - allowed);
                fig.max_t_err_us = fig.max_t_err_us.max(dt_us);
                let ok = d <= allowed
                    && f32::from(p.ring) == r[6]
                    && u8::try_from(ret).unwrap() == p.ret
                    && p.intensity == r[3]
                    && dt_us <= 1.0;
                if ok {
                    fig.binary_matched += 1;
                }
            }
        }
    }
    fig
}

#[test]
fn every_velodyne_capture_matches_velodyne_decoder() {
    let Some(root) = common::captures() else {
        return;
    };
    let files = golden_files(&root);
    assert!(
        files.len() >= 7,
        "expected the 7 Velodyne goldens, found {}",
        files.len()
    );
    println!("| capture | frames | points | dumped points | matched | max |Δxyz| mm | max Δt µs |");
    println!("|---|---|---|---|---|---|---|");
    for gp in files {
        let fig = check_capture(&root, &gp, None);
        let name = gp
            .file_name()
            .unwrap()
            .to_string_lossy()
            .replace(".golden.json", "");
        let pct = 100.0 * fig.binary_matched as f64 / fig.binary_points.max(1) as f64;
        println!(
            "| {name} | {} | {} | {} | {} ({pct:.4} %) | {:.3} | {:.4} |",
            fig.frames,
            fig.points,
            fig.binary_points,
            fig.binary_matched,
            fig.max_xyz_err_m * 1e3,
            fig.max_t_err_us
        );
        assert!(fig.binary_points > 0, "{name}: no dumped frame compared");
        assert!(
            pct >= 99.9,
            "{name}: only {pct:.3} % of points match ({fig:?})"
        );
    }
}

#[test]
fn nebula_bags_match_velodyne_decoder() {
    let Some(root) = common::captures() else {
        return;
    };
    let mut checked = 0;
    for gp in golden_files(&root) {
        let g: Value = serde_json::from_slice(&std::fs::read(&gp).unwrap()).unwrap();
        let capture = root.join(g["capture"].as_str().unwrap());
        let bag = capture.with_extension("db3");
        if !bag.is_file() {
            continue;
        }
        // The directory (metadata.yaml + .db3) and the bare .db3.
        for input in [capture.parent().unwrap(), bag.as_path()] {
            let fig = check_capture(&root, &gp, Some(input));
            let pct = 100.0 * fig.binary_matched as f64 / fig.binary_points.max(1) as f64;
            println!(
                "{}: {} frames, {} points, {} of {} dumped points match ({pct:.4} %)",
                input.display(),
                fig.frames,
                fig.points,
                fig.binary_matched,
                fig.binary_points
            );
            assert!(pct >= 99.9, "{}: only {pct:.3} % match", input.display());
            checked += 1;
        }
    }
    assert_eq!(
        checked, 4,
        "the VLP-16 and VLP-32C bags, as directory and as .db3"
    );
}
