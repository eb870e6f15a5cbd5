//! A rosbag2 directory around `--format ros2` MCAP files: its `metadata.yaml`.
//!
//! The yaml is rosbag2's `rosbag2_bagfile_information`, **version 5** (per-file information,
//! QoS profiles as a YAML string): the newest layout ROS 2 Humble reads, and one every later
//! rosbag2 (and `rosbags`) still reads. Fields as rosbag2's `metadata_io.cpp` writes them:
//! `version`, `storage_identifier` (`mcap`), `duration.nanoseconds`,
//! `starting_time.nanoseconds_since_epoch`, `message_count`, `topics_with_message_count`
//! (`topic_metadata` {`name`, `type`, `serialization_format` `cdr`, `offered_qos_profiles`} and
//! `message_count`), `compression_format` / `compression_mode` (empty: MCAP compresses its own
//! chunks), `relative_file_paths` and `files` (`path`, `starting_time`, `duration`,
//! `message_count`).
//!
//! It lists only files that are complete (summary and footer written), so a bag whose recorder
//! was killed opens with every file it names; [`write_metadata`] replaces the yaml atomically
//! (a temporary file renamed over it), so a reader never sees half of one.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use super::mcap::SinkSummary;

macro_rules! qos {
    ($durability:literal) => {
        concat!(
            "- history: 3\n  depth: 0\n  reliability: 1\n  durability: ",
            $durability,
            "\n  deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n  avoid_ros_namespace_conventions: false"
        )
    };
}

/// The QoS profile offered for every topic but `/tf_static`: reliable, volatile, keep-last
/// (history and depth left to the player, as rosbag2 records them), durations infinite.
pub const QOS_VOLATILE: &str = qos!(2);
/// The QoS of `/tf_static`: transient local, as tf2's static broadcaster offers it, so a
/// late subscriber still gets the transforms.
pub const QOS_TRANSIENT_LOCAL: &str = qos!(1);

/// The QoS profile string of `topic`.
pub fn qos_of(topic: &str) -> &'static str {
    if topic == "/tf_static" {
        QOS_TRANSIENT_LOCAL
    } else {
        QOS_VOLATILE
    }
}

/// One complete file of the bag.
#[derive(Clone, Debug)]
pub struct BagFile {
    /// File name inside the directory.
    pub name: String,
    /// What it holds.
    pub summary: SinkSummary,
}

/// A YAML double-quoted scalar.
fn quoted(s: &str) -> String {
    let mut o = String::with_capacity(s.len() + 2);
    o.push('"');
    for c in s.chars() {
        match c {
            '"' => o.push_str("\\\""),
            '\\' => o.push_str("\\\\"),
            '\n' => o.push_str("\\n"),
            c if c.is_control() => {
                let _ = write!(o, "\\u{:04x}", c as u32);
            }
            c => o.push(c),
        }
    }
    o.push('"');
    o
}

/// The text of `metadata.yaml` for `files` (in order).
pub fn metadata_yaml(files: &[BagFile]) -> String {
    // Topics in order of first appearance, with their type and total count.
    let mut topics: Vec<(String, String, u64)> = Vec::new();
    let mut index: BTreeMap<String, usize> = BTreeMap::new();
    let (mut start, mut end, mut total) = (u64::MAX, 0u64, 0u64);
    for f in files {
        for (topic, ty) in &f.summary.types {
            if !index.contains_key(topic) {
                index.insert(topic.clone(), topics.len());
                topics.push((topic.clone(), ty.clone(), 0));
            }
        }
        for (topic, n) in &f.summary.messages {
            if let Some(&i) = index.get(topic) {
                topics[i].2 += n;
            }
            total += n;
        }
        if let Some((a, b)) = f.summary.bounds {
            start = start.min(a);
            end = end.max(b);
        }
    }
    if start > end {
        (start, end) = (0, 0);
    }
    let mut y = String::with_capacity(4096);
    y.push_str("rosbag2_bagfile_information:\n");
    y.push_str("  version: 5\n");
    y.push_str("  storage_identifier: mcap\n");
    let _ = writeln!(y, "  duration:\n    nanoseconds: {}", end - start);
    let _ = writeln!(y, "  starting_time:\n    nanoseconds_since_epoch: {start}");
    let _ = writeln!(y, "  message_count: {total}");
    if topics.is_empty() {
        y.push_str("  topics_with_message_count: []\n");
    } else {
        y.push_str("  topics_with_message_count:\n");
    }
    for (topic, ty, n) in &topics {
        y.push_str("    - topic_metadata:\n");
        let _ = writeln!(y, "        name: {}", quoted(topic));
        let _ = writeln!(y, "        type: {}", quoted(ty));
        y.push_str("        serialization_format: cdr\n");
        let _ = writeln!(y, "        offered_qos_profiles: {}", quoted(qos_of(topic)));
        let _ = writeln!(y, "      message_count: {n}");
    }
    y.push_str("  compression_format: \"\"\n");
    y.push_str("  compression_mode: \"\"\n");
    if files.is_empty() {
        y.push_str("  relative_file_paths: []\n  files: []\n");
        return y;
    }
    y.push_str("  relative_file_paths:\n");
    for f in files {
        let _ = writeln!(y, "    - {}", quoted(&f.name));
    }
    y.push_str("  files:\n");
    for f in files {
        let (a, b) = f.summary.bounds.unwrap_or((0, 0));
        let n: u64 = f.summary.messages.values().sum();
        let _ = writeln!(y, "    - path: {}", quoted(&f.name));
        let _ = writeln!(
            y,
            "      starting_time:\n        nanoseconds_since_epoch: {a}"
        );
        let _ = writeln!(y, "      duration:\n        nanoseconds: {}", b - a);
        let _ = writeln!(y, "      message_count: {n}");
    }
    y
}

