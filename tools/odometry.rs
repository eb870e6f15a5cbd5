//! Runs ringscan's LiDAR odometry over a capture's sweeps (or over sweeps dumped to a file)
//! and writes the trajectory (TUM) and per-sweep timings, for side-by-side runs with KISS-ICP
//! (`tools/odometry_kiss.sh`) and for the simulator evaluation (`tools/odometry_eval.py`).
//!
//! ```text
//! cargo run --release --example odometry -- --model vlp16 --calib VLP16db.yaml \
//!     [--max-range 100] [--dump sweeps.bin] [--repeat 5] [--no-degeneracy] [--deskew] \
//!     [--timed [--deskew-passes 1-4]] [--point-to-plane] [--voxel M] \
//!     [--keyframe-m 0] [--skip N] [--trajectory out.tum] [--report out.json] capture.pcap
//! cargo run --release --example odometry -- --sweeps sweeps.bin [...]   # read a dump instead
//! ```
//! - Sweeps come from [`ringscan::sensor::velodyne::VelodyneStream`] (the CLI's cut: azimuth wrap at
//!   0°), in order; fragments cut by the capture's end (fewer than 10 % of the points of the
//!   largest sweep) are left out and counted.
//! - `--dump FILE` writes the sweeps as decoded: per sweep `i64 stamp_ns`, `u64 n`, then `n`
//!   records of little-endian `f32` x, y, z (m, sensor frame) and `u32` t (ns after the
//!   sweep's timestamp).
//! - `--deskew`: each sweep is first deskewed (`ringscan::deskew`, constant velocity from
//!   `Odometry::last_motion`) to the middle of its span, and registered with the stamp of
//!   that middle; the poses are then those of the sensor at mid-sweep. (Deskewing to the
//!   start or the end feeds back: a velocity error e leaves the deskewed cloud's centre of
//!   time half a sweep off the reference, the next motion estimate is off by −e/2 + e_prev/2,
//!   and the errors alternate without decaying — seen on the simulated drives. At mid-sweep
//!   the residual smear is centred and the loop converges.)
//! - `--timed`: each sweep goes to `Odometry::register_timed` with its per-point times:
//!   deskewed to its end with the predicted motion (constant velocity) and registered; with
//!   `--deskew-passes N` (default 1) deskewed again with the motion just estimated and
//!   registered again, up to N registrations in all; poses are those of the sensor at the
//!   sweep's last point. Time includes the deskews.
//! - `--skip N` leaves out the first N sweeps (a sequence that starts elsewhere).
//! - `--repeat R` runs the whole sequence R times on fresh odometries; the trajectory is the
//!   first run's (every run gives the same poses), each sweep's time the median over the runs.
//!   Time = `Odometry::register` from the decoded points to the pose (range filter,
//!   subsampling, ICP, map update, degeneracy), single thread.
//! - `--report FILE` writes JSON: per sweep the stamp, time (ms), status, ICP iterations,
//!   inliers, threshold, degeneracy (eigenvalues, condition number, named axes).

use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::Path;
use std::time::Instant;

use ringscan::deskew::{Deskewer, Reference, Twist};
use ringscan::point::Point;
use ringscan::registration::odometry::Odometry;
use ringscan::registration::odometry::OdometryConfig;
use ringscan::registration::odometry::OdometryMethod;
use ringscan::registration::odometry::OdometryStep;
use ringscan::registration::odometry::TrackStatus;
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::StreamConfig;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::velodyne::VelodyneStream;
use ringscan::source::pcap::PcapSource;

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

type Sweeps = Vec<(i64, Vec<Point>)>;

fn decode(args: &[String], input: &str) -> Result<Sweeps, Box<dyn std::error::Error>> {
    let model = match arg(args, "--model") {
        Some(m) => Some(VelodyneModel::from_id(&m).ok_or("unknown --model")?),
        None => None,
    };
    let mut calibrations = Vec::new();
    if let Some(path) = arg(args, "--calib") {
        calibrations.push(parse_velodyne(&std::fs::read_to_string(&path)?, &path)?);
    }
    let mut stream = VelodyneStream::new(StreamConfig {
        model,
        calibrations,
        ..StreamConfig::default()
    });
    let mut sweeps: Sweeps = Vec::new();
    let mut on_sweep = |s: &mut ringscan::sweep::Sweep,
                        _: &ringscan::sensor::velodyne::SensorFacts| {
        if !s.points.is_empty() {
            sweeps.push((s.timestamp_ns, s.points.clone()));
        }
    };
    let mut src = PcapSource::open(Path::new(input))?;
    while let Some(d) = src.next_datagram()? {
        stream.push(d.time_ns, d.payload, &mut on_sweep)?;
    }
    stream.finish(&mut on_sweep)?;
    let largest = sweeps.iter().map(|s| s.1.len()).max().unwrap_or(0);
    let before = sweeps.len();
    sweeps.retain(|s| s.1.len() * 10 >= largest);
    eprintln!(
        "{input}: {} sweeps, {} fragments under 10 % of the largest sweep ({largest} points) left out",
        sweeps.len(),
        before - sweeps.len()
    );
    Ok(sweeps)
}

