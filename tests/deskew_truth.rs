//! Deskew against the simulator's ground truth: a sensor driving at 15 m/s while turning at
//! 60 °/s through the urban scene (`ringscan::sim`). Each decoded point carries, from the
//! simulator, the world point its ray hit. A sweep's points are deskewed into the sensor pose
//! at the sweep's timestamp; moved into the world with the true pose at that time, they must
//! land on their true world points: the 99th percentile of the distance is ≤ 2 cm for each
//! motion source (constant velocity, IMU, TUM poses file). Without deskew the same measure is
//! printed beside it (and must be far worse, so the test can tell).
//!
//! The truth is the ray-cast geometry and the trajectory, independent of `deskew`. The motion
//! given to deskew comes from independent channels: the twist (the trajectory's definition),
//! the simulator's IMU packets decoded by `wire::ouster`, and a TUM text written from the
//! trajectory and parsed by `deskew::PoseTable`.

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Vector3};
use ringscan::deskew::{Deskewer, ImuTrack, PoseTable, Reference, Twist};
use ringscan::point::Point;
use ringscan::sensor::ouster::sim::OusterSim;
use ringscan::sensor::ouster::sim::OusterTruth;
use ringscan::sensor::ouster::wire::ImuPacketLegacy;
use ringscan::sensor::ouster::OusterDecoder;
use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::sim::Truth;
use ringscan::sensor::velodyne::sim::VelodyneSim;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::VelodyneDecoder;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::DecodeOptions;
use ringscan::sim::motion::Trajectory;
use ringscan::sim::scenes;

const T0: i64 = 1_714_564_800_000_000_000;
const V_MPS: f64 = 15.0;
const W_DEGPS: f64 = 60.0;

fn moving() -> Trajectory {
    Trajectory::twist(
        T0,
        Isometry3::translation(40.0, 0.0, scenes::SENSOR_HEIGHT_M),
        Vector3::new(V_MPS, 0.0, 0.0),
        Vector3::new(0.0, 0.0, W_DEGPS.to_radians()),
    )
}

fn twist() -> Twist {
    Twist {
        linear_mps: Vector3::new(V_MPS, 0.0, 0.0),
        angular_radps: Vector3::new(0.0, 0.0, W_DEGPS.to_radians()),
    }
}

/// One sweep as a decoder gives it, with the truth of each point.
struct SimSweep {
    points: Vec<Point>,
    world: Vec<[f64; 3]>,
    /// The sweep's timestamp (first firing) on the simulator's clock.
    start_ns: i64,
    /// The same instant in the sensor's packet clock (Ouster column timestamps).
    device_start_ns: i64,
}

/// Median and 99th percentile of |world_from_sensor(start) · p − truth|, metres.
fn errors(s: &SimSweep, points: &[Point], traj: &Trajectory) -> (f64, f64) {
    let pose = traj.pose(s.start_ns);
    let mut d: Vec<f64> = points
        .iter()
        .zip(&s.world)
        .map(|(p, w)| {
            let q = pose * Point3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z));
            (q.coords - Vector3::from(*w)).norm()
        })
        .collect();
    d.sort_by(f64::total_cmp);
    let at = |f: f64| d[((d.len() - 1) as f64 * f).round() as usize];
    (at(0.5), at(0.99))
}

