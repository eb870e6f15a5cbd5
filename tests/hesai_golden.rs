//! Fidelity against tier4/nebula on every real Hesai capture in `../shared/captures`
//! (`captures/NEBULA.md`: which scan each expected PCD is, nebula's configuration, its axes).
//!
//! Each converted pcap is streamed through [`HesaiStream`] from its first packet, with cut 0°;
//! the sweep emitted when the scan's last packet (NEBULA.md, "PCD = scan of") has been pushed is
//! compared with the expected PCD (nebula's `(x, y, z)` mapped to ringscan's `(y, −x, z)`):
//!
//! - **nebula's filtering** ([`HesaiOptions::nebula`]: the model's range, the config's range,
//!   the 0.1 m dual-return threshold): the same number of points and, in order, each within
//!   0.1 mm;
//! - **ringscan's defaults** (no range clamp, only identical returns merged): at least 99.9 % of
//!   the expected points have a decoded point within 1 mm and the counts differ by at most 0.5 %
//!   once the points outside nebula's test range are set apart (the QT128's returns under
//!   0.3 m, which its sensor rates and ringscan keeps);
//! - that no near limit the same for every model fits all six scans' counts: nebula's test
//!   ranges keep the QT64's and XT32's returns under 0.3 m and cut the QT128's.
//!
//! The figures are printed (`cargo test --test hesai_golden -- --nocapture`) and written up in
//! docs/hesai-figures.md.

mod common;

use std::collections::HashMap;
use std::path::Path;

use ringscan::point::Point;
use ringscan::sensor::hesai::family::parse_hesai_calibration;
use ringscan::sensor::hesai::{HesaiConfig, HesaiModel, HesaiOptions, HesaiStream};

const GT: &str = "tier4__nebula/src/nebula_hesai/nebula_hesai/test_resources/decoder_ground_truth";
const CALIB: &str = "tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration";

struct Case {
    model: HesaiModel,
    pcap: &'static str,
    pcd: &'static str,
    csv: &'static str,
    /// The packets whose points make up the expected scan (0-based pcap records).
    packets: (usize, usize),
    /// nebula's config range, m.
    range: (f32, f32),
    points: usize,
}

const CASES: [Case; 6] = [
    Case {
        model: HesaiModel::Pandar40P,
        pcap: "40p/1673400149412331409/1673400149412331409_0.pcap",
        pcd: "40p/1673400149711850138.pcd",
        csv: "Pandar40P.csv",
        packets: (714, 1082),
        range: (0.3, 200.0),
        points: 56_762,
    },
    Case {
        model: HesaiModel::Pandar64,
        pcap: "64/1673403880599376836/1673403880599376836_0.pcap",
        pcd: "64/1673403880898440686.pcd",
        csv: "Pandar64.csv",
        packets: (1190, 1807),
        range: (0.3, 200.0),
        points: 93_591,
    },
    Case {
        model: HesaiModel::PandarQt64,
        pcap: "qt64/1673401195788312575/1673401195788312575_0.pcap",
        pcd: "qt64/1673401196087570870.pcd",
        csv: "PandarQT64.csv",
        packets: (593, 905),
        range: (0.1, 60.0),
        points: 34_158,
    },
    Case {
        model: HesaiModel::PandarQt128,
        pcap: "qt128/1730273789074637152/1730273789074637152_0.pcap",
        pcd: "qt128/1730273789174759609.pcd",
        csv: "PandarQT128.csv",
        packets: (855, 1798),
        range: (0.3, 300.0),
        points: 73_560,
    },
    Case {
        model: HesaiModel::PandarXt32,
        pcap: "xt32/1673400677802009732/1673400677802009732_0.pcap",
        pcd: "xt32/1673400678101968885.pcd",
        csv: "PandarXT32.csv",
        packets: (1498, 1998),
        range: (0.05, 120.0),
        points: 63_021,
    },
    Case {
        model: HesaiModel::PandarXt32m,
        pcap: "xt32m/1660893203042895158/1660893203042895158_0.pcap",
        pcd: "xt32m/1660893203292679064.pcd",
        csv: "PandarXT32M.csv",
        packets: (1541, 1813),
        range: (0.5, 300.0),
        points: 13_574,
    },
];