fn read_dump(path: &str) -> Result<Sweeps, Box<dyn std::error::Error>> {
    let mut bytes = Vec::new();
    File::open(path)?.read_to_end(&mut bytes)?;
    let mut out = Vec::new();
    let mut at = 0usize;
    let take = |at: &mut usize, n: usize| -> Result<&[u8], Box<dyn std::error::Error>> {
        let s = bytes.get(*at..*at + n).ok_or("truncated sweep dump")?;
        *at += n;
        Ok(s)
    };
    while at < bytes.len() {
        let stamp = i64::from_le_bytes(take(&mut at, 8)?.try_into()?);
        let n = usize::try_from(u64::from_le_bytes(take(&mut at, 8)?.try_into()?))?;
        let raw = take(&mut at, n.checked_mul(16).ok_or("bad count")?)?;
        let w = |i: usize| [raw[i], raw[i + 1], raw[i + 2], raw[i + 3]];
        out.push((
            stamp,
            (0..n)
                .map(|k| Point {
                    x: f32::from_le_bytes(w(16 * k)),
                    y: f32::from_le_bytes(w(16 * k + 4)),
                    z: f32::from_le_bytes(w(16 * k + 8)),
                    t: u32::from_le_bytes(w(16 * k + 12)),
                    ..Point::default()
                })
                .collect(),
        ));
    }
    Ok(out)
}

fn write_dump(path: &str, sweeps: &Sweeps) -> std::io::Result<()> {
    let mut w = BufWriter::new(File::create(path)?);
    for (stamp, pts) in sweeps {
        w.write_all(&stamp.to_le_bytes())?;
        w.write_all(&(pts.len() as u64).to_le_bytes())?;
        for p in pts {
            for v in [p.x, p.y, p.z] {
                w.write_all(&v.to_le_bytes())?;
            }
            w.write_all(&p.t.to_le_bytes())?;
        }
    }
    w.flush()
}