/// A HDL-32E (built-in table) sweep: packets from the sweep's first firing on, for 100 ms.
fn velodyne_sweep() -> (SimSweep, Trajectory) {
    let model = VelodyneModel::Hdl32e;
    let calib = builtin(model).unwrap();
    let mode = ReturnMode::Strongest;
    let mut sim = VelodyneSim::new(model, mode, calib.clone(), T0);
    sim.trajectory = moving();
    let dec = VelodyneDecoder::new(model, mode, &calib, DecodeOptions::default()).unwrap();
    let rings = calib.rings();
    let scene = scenes::urban();
    // Skip a little so the sweep does not start at the trajectory's origin.
    for _ in 0..50 {
        sim.next_packet(&scene, &mut Vec::new());
    }
    let packets = (0.1e9 / sim.period_ns()).floor() as usize;
    let mut s = SimSweep {
        points: Vec::new(),
        world: Vec::new(),
        start_ns: 0,
        device_start_ns: 0,
    };
    for k in 0..packets {
        let mut truth: Vec<Truth> = Vec::new();
        let (_, bytes) = sim.next_packet(&scene, &mut truth);
        let Some(first) = truth.first() else {
            continue;
        };
        let packet_start = first.time_ns - first.t_ns.round() as i64;
        if k == 0 {
            s.start_ns = packet_start;
        }
        let p = DataPacket::new(&bytes).unwrap();
        let mut pts = Vec::new();
        dec.decode(&p, 0, &mut pts);
        let by_key: HashMap<(u32, u16, u8), &Truth> = truth
            .iter()
            .map(|t| ((t.t_ns.round() as u32, rings[t.laser], t.ret), t))
            .collect();
        for mut pt in pts {
            let t = by_key[&(pt.t, pt.ring, pt.ret)];
            pt.t += (packet_start - s.start_ns) as u32;
            s.points.push(pt);
            s.world.push(t.world);
        }
    }
    s.device_start_ns = s.start_ns;
    (s, sim.trajectory.clone())
}

/// Ouster metadata with the defaults the SDK fills in (LEGACY lidar and IMU packets, IMU at
/// the default `imu_to_sensor_transform`): 128 beams evenly from +22.5° to −22.5°, 1024×10.
fn os1_128() -> ringscan::sensor::ouster::calib::OusterInfo {
    let alt: Vec<String> = (0..128)
        .map(|i| format!("{:.4}", 22.5 - 45.0 * f64::from(i) / 127.0))
        .collect();
    let az: Vec<String> = (0..128)
        .map(|i| format!("{:.3}", [4.2, 1.4, -1.4, -4.2][i % 4]))
        .collect();
    let text = format!(
        r#"{{"prod_line": "OS-1-128", "lidar_mode": "1024x10", "beam_altitude_angles": [{}], "beam_azimuth_angles": [{}]}}"#,
        alt.join(", "),
        az.join(", ")
    );
    ringscan::sensor::ouster::calib::parse(&text, "os1-128-sim.json").unwrap()
}

/// The second frame of a simulated OS-1-128, and the IMU samples (sensor clock ns, rad/s in
/// the IMU frame) of 0.4 s around it.
/// IMU samples: sensor clock ns, angular velocity rad/s (IMU frame).
type Gyro = Vec<(i64, [f64; 3])>;

fn ouster_sweep() -> (SimSweep, Trajectory, Gyro, [f64; 16]) {
    let info = os1_128();
    let mut sim = OusterSim::new(info.clone(), T0);
    sim.trajectory = moving();
    let dec = OusterDecoder::new(&info).unwrap();
    let scene = scenes::urban();
    let per_frame = 1024 / info.format.columns_per_packet.max(1);
    for _ in 0..per_frame {
        sim.next_packet(&scene, &mut Vec::new());
    }
    let mut s = SimSweep {
        points: Vec::new(),
        world: Vec::new(),
        start_ns: 0,
        device_start_ns: 0,
    };
    let mut device_start = None;
    for _ in 0..per_frame {
        let mut truth: Vec<OusterTruth> = Vec::new();
        let (_, bytes) = sim.next_packet(&scene, &mut truth);
        let p = dec.packet(&bytes).unwrap();
        let start = *device_start.get_or_insert_with(|| {
            let c0 = p.column(0).unwrap();
            // The truth of column 0 gives the same instant on the simulator's clock.
            s.start_ns = truth
                .iter()
                .find(|t| t.column == c0.measurement_id())
                .map(|t| t.time_ns)
                .unwrap();
            c0.timestamp_ns()
        });
        let by_key: HashMap<(u16, u16, u8), &OusterTruth> = truth
            .iter()
            .map(|t| ((t.column, t.row, t.ret), t))
            .collect();
        dec.decode_with(&p, start, |pt, _, row, col| {
            let t = by_key[&(col as u16, row as u16, pt.ret)];
            s.points.push(pt);
            s.world.push(t.world);
        })
        .unwrap();
    }
    s.device_start_ns = device_start.unwrap() as i64;
    let mut imu = Vec::new();
    while sim.next_imu_time_ns() < T0 + 400_000_000 {
        let (_, b) = sim.next_imu_packet().unwrap();
        let p = ImuPacketLegacy::new(&b).unwrap();
        let w = p.gyro_dps().map(|x| f64::from(x).to_radians());
        imu.push((p.gyro_ts_ns() as i64, w));
    }
    (s, sim.trajectory.clone(), imu, info.imu_to_sensor)
}