/// Reads a binary PCD of `x y z` float32 fields (the format NEBULA.md describes).
fn read_pcd(path: &Path) -> Vec<[f32; 3]> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut off = 0;
    let mut points = None;
    let mut fields = String::new();
    loop {
        let end = bytes[off..]
            .iter()
            .position(|&b| b == b'\n')
            .expect("PCD header line")
            + off;
        let line = std::str::from_utf8(&bytes[off..end]).expect("ASCII header");
        off = end + 1;
        if let Some(v) = line.strip_prefix("POINTS ") {
            points = Some(v.trim().parse::<usize>().unwrap());
        }
        if let Some(v) = line.strip_prefix("FIELDS ") {
            fields = v.trim().to_string();
        }
        if line.starts_with("DATA") {
            assert_eq!(line.trim(), "DATA binary", "{}", path.display());
            break;
        }
    }
    assert_eq!(fields, "x y z", "{}", path.display());
    let n = points.expect("POINTS");
    let data = &bytes[off..];
    assert_eq!(data.len(), n * 12, "{}", path.display());
    data.chunks_exact(12)
        .map(|r| {
            let f = |i: usize| f32::from_le_bytes([r[i], r[i + 1], r[i + 2], r[i + 3]]);
            [f(0), f(4), f(8)]
        })
        .collect()
}

/// nebula's (x, y, z) in ringscan's frame.
fn to_ringscan(p: [f32; 3]) -> [f64; 3] {
    [f64::from(p[1]), -f64::from(p[0]), f64::from(p[2])]
}

