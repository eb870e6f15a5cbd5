//! Property tests of the Ouster round trips, against the simulator's truth:
//!
//! - **Geometry**: for every profile, random beam counts, lidar modes, beam angles, rooms and
//!   sensor motion → `sim::ouster::OusterSim` packets → `OusterDecoder`: one point per return
//!   the simulator recorded, each within 1 cm + range · sin(0.005°) of the scene point its ray
//!   hit, with the range (in the profile's units) and the reflectivity it sent.
//! - **Frame-id wraps**: frames whose 16-bit (standard header) or 32-bit (FUSA) frame id rolls
//!   over, through `OusterStream`: one sweep per frame, consecutive indices, each with the
//!   frame's id and every point of it; nothing late, missing or malformed.
//!
//! `PROPTEST_CASES=N` sets the case count per profile.
#![cfg(feature = "sim")]

use std::collections::HashMap;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};

use ringscan::point::Point;
use ringscan::sensor::ouster::calib::parse;
use ringscan::sensor::ouster::calib::OusterInfo;
use ringscan::sensor::ouster::model::PacketFormat;
use ringscan::sensor::ouster::model::Profile;
use ringscan::sensor::ouster::model::ALL_PROFILES;
use ringscan::sensor::ouster::sim::OusterSim;
use ringscan::sensor::ouster::sim::OusterTruth;
use ringscan::sensor::ouster::OusterDecoder;
use ringscan::sensor::ouster::OusterStream;
use ringscan::sensor::ouster::OusterStreamConfig;
use ringscan::sensor::DecodeOptions;
use ringscan::sim::motion::Trajectory;
use ringscan::sim::scene::Shapes;
use ringscan::sweep::Sweep;

const SIN_0005_DEG: f64 = 8.726_646e-5;
const T0: i64 = 1_714_564_800_000_000_000;

fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn runner(cases: u32) -> TestRunner {
    TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    })
}

/// A sensor: `profile`, H beams from `top` down to `bottom` degrees with azimuth offsets of
/// ± `az` degrees, W columns at 10 Hz (20 Hz for 512 and 1024 when `fast`), pixel shifts.
fn sensor(profile: Profile, h: usize, w: usize, top: f64, bottom: f64, az: f64) -> OusterInfo {
    let text = serde_json::json!({
        "beam_altitude_angles": (0..64).map(|u| 20.0 - 0.5 * f64::from(u)).collect::<Vec<_>>(),
        "beam_azimuth_angles": vec![0.0; 64],
        "lidar_mode": format!("{w}x10"),
        "prod_line": "OS-1-64",
    })
    .to_string();
    let mut info = parse(&text, "synthetic.json").expect("the base metadata parses");
    info.format = PacketFormat {
        profile,
        columns_per_packet: 16,
        pixels_per_column: h,
    };
    info.columns_per_frame = w;
    info.column_window = (0, w - 1);
    info.beam_altitude_angles = (0..h)
        .map(|u| top - (top - bottom) * u as f64 / (h - 1) as f64)
        .collect();
    info.beam_azimuth_angles = (0..h)
        .map(|u| [az, az / 3.0, -az / 3.0, -az][u % 4])
        .collect();
    info.pixel_shift_by_row = (0..h).map(|u| [12, 4, -4, -12][u % 4]).collect();
    info.serial = 992_210_000_957;
    info.init_id = 5_431_293;
    info.firmware = "v2.5.2".to_owned();
    info
}

#[derive(Clone, Debug)]
struct Case {
    profile: usize,
    h: usize,
    w: usize,
    top: f64,
    bottom: f64,
    az: f64,
    room: [f64; 4],
    speed: f64,
    yaw_rate_deg: f64,
    start_packet: u64,
    packets: usize,
}