fn report(what: &str, none: (f64, f64), got: (f64, f64)) {
    eprintln!(
        "{what}: deskewed median {:.2} mm, p99 {:.2} mm; without deskew median {:.1} mm, p99 {:.1} mm",
        got.0 * 1e3,
        got.1 * 1e3,
        none.0 * 1e3,
        none.1 * 1e3
    );
    assert!(got.1 <= 0.02, "{what}: p99 {} m > 2 cm", got.1);
    assert!(
        none.1 > 0.5,
        "{what}: the motion must matter without deskew"
    );
}

fn poses_tum(traj: &Trajectory, around_ns: i64) -> PoseTable {
    // A 100 Hz TUM file from the trajectory, written as text and parsed back.
    let text = traj
        .sample(around_ns - 500_000_000, around_ns + 500_000_000, 10_000_000)
        .to_tum();
    PoseTable::from_tum(&text).unwrap()
}

#[test]
fn velodyne_constant_velocity_and_poses_meet_2_cm() {
    let (s, traj) = velodyne_sweep();
    assert!(s.points.len() > 30_000, "{} points", s.points.len());
    let none = errors(&s, &s.points, &traj);
    let mut d = Deskewer::new(Reference::Start);

    let mut pts = s.points.clone();
    d.deskew_constant_velocity(&mut pts, &twist());
    report("HDL-32E constant velocity", none, errors(&s, &pts, &traj));

    let table = poses_tum(&traj, s.start_ns);
    let mut pts = s.points.clone();
    d.deskew_poses(&mut pts, s.start_ns, &table).unwrap();
    report("HDL-32E poses (TUM)", none, errors(&s, &pts, &traj));
}

#[test]
fn ouster_constant_velocity_imu_and_poses_meet_2_cm() {
    let (s, traj, imu, imu_to_sensor) = ouster_sweep();
    assert!(s.points.len() > 60_000, "{} points", s.points.len());
    let none = errors(&s, &s.points, &traj);
    let mut d = Deskewer::new(Reference::Start);

    let mut pts = s.points.clone();
    d.deskew_constant_velocity(&mut pts, &twist());
    report("OS-1-128 constant velocity", none, errors(&s, &pts, &traj));

    let mut track = ImuTrack::from_imu_to_sensor(&imu_to_sensor);
    for (t, w) in &imu {
        track.push(*t, *w);
    }
    assert!(track.len() >= 30, "{} IMU samples", track.len());
    let mut pts = s.points.clone();
    d.deskew_imu(
        &mut pts,
        s.device_start_ns,
        &track,
        &Vector3::new(V_MPS, 0.0, 0.0),
    )
    .unwrap();
    report("OS-1-128 IMU", none, errors(&s, &pts, &traj));

    let table = poses_tum(&traj, s.start_ns);
    let mut pts = s.points.clone();
    d.deskew_poses(&mut pts, s.start_ns, &table).unwrap();
    report("OS-1-128 poses (TUM)", none, errors(&s, &pts, &traj));
}
