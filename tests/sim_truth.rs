//! The simulator with a MOVING sensor (15 m/s forward, 60 °/s yaw) in the urban scene: decoding
//! its packets with ringscan must put every point back on the scene point the simulator's ray
//! hit, in the sensor frame at that measurement's time, within 1 cm + range · sin(0.005°), for
//! every Velodyne model (VLP-16, HDL-32E, VLP-32C with their built-in tables; HDL-64E S2 and
//! S3 with real db.xml / yaml calibrations) and for Ouster metadata files of every profile.
//!
//! The truth is the ray-cast geometry (`sim::scene`), independent of the decoders. The test
//! prints the largest error per sensor. The world truth is checked as well: ground-labelled
//! points lie on the urban scene's ground heights (road z = 0, sidewalks z = 0.15 m), and the
//! decoded point moved by the true pose at its time lands on the world point.

mod common;

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Vector3};
use ringscan::sensor::ouster::calib::OusterInfo;
use ringscan::sensor::ouster::model::Profile;
use ringscan::sensor::ouster::model::ALL_PROFILES;
use ringscan::sensor::ouster::sim::OusterSim;
use ringscan::sensor::ouster::sim::OusterTruth;
use ringscan::sensor::ouster::OusterDecoder;
use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::calib::VelodyneCalibration;
use ringscan::sensor::velodyne::sim::Truth;
use ringscan::sensor::velodyne::sim::VelodyneSim;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::VelodyneDecoder;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::DecodeOptions;
use ringscan::sim::motion::Trajectory;
use ringscan::sim::scene::World;
use ringscan::sim::scene::GROUND;
use ringscan::sim::scenes;

const SIN_0005_DEG: f64 = 8.726_646e-5;
const T0: i64 = 1_714_564_800_000_000_000;

/// 15 m/s forward, 60 °/s yaw, from the middle of the urban loop's first street.
fn moving() -> Trajectory {
    Trajectory::twist(
        T0,
        Isometry3::translation(40.0, 0.0, scenes::SENSOR_HEIGHT_M),
        Vector3::new(15.0, 0.0, 0.0),
        Vector3::new(0.0, 0.0, 60f64.to_radians()),
    )
}

#[derive(Debug, Default)]
struct Figures {
    points: usize,
    max_error: f64,
    worst_excess: f64,
    ground: usize,
    objects: usize,
}

impl Figures {
    fn check(
        &mut self,
        what: &str,
        got: [f32; 3],
        xyz: [f64; 3],
        world: [f64; 3],
        pose: Isometry3<f64>,
    ) {
        let g = Vector3::new(f64::from(got[0]), f64::from(got[1]), f64::from(got[2]));
        let t = Vector3::from(xyz);
        let d = (g - t).norm();
        let allowed = 0.01 + t.norm() * SIN_0005_DEG;
        assert!(
            d <= allowed,
            "{what}: point off by {d} m (allowed {allowed}) at {xyz:?}"
        );
        // The true pose at the measurement time maps the decoded point onto the world truth.
        let w = pose * Point3::from(g);
        assert!((w.coords - Vector3::from(world)).norm() <= allowed + 1e-6);
        self.max_error = self.max_error.max(d);
        self.worst_excess = self.worst_excess.max(d - allowed);
        self.points += 1;
    }

    fn label(&mut self, what: &str, label: u32, world: [f64; 3]) {
        if label == GROUND {
            // Urban ground: the road (z = 0) or a kerb top / sidewalk (z = 0.15).
            let z = world[2];
            assert!(
                z.abs() < 1e-6 || (z - 0.15).abs() < 1e-6,
                "{what}: ground point at z = {z}"
            );
            self.ground += 1;
        } else {
            self.objects += 1;
        }
    }
}

fn velodyne(
    model: VelodyneModel,
    calib: &VelodyneCalibration,
    name: &str,
    scene: &World,
) -> Figures {
    let mode = ReturnMode::Strongest;
    let mut sim = VelodyneSim::new(model, mode, calib.clone(), T0);
    sim.trajectory = moving();
    let dec = VelodyneDecoder::new(model, mode, calib, DecodeOptions::default()).unwrap();
    let rings = calib.rings();
    let mut f = Figures {
        worst_excess: f64::NEG_INFINITY,
        ..Figures::default()
    };
    // 0.11 s: a revolution and a bit, 1.65 m and 6.6° of motion.
    let packets = (0.11e9 / sim.period_ns()).round() as usize;
    let what = format!("{} ({name})", model.name());
    for _ in 0..packets {
        let mut truth: Vec<Truth> = Vec::new();
        let (_, bytes) = sim.next_packet(scene, &mut truth);
        let p = DataPacket::new(&bytes).unwrap();
        let mut pts = Vec::new();
        let n = dec.decode(&p, 0, &mut pts);
        assert_eq!(n.points, truth.len(), "{what}: one point per measurement");
        let by_key: HashMap<(u32, u16, u8), &Truth> = truth
            .iter()
            .map(|t| ((t.t_ns.round() as u32, rings[t.laser], t.ret), t))
            .collect();
        for pt in &pts {
            let t = by_key[&(pt.t, pt.ring, pt.ret)];
            let pose = sim.trajectory.pose(t.time_ns);
            f.check(&what, [pt.x, pt.y, pt.z], t.xyz, t.world, pose);
            f.label(&what, t.label, t.world);
        }
    }
    eprintln!(
        "{what}: {} points ({} ground, {} object), max error {:.2} mm, worst excess over the allowance {:.2} mm",
        f.points,
        f.ground,
        f.objects,
        f.max_error * 1e3,
        f.worst_excess * 1e3
    );
    assert!(f.points > packets * 100, "{what}: only {} points", f.points);
    assert!(f.ground > 100 && f.objects > 100, "{what}: {f:?}");
    f
}