fn dist(a: [f64; 3], p: &Point) -> f64 {
    let d = [
        a[0] - f64::from(p.x),
        a[1] - f64::from(p.y),
        a[2] - f64::from(p.z),
    ];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// Decodes the capture and returns the sweep emitted once the scan's last packet is pushed.
fn scan_of(root: &Path, case: &Case, options: HesaiOptions) -> Vec<Point> {
    let calib_path = root.join(CALIB).join(case.csv);
    let calib = parse_hesai_calibration(&std::fs::read(&calib_path).unwrap())
        .expect("a Hesai CSV")
        .unwrap();
    let mut cfg = HesaiConfig::new(Some(calib), case.csv);
    cfg.options = options;
    cfg.cut_cdeg = Some(0);
    let mut stream = HesaiStream::new(cfg);
    let packets = common::datagrams(&root.join(GT).join(case.pcap));
    let mut found: Option<Vec<Point>> = None;
    for (i, (t, _, payload)) in packets.iter().enumerate() {
        stream
            .push(*t, payload, &mut |sw, _| {
                if found.is_none() && i >= case.packets.1 {
                    found = Some(sw.points.clone());
                }
            })
            .unwrap();
        if found.is_some() {
            break;
        }
    }
    assert_eq!(stream.facts().model, Some(case.model), "{}", case.pcap);
    assert_eq!(stream.stats().malformed, 0, "{}", case.pcap);
    found.unwrap_or_else(|| {
        panic!(
            "{}: no sweep completed after packet {}",
            case.pcap, case.packets.1
        )
    })
}

#[test]
fn nebula_filtering_matches_one_to_one() {
    let Some(root) = common::captures() else {
        return;
    };
    for case in &CASES {
        let expected = read_pcd(&root.join(GT).join(case.pcd));
        assert_eq!(expected.len(), case.points);
        let got = scan_of(
            &root,
            case,
            HesaiOptions::nebula(case.range.0, case.range.1),
        );
        let mut max_err = 0f64;
        let n = got.len().min(expected.len());

        for i in 0..n {
            max_err = max_err.max(dist(to_ringscan(expected[i]), &got[i]));
        }
        println!(
            "{:>12} nebula filtering: {} points (expected {}), in order max |Δxyz| {:.3e} m",
            case.model.name(),
            got.len(),
            expected.len(),
            max_err
        );
        assert_eq!(got.len(), expected.len(), "{}", case.pcd);
        assert!(max_err <= 1e-4, "{}: max error {max_err} m", case.pcd);
    }
}

#[test]
fn ringscan_defaults_match_within_1mm() {
    let Some(root) = common::captures() else {
        return;
    };
    let mut failures = Vec::new();
    for case in &CASES {
        let expected = read_pcd(&root.join(GT).join(case.pcd));
        let got = scan_of(&root, case, HesaiOptions::default());
        // Grid of decoded points, 1 cm cells.
        let cell = |v: f64| (v / 0.01).floor() as i64;
        let mut grid: HashMap<(i64, i64, i64), Vec<usize>> = HashMap::new();
        for (i, p) in got.iter().enumerate() {
            let k = (
                cell(f64::from(p.x)),
                cell(f64::from(p.y)),
                cell(f64::from(p.z)),
            );
            grid.entry(k).or_default().push(i);
        }
        let mut matched = 0usize;
        for e in &expected {
            let a = to_ringscan(*e);
            let (cx, cy, cz) = (cell(a[0]), cell(a[1]), cell(a[2]));
            let mut ok = false;
            'search: for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        if let Some(v) = grid.get(&(cx + dx, cy + dy, cz + dz)) {
                            if v.iter().any(|&i| dist(a, &got[i]) <= 1e-3) {
                                ok = true;
                                break 'search;
                            }
                        }
                    }
                }
            }
            matched += usize::from(ok);
        }
        let rate = matched as f64 / expected.len() as f64;
        let count_diff = (got.len() as f64 - expected.len() as f64) / expected.len() as f64;
        // The one difference of the defaults that changes counts beyond the dual-return rule:
        // nebula's test configuration narrows the range beyond the model's own (QT128: 0.3 m
        // instead of 0.05 m). Those points are counted apart.
        let outside_config = got
            .iter()
            .filter(|p| {
                let r = (p.x * p.x + p.y * p.y + p.z * p.z).sqrt();
                r < case.range.0 * 0.999_999 || r > case.range.1 * 1.000_001
            })
            .count();
        let inside_diff = (got.len() as f64 - outside_config as f64 - expected.len() as f64)
            / expected.len() as f64;
        println!(
            "{:>12} defaults: {} points (expected {}, {:+.3} %; {} outside nebula's config range, \
             {:+.3} % without them), {:.4} % of expected within 1 mm",
            case.model.name(),
            got.len(),
            expected.len(),
            100.0 * count_diff,
            outside_config,
            100.0 * inside_diff,
            100.0 * rate
        );
        if rate < 0.999 || inside_diff.abs() > 0.005 {
            failures.push(format!(
                "{}: {:.4} % matched, count {:+.3} %",
                case.pcd,
                100.0 * rate,
                100.0 * count_diff
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Why the defaults keep the QT128's returns under 0.3 m (docs/hesai-figures.md §1): nebula's
/// expected clouds disagree with each other about the near band, so no default that is the
/// same rule for every model reproduces all six counts. The QT64 and XT32 expected clouds keep
/// their returns under 0.3 m (a fifth of each cloud: the mount, as for the QT128), the QT128's
/// cuts them; only nebula's per-capture test configurations, which a default cannot know,
/// give all six. This checks that claim on the data, for every near limit applied on top of
/// each model's own range, and for nebula's shipped per-model parameter files.
#[test]
fn no_single_near_limit_fits_every_nebula_scan() {
    let Some(root) = common::captures() else {
        return;
    };
    let radius = |p: &Point| (p.x * p.x + p.y * p.y + p.z * p.z).sqrt();
    let mut decoded = Vec::new();
    for case in &CASES {
        let expected = read_pcd(&root.join(GT).join(case.pcd));
        let near = expected
            .iter()
            .filter(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() < 0.3 * 0.999_999)
            .count();
        let got = scan_of(&root, case, HesaiOptions::default());
        let got_near = got.iter().filter(|p| radius(p) < 0.3 * 0.999_999).count();
        println!(
            "{:>12}: expected cloud {} points, {} under 0.3 m ({:.1} %); decoded {} under 0.3 m",
            case.model.name(),
            expected.len(),
            near,
            100.0 * near as f64 / expected.len() as f64,
            got_near
        );
        decoded.push((case, expected.len(), got));
    }
    // Count error of each model under a rule giving each model a near limit (m), on top of
    // its own measuring range (which the default points already respect).
    let fits = |limit: &dyn Fn(&Case) -> f32| -> Vec<(&'static str, f64)> {
        decoded
            .iter()
            .map(|(case, expected, got)| {
                let l = limit(case) * 0.999_999;
                let n = got.iter().filter(|p| radius(p) >= l).count();
                (
                    case.model.name(),
                    (n as f64 - *expected as f64) / *expected as f64,
                )
            })
            .filter(|(_, e)| e.abs() > 0.005)
            .collect()
    };
    for cm in 0..=50u8 {
        let l = f32::from(cm) / 100.0;
        let misfits = fits(&|_| l);
        assert!(
            !misfits.is_empty(),
            "a near limit of {l} m for every model fits all six nebula scans: \
             docs/hesai-figures.md §1 is wrong"
        );
        if cm % 5 == 0 {
            println!(
                "near limit {l:.2} m for every model: count off by more than 0.5 % for {misfits:?}"
            );
        }
    }
    // nebula's own shipped defaults (nebula_hesai/config/*.param.yaml at 606ac41f: min_range
    // 0.3 m, XT16 / XT32 0.05 m) do not reproduce its test configurations either.
    let shipped = |c: &Case| match c.model {
        HesaiModel::PandarXt32 => 0.05,
        _ => 0.3,
    };
    let misfits = fits(&shipped);
    println!("nebula's shipped min_range per model: off by more than 0.5 % for {misfits:?}");
    assert!(!misfits.is_empty());
    // The test configurations themselves fit (the defaults test checks the rest of the match).
    assert!(fits(&|c| c.range.0).is_empty());
}