fn status_name(s: &TrackStatus) -> String {
    match s {
        TrackStatus::Initialized => "initialized".into(),
        TrackStatus::Converged => "converged".into(),
        TrackStatus::NotConverged => "not-converged".into(),
        TrackStatus::Lost(e) => format!("lost: {e}"),
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let sweeps = if let Some(dump) = arg(&args, "--sweeps") {
        read_dump(&dump)?
    } else {
        let input = args
            .last()
            .filter(|a| !a.starts_with("--"))
            .ok_or("the last argument is the pcap (or give --sweeps FILE)")?;
        decode(&args, input)?
    };
    let mut sweeps = sweeps;
    if let Some(k) = arg(&args, "--skip") {
        let k: usize = k.parse()?;
        sweeps.drain(..k.min(sweeps.len()));
    }
    if let Some(path) = arg(&args, "--dump") {
        write_dump(&path, &sweeps)?;
    }
    let max_range: f64 = arg(&args, "--max-range").map_or(Ok(100.0), |s| s.parse())?;
    let repeat: usize = arg(&args, "--repeat").map_or(Ok(1), |s| s.parse())?;
    let mut cfg = OdometryConfig::for_max_range(max_range);
    if let Some(v) = arg(&args, "--voxel") {
        cfg.voxel_size_m = v.parse()?;
    }
    if args.iter().any(|a| a == "--point-to-plane") {
        cfg.method = OdometryMethod::PointToPlane;
    }
    if args.iter().any(|a| a == "--no-degeneracy") {
        cfg.degeneracy = None;
    }
    if let Some(k) = arg(&args, "--keyframe-m") {
        cfg.keyframe_translation_m = k.parse()?;
    }
    if let Some(k) = arg(&args, "--min-eigenvalue") {
        if let Some(d) = cfg.degeneracy.as_mut() {
            d.min_eigenvalue = k.parse()?;
        }
    }
    cfg.continuous_time = args.iter().any(|a| a == "--continuous");
    if let Some(k) = arg(&args, "--ct-start") {
        cfg.continuous_start_weight = k.parse()?;
    }
    if let Some(k) = arg(&args, "--ct-motion") {
        cfg.continuous_motion_weight = k.parse()?;
    }
    if let Some(k) = arg(&args, "--deskew-passes") {
        cfg.deskew_passes = k.parse()?;
    }
    let deskew = args.iter().any(|a| a == "--deskew");
    let timed = args.iter().any(|a| a == "--timed");
    let mut deskewer = Deskewer::new(Reference::Start);
    let mut buf: Vec<Point> = Vec::new();
    let mut times = vec![Vec::with_capacity(repeat.max(1)); sweeps.len()];
    let mut steps: Vec<OdometryStep> = Vec::new();
    for run in 0..repeat.max(1) {
        let mut odo = Odometry::new(cfg)?;
        for (i, (stamp, pts)) in sweeps.iter().enumerate() {
            let t0 = Instant::now();
            let step = if timed {
                odo.register_timed(pts, *stamp, None)
            } else if deskew {
                buf.clear();
                buf.extend_from_slice(pts);
                let span_ns = buf.iter().map(|p| p.t).max().unwrap_or(0);
                let twist = odo.last_motion().and_then(|m| {
                    Twist::from_relative_motion(&m.previous_from_current, m.dt_ns as f64 * 1e-9)
                });
                if let Some(tw) = twist {
                    // To the sweep's start, then on to its middle (see the module docs).
                    deskewer.deskew_constant_velocity(&mut buf, &tw);
                    let mid_from_start = tw.integrate(f64::from(span_ns) * 0.5e-9).inverse();
                    for p in &mut buf {
                        let q = mid_from_start
                            * nalgebra::Point3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z));
                        (p.x, p.y, p.z) = (q.x as f32, q.y as f32, q.z as f32);
                    }
                }
                odo.register_points(&buf, *stamp + i64::from(span_ns / 2))
            } else {
                odo.register_points(pts, *stamp)
            };
            times[i].push(t0.elapsed().as_secs_f64() * 1e3);
            if run == 0 {
                steps.push(step);
            }
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let ms: Vec<f64> = times.iter_mut().map(median).collect();
    if let Some(path) = arg(&args, "--trajectory") {
        let mut w = BufWriter::new(File::create(&path)?);
        for s in &steps {
            let t = s.world_from_sensor.translation.vector;
            let q = s.world_from_sensor.rotation;
            writeln!(
                w,
                "{:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}",
                s.stamp_ns as f64 * 1e-9,
                t.x,
                t.y,
                t.z,
                q.i,
                q.j,
                q.k,
                q.w
            )?;
        }
        w.flush()?;
    }
    if let Some(path) = arg(&args, "--report") {
        let per: Vec<serde_json::Value> = steps
            .iter()
            .zip(&ms)
            .map(|(s, ms)| {
                let deg = s.degeneracy.map(|d| {
                    serde_json::json!({
                        "eigenvalues": d.eigenvalues,
                        "condition_number": if d.condition_number.is_finite() { d.condition_number } else { f64::MAX },
                        "axes": d.degenerate_names(),
                        "axis_share": d.axis_share,
                        "samples": d.samples,
                    })
                });
                serde_json::json!({
                    "stamp_ns": s.stamp_ns,
                    "ms": ms,
                    "status": status_name(&s.status),
                    "iterations": s.icp.map(|r| r.iterations),
                    "inliers": s.icp.map(|r| r.inliers),
                    "rmse_m": s.icp.map(|r| r.rmse_m),
                    "threshold_m": s.threshold_m,
                    "points": s.points,
                    "source_points": s.source_points,
                    "map_points": s.map_points,
                    "keyframe": s.keyframe,
                    "degenerate": s.degenerate,
                    "degeneracy": deg,
                })
            })
            .collect();
        std::fs::write(
            &path,
            serde_json::to_string(&serde_json::json!({"sweeps": per}))?,
        )?;
    }
    let n = ms.len().max(1) as f64;
    let mean_ms = ms.iter().sum::<f64>() / n;
    let mut sorted = ms.clone();
    sorted.sort_by(f64::total_cmp);
    let pts = sweeps.iter().map(|s| s.1.len()).sum::<usize>() as f64 / n;
    let degenerate = steps.iter().filter(|s| s.degenerate).count();
    eprintln!(
        "ringscan odometry: {} sweeps ({pts:.0} points each), {:.3} ms per sweep (mean of per-sweep medians over {} runs; median {:.3}, max {:.3}); {} degenerate; statuses: {}",
        steps.len(),
        mean_ms,
        repeat.max(1),
        sorted.get(sorted.len() / 2).copied().unwrap_or(0.0),
        sorted.last().copied().unwrap_or(0.0),
        degenerate,
        {
            let mut c = std::collections::BTreeMap::new();
            for s in &steps {
                *c.entry(status_name(&s.status)).or_insert(0) += 1;
            }
            format!("{c:?}")
        }
    );
    Ok(())
}