/// Writes `dir/metadata.yaml` for `files`, atomically: `metadata.yaml.tmp-ringscan`, synced,
/// then renamed over the old one.
pub fn write_metadata(dir: &Path, files: &[BagFile]) -> io::Result<()> {
    let path = dir.join("metadata.yaml");
    let temp = super::mcap::temp_path(&path);
    let text = metadata_yaml(files);
    let written = (|| {
        let mut f = std::fs::File::create(&temp)?;
        f.write_all(text.as_bytes())?;
        f.sync_all()
    })();
    if let Err(e) = written.and_then(|()| std::fs::rename(&temp, &path)) {
        let _ = std::fs::remove_file(&temp);
        return Err(e);
    }
    Ok(())
}

/// Whether `--out PATH` with `--format ros2` names a rosbag2 directory (anything but a file
/// ending in `.mcap`).
pub fn is_bag_dir(path: &Path) -> bool {
    !path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
}

/// The storage file `index` of the bag directory `dir`: `<dir>/<dir name>_<index>.mcap`, as
/// rosbag2 names them.
pub fn file_path(dir: &Path, index: usize) -> PathBuf {
    let stem = dir
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "bag".to_string());
    dir.join(format!("{stem}_{index}.mcap"))
}

/// Creates the directory (it may exist, but must not hold a `metadata.yaml` already: a bag is
/// not overwritten) and writes an empty `metadata.yaml`.
pub fn create_dir(dir: &Path) -> io::Result<()> {
    std::fs::create_dir_all(dir)?;
    if dir.join("metadata.yaml").exists() {
        return Err(io::Error::new(
            io::ErrorKind::AlreadyExists,
            format!(
                "{} already holds a rosbag2 (metadata.yaml); choose another --out",
                dir.display()
            ),
        ));
    }
    write_metadata(dir, &[])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_kinds() {
        assert!(is_bag_dir(Path::new("/x/run")));
        assert!(is_bag_dir(Path::new("/x/run.bag")));
        assert!(!is_bag_dir(Path::new("/x/run.MCAP")));
        assert_eq!(
            file_path(Path::new("/x/run"), 3),
            PathBuf::from("/x/run/run_3.mcap")
        );
    }

    #[test]
    fn yaml_sums_files() {
        let mut a = SinkSummary::default();
        a.messages.insert("/points".into(), 2);
        a.messages.insert("/tf_static".into(), 1);
        a.types
            .insert("/points".into(), "sensor_msgs/msg/PointCloud2".into());
        a.types
            .insert("/tf_static".into(), "tf2_msgs/msg/TFMessage".into());
        a.bounds = Some((100, 150));
        let mut b = a.clone();
        b.bounds = Some((200, 260));
        let y = metadata_yaml(&[
            BagFile {
                name: "r_0.mcap".into(),
                summary: a,
            },
            BagFile {
                name: "r_1.mcap".into(),
                summary: b,
            },
        ]);
        assert!(y.contains("  message_count: 6\n"), "{y}");
        assert!(y.contains("nanoseconds_since_epoch: 100\n"), "{y}");
        assert!(y.contains("  duration:\n    nanoseconds: 160\n"), "{y}");
        assert!(y.contains("      message_count: 4\n"), "{y}");
        assert!(y.contains("durability: 1"), "{y}");
        assert_eq!(y.matches("- topic_metadata:").count(), 2);
    }
}