#[test]
fn velodyne_models_recover_the_scene_while_moving() {
    let scene = scenes::urban();
    for model in [
        VelodyneModel::Vlp16,
        VelodyneModel::Hdl32e,
        VelodyneModel::Vlp32c,
    ] {
        let calib = builtin(model).unwrap();
        velodyne(model, &calib, "built-in table", &scene);
    }
    let Some(root) = common::captures() else {
        return;
    };
    for (model, rel) in [
        (
            VelodyneModel::Hdl64eS2,
            "ros-drivers__velodyne/velodyne_pointcloud/tests/64e_s2.1-sztaki.xml",
        ),
        (
            VelodyneModel::Hdl64eS2,
            "ros-drivers__velodyne/velodyne_pointcloud/params/64e_s2.1-sztaki.yaml",
        ),
        (
            VelodyneModel::Hdl64eS3,
            "ros-drivers__velodyne/velodyne_pointcloud/params/64e_s3-xiesc.yaml",
        ),
    ] {
        let text = std::fs::read_to_string(root.join(rel)).unwrap();
        let calib = parse_velodyne(&text, rel).unwrap();
        let name = rel.rsplit('/').next().unwrap();
        velodyne(model, &calib, name, &scene);
    }
}

fn ouster(info: &OusterInfo, name: &str, scene: &World, seconds: f64) -> Figures {
    let mut sim = OusterSim::new(info.clone(), T0);
    sim.trajectory = moving();
    let dec = OusterDecoder::new(info).unwrap();
    let h = info.format.pixels_per_column;
    let mut f = Figures {
        worst_excess: f64::NEG_INFINITY,
        ..Figures::default()
    };
    let what = format!(
        "{} {} {}x{} ({name})",
        info.prod_line,
        info.format.profile.name(),
        info.columns_per_frame,
        info.fps
    );
    let packets = (seconds * 1e9 / sim.packet_period_ns()).round() as usize;
    for _ in 0..packets {
        let mut truth: Vec<OusterTruth> = Vec::new();
        let (_, bytes) = sim.next_packet(scene, &mut truth);
        let p = dec.packet(&bytes).unwrap_or_else(|e| panic!("{what}: {e}"));
        let by_key: HashMap<(u16, u16, u8), &OusterTruth> = truth
            .iter()
            .map(|t| ((t.column, t.row, t.ret), t))
            .collect();
        let mut n = 0;
        dec.decode_with(&p, 0, |pt, x, row, col| {
            let t = by_key
                .get(&(col as u16, row as u16, pt.ret))
                .unwrap_or_else(|| panic!("{what}: no truth for {row} {col} {}", pt.ret));
            assert!(row < h);
            assert_eq!(x.range_mm, t.range_mm, "{what}");
            let pose = sim.trajectory.pose(t.time_ns);
            f.check(&what, [pt.x, pt.y, pt.z], t.xyz, t.world, pose);
            if t.ret == 0 {
                // (A second return is on an imaginary surface 1.5 m behind the first.)
                f.label(&what, t.label, t.world);
            }
            n += 1;
        })
        .unwrap();
        assert_eq!(n, truth.len(), "{what}: one point per return");
    }
    eprintln!(
        "{what}: {} points ({} ground, {} object), max error {:.2} mm, worst excess over the allowance {:.2} mm",
        f.points,
        f.ground,
        f.objects,
        f.max_error * 1e3,
        f.worst_excess * 1e3
    );
    assert!(f.ground > 100 && f.objects > 100, "{what}: {f:?}");
    f
}

