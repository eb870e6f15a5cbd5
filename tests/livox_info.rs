//! What `ringscan info` says of a Livox sensor (`Family::describe` over the stream's summary),
//! against what the simulator sent: the point and IMU packets it wrote and the returns it cast.
#![cfg(feature = "sim")]

use ringscan::sensor::livox::model::LivoxModel;
use ringscan::sensor::livox::sim::LivoxSim;
use ringscan::sensor::livox::{LivoxConfig, LivoxStream};
use ringscan::sensor::SensorStream;
use ringscan::sim::motion::{Route, Trajectory};
use ringscan::sim::scenes;

const T0: i64 = 1_714_564_800_000_000_000;

#[test]
fn info_words_what_the_simulator_sent() {
    let model = LivoxModel::Mid360;
    let mut sim = LivoxSim::new(model, T0);
    sim.trajectory = Trajectory::route(T0, Route::urban());
    let (mut truth, mut imu_truth) = (Vec::new(), Vec::new());
    let packets = sim.run_until(
        &scenes::urban(),
        T0 + 300_000_000,
        &mut truth,
        &mut imu_truth,
    );
    let mut s = LivoxStream::new(LivoxConfig::new(Some(model), model.protocol()));
    for (host, _, b) in &packets {
        s.push(*host, b, &mut |_, _| {});
    }
    s.finish(&mut |_, _| {});
    let (mut v, _) = SensorStream::summary(&s);
    // What the demultiplexer adds to each sensor's entry.
    v["name"] = "mid360-12".into();
    v["address"] = "192.168.1.12".into();
    v["ports"] = serde_json::json!([56301, 56401]);
    let text = ringscan::sensor::family("livox")
        .expect("the livox family")
        .describe(&v)
        .join("\n");
    let imu = imu_truth.len();
    for want in [
        "Livox MID-360, protocol livox-sdk2, data type 1, 4 lines".to_string(),
        format!("{} point + {imu} IMU packets", packets.len() - imu),
        format!("{} points", truth.len()),
        format!("CRC: {} ok, 0 failed", packets.len()),
    ] {
        assert!(text.contains(&want), "{want:?} not in:\n{text}");
    }
    eprintln!("{text}");
}