fn case() -> impl Strategy<Value = Case> {
    (
        0..ALL_PROFILES.len(),
        prop::sample::select(vec![16usize, 32, 64, 128]),
        prop::sample::select(vec![512usize, 1024, 2048]),
        (5.0..45.0f64, -45.0..-5.0f64, 0.0..4.5f64),
        (3.0..40.0f64, 3.0..40.0f64, 0.5..3.0f64, 1.0..10.0f64),
        (0.0..20.0f64, -90.0..90.0f64),
        (0u64..200, 1usize..4),
    )
        .prop_map(
            |(profile, h, w, (top, bottom, az), (x, y, floor, ceil), (speed, yaw), (s, n))| Case {
                profile,
                h,
                w,
                top,
                bottom,
                az,
                room: [x, y, floor, ceil],
                speed,
                yaw_rate_deg: yaw,
                start_packet: s,
                packets: n,
            },
        )
}

fn check_case(c: &Case) -> Result<usize, TestCaseError> {
    let profile = ALL_PROFILES[c.profile];
    let info = sensor(profile, c.h, c.w, c.top, c.bottom, c.az);
    let dec = OusterDecoder::new(&info).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let scene = Shapes::room(c.room[0], c.room[1], c.room[2], c.room[3]);
    let mut sim = OusterSim::new(info.clone(), T0);
    sim.trajectory = Trajectory::twist(
        T0,
        Isometry3::identity(),
        Vector3::new(c.speed, 0.0, 0.0),
        Vector3::new(0.0, 0.0, c.yaw_rate_deg.to_radians()),
    );
    sim.packet_index = c.start_packet;
    let mut matched = 0;
    for _ in 0..c.packets {
        let mut truth: Vec<OusterTruth> = Vec::new();
        let (_, bytes) = sim.next_packet(&scene, &mut truth);
        let p = dec
            .packet(&bytes)
            .map_err(|e| TestCaseError::fail(format!("{profile}: {e}")))?;
        let by_key: HashMap<(u16, u16, u8), &OusterTruth> = truth
            .iter()
            .map(|t| ((t.column, t.row, t.ret), t))
            .collect();
        let mut n = 0usize;
        let mut failure = None;
        let mut seq: Vec<(Point, u32)> = Vec::new();
        dec.decode_with(&p, 0, |pt, x, row, col| {
            n += 1;
            seq.push((pt, col as u32));
            let Some(t) = by_key.get(&(col as u16, row as u16, pt.ret)) else {
                failure = Some(format!(
                    "no truth for pixel ({row}, {col}) return {}",
                    pt.ret
                ));
                return;
            };
            let r = t.xyz.iter().map(|v| v * v).sum::<f64>().sqrt();
            let err = ((f64::from(pt.x) - t.xyz[0]).powi(2)
                + (f64::from(pt.y) - t.xyz[1]).powi(2)
                + (f64::from(pt.z) - t.xyz[2]).powi(2))
            .sqrt();
            if err > 0.01 + r * SIN_0005_DEG {
                failure = Some(format!(
                    "pixel ({row}, {col}): error {err} m at range {r} m"
                ));
            }
            if x.range_mm != t.range_mm || pt.intensity != f32::from(t.reflectivity) {
                failure = Some(format!(
                    "pixel ({row}, {col}): range {} / {} mm, reflectivity {} / {}",
                    x.range_mm, t.range_mm, pt.intensity, t.reflectivity
                ));
            }
        })
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
        if let Some(f) = failure {
            return Err(TestCaseError::fail(format!("{profile}: {f}")));
        }
        prop_assert_eq!(n, truth.len(), "{}: one point per return", profile);
        // The append loop with columns (what `ringscan.open` keeps for `.image()`) gives the
        // same points, in the same order, at the columns the truth checked above.
        let (mut pts, mut cols) = (Vec::new(), Vec::new());
        dec.decode_columns(&p, 0, &mut pts, &mut cols)
            .map_err(|e| TestCaseError::fail(e.to_string()))?;
        let (want_pts, want_cols): (Vec<Point>, Vec<u32>) = seq.into_iter().unzip();
        prop_assert!(pts == want_pts, "{}: decode_columns points differ", profile);
        prop_assert_eq!(cols, want_cols, "{}: decode_columns columns", profile);
        matched += n;
    }
    Ok(matched)
}

