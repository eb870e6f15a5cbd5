//! MCAP reading helpers shared by the CLI tests, and the foxglove message mirrors
//! (`ringscan::sink::read`: declared from Foxglove's `.proto` files and decoded by prost,
//! independently of the crate's hand-written encoders) under short names.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::Path;

#[allow(unused_imports)]
pub use ringscan::sink::read::{
    CubePrimitive as Cube, FrameTransform, KeyValuePair as Kv, PackedElementField as Field,
    PointCloud, Pose, Quaternion as Q, SceneEntity as Entity, SceneEntityDeletion as Deletion,
    SceneUpdate, Vector3 as V3,
};

/// Message bodies per topic, in file order.
pub type ByTopic = BTreeMap<String, Vec<Vec<u8>>>;

/// Messages per topic, in file order, and each channel's schema name.
pub fn read_mcap(path: &Path) -> (ByTopic, BTreeMap<String, String>) {
    let bytes = std::fs::read(path).unwrap();
    let mut by_topic: ByTopic = BTreeMap::new();
    let mut schemas = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let topic = m.channel.topic.clone();
        if let Some(s) = &m.channel.schema {
            schemas.insert(topic.clone(), s.name.clone());
        }
        by_topic.entry(topic).or_default().push(m.data.to_vec());
    }
    (by_topic, schemas)
}

/// Runs the `ringscan` binary.
pub fn ringscan(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_ringscan"))
        .args(args)
        .output()
        .unwrap()
}

/// A path in the temporary directory, unique to this test process.
pub fn out_path(test: &str, name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("ringscan-{test}-{}-{name}", std::process::id()))
}