fn metadata(root: &std::path::Path, rel: &str) -> OusterInfo {
    let path = root.join("ouster-lidar__ouster-sdk/tests").join(rel);
    let text = std::fs::read_to_string(&path).unwrap();
    ringscan::sensor::ouster::calib::parse(&text, rel).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

#[test]
fn ouster_metadata_and_profiles_recover_the_scene_while_moving() {
    let Some(root) = common::captures() else {
        return;
    };
    let scene = scenes::urban();
    // Real metadata as they are: profiles, beam counts, modes, column windows, FUSA, PTP.
    for rel in [
        "metadata/3_0_1_os-122246000293-128.json",
        "metadata/2_3_1_os-992146000760-128.json",
        "metadata/2_5_0_os-992146000760-128.json",
        "metadata/2_0_rc2_os-992011000121-32U0_legacy.json",
        "metadata/2_0_0_os1-992008000494-128_col_win_legacy.json",
        "metadata/2_1_2_os1-991913000010-64.json",
        "metadata/1_14_6cccd_os-882002000138-32U0_legacy.json",
        "pcaps/OS-1-128_767798045_1024x10_20230712_120049.json",
        "pcaps/shot_limiting_test.json",
        "pcaps/windowed_frame1_0.json",
    ] {
        let info = metadata(&root, rel);
        ouster(&info, rel, &scene, 0.1);
    }
    // Every profile with one sensor's beam intrinsics, and other columns per frame.
    let base = metadata(&root, "metadata/3_0_1_os-122246000293-128.json");
    for profile in ALL_PROFILES {
        let mut info = base.clone();
        info.format.profile = profile;
        info.lidar_profile_name = profile.name().to_owned();
        ouster(&info, "3_0_1 metadata, profile set", &scene, 0.03);
    }
    for (w, fps) in [(512, 20), (2048, 10), (4096, 5)] {
        let mut info = base.clone();
        info.format.profile = Profile::Rng19Rfl8Sig16Nir16;
        info.columns_per_frame = w;
        info.fps = fps;
        info.column_window = (0, w - 1);
        ouster(&info, "3_0_1 metadata, mode set", &scene, 0.03);
    }
}

/// The IMU packets carry the specific force and body rate of the trajectory at the IMU, in the
/// IMU frame: for a constant body twist (v, ω) and the IMU at r (sensor frame), the closed form
/// is f = ω × (v + ω × r) + g·ẑ (yaw-only motion keeps ẑ up), ω unchanged, both rotated into
/// the IMU axes by `imu_to_sensor`. The packets go through ringscan's IMU path
/// (`OusterStream`, SI units), which must give back those values at the sample times.
#[test]
fn ouster_imu_packets_follow_the_motion() {
    use ringscan::sensor::ouster::OusterStream;
    use ringscan::sensor::ouster::OusterStreamConfig;
    let Some(root) = common::captures() else {
        return;
    };
    let g = ringscan::sim::motion::GRAVITY;
    for rel in [
        "metadata/3_0_1_os-122246000293-128.json",
        "pcaps/shot_limiting_test.json",
    ] {
        let mut info = metadata(&root, rel);
        // A rotated IMU too, so that the frame change is exercised.
        let (s, c) = (0.3f64.sin(), 0.3f64.cos());
        info.imu_to_sensor[0] = c;
        info.imu_to_sensor[1] = -s;
        info.imu_to_sensor[4] = s;
        info.imu_to_sensor[5] = c;
        let m = info.imu_to_sensor;
        let mut sim = OusterSim::new(info.clone(), T0);
        sim.trajectory = moving();
        let v = Vector3::new(15.0, 0.0, 0.0);
        let w = Vector3::new(0.0, 0.0, 60f64.to_radians());
        let r = Vector3::new(m[3], m[7], m[11]) * 1e-3;
        let r_si = nalgebra::Rotation3::from_matrix(&nalgebra::Matrix3::new(
            m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10],
        ));
        let f_want = r_si.inverse() * (w.cross(&(v + w.cross(&r))) + Vector3::new(0.0, 0.0, g));
        let w_want = r_si.inverse() * w;
        let mut stream = OusterStream::new(OusterStreamConfig {
            info: info.clone(),
            metadata_name: rel.into(),
            crc: None,
            decode: DecodeOptions::default(),
            keep_extras: false,
            keep_columns: false,
        })
        .unwrap();
        let mut samples = 0;
        for _ in 0..20 {
            let t_first = sim.next_imu_time_ns();
            let (host, b) = sim.next_imu_packet().unwrap();
            stream.push(host, &b, &mut |_, _| {});
            for (k, s) in stream.drain_imu().enumerate() {
                let a = Vector3::from(s.accel);
                let gy = Vector3::from(s.gyro);
                assert_eq!(s.sensor_ns as i64, t_first + k as i64 * sim.imu_period_ns);
                assert!((a - f_want).norm() < 1e-4, "{rel}: accel {a} want {f_want}");
                assert!(
                    (gy - w_want).norm() < 1e-5,
                    "{rel}: gyro {gy} want {w_want}"
                );
                samples += 1;
            }
        }
        assert!(samples >= 20, "{rel}: {samples} samples");
        eprintln!(
            "{rel}: {samples} IMU samples ({:?}) through OusterStream match the closed form",
            info.imu_profile
        );
    }
}