#[test]
fn every_profile_round_trips_random_scenes_and_motion() {
    for (i, profile) in ALL_PROFILES.into_iter().enumerate() {
        let points = std::cell::Cell::new(0usize);
        let mut runner = runner(cases(12));
        runner
            .run(&case().prop_map(move |c| Case { profile: i, ..c }), |c| {
                points.set(points.get() + check_case(&c)?);
                Ok(())
            })
            .unwrap_or_else(|e| panic!("{profile}: {e}"));
        assert!(points.get() > 0, "{profile}: the cases hit nothing");
    }
}

/// Frames `first_frame ..` of a small sensor through an `OusterStream`.
fn wrap_case(profile: Profile, first_frame: u64, frames: u64) -> Result<(), TestCaseError> {
    let info = sensor(profile, 16, 512, 15.0, -15.0, 1.0);
    let cfg = OusterStreamConfig {
        info: info.clone(),
        metadata_name: "synthetic.json".into(),
        crc: None,
        decode: DecodeOptions::default(),
        keep_extras: false,
        keep_columns: false,
    };
    let mut stream = OusterStream::new(cfg).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let scene = Shapes::room(12.0, 7.0, 1.5, 3.0);
    let mut sim = OusterSim::new(info.clone(), T0);
    sim.trajectory = Trajectory::fixed(Isometry3::from_parts(
        Translation3::new(0.5, -0.3, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.4),
    ));
    let per_frame = (info.columns_per_frame / info.format.columns_per_packet) as u64;
    sim.packet_index = first_frame * per_frame;
    let bits = if profile == Profile::FusaRng15Rfl8Nir8Dual {
        32
    } else {
        16
    };
    let mut expected_points: HashMap<u32, usize> = HashMap::new();
    let mut sweeps: Vec<(u64, u32, usize)> = Vec::new();
    let mut on_sweep = |s: &mut Sweep, _: &ringscan::sensor::ouster::OusterFacts| {
        sweeps.push((s.index, s.frame_id, s.points.len()));
    };
    for _ in 0..frames * per_frame {
        let mut truth = Vec::new();
        let (host, bytes) = sim.next_packet(&scene, &mut truth);
        for t in &truth {
            let id = (u64::from(t.frame_id) % (1u64 << bits)) as u32;
            *expected_points.entry(id).or_insert(0) += 1;
        }
        stream.push(host, &bytes, &mut on_sweep);
    }
    stream.finish(&mut on_sweep);
    let st = stream.stats().clone();
    prop_assert_eq!(
        st.malformed + st.late + st.crc_failures + st.wrong_sensor,
        0,
        "{:?}",
        st
    );
    prop_assert_eq!(st.missing_columns, 0, "{:?}", st);
    prop_assert_eq!(
        sweeps.len() as u64,
        frames,
        "one sweep per frame: {:?}",
        sweeps
    );
    for (k, &(index, frame_id, n)) in sweeps.iter().enumerate() {
        prop_assert_eq!(index, sweeps[0].0 + k as u64, "consecutive sweep indices");
        let want = ((first_frame + k as u64) % (1u64 << bits)) as u32;
        prop_assert_eq!(frame_id, want, "frame id of sweep {}", k);
        prop_assert_eq!(
            Some(&n),
            expected_points.get(&want),
            "points of frame {}",
            want
        );
    }
    Ok(())
}

#[test]
fn frame_id_wraps_are_seamless() {
    for profile in [
        Profile::Rng19Rfl8Sig16Nir16,
        Profile::Rng15Rfl8Nir8Dual,
        Profile::FusaRng15Rfl8Nir8Dual,
        Profile::Legacy,
    ] {
        let top: u64 = if profile == Profile::FusaRng15Rfl8Nir8Dual {
            1 << 32
        } else {
            1 << 16
        };
        let mut runner = runner(cases(6));
        runner
            .run(&(1u64..4, 3u64..6), |(before, frames)| {
                wrap_case(profile, top - before, frames)
            })
            .unwrap_or_else(|e| panic!("{profile}: {e}"));
    }
}
