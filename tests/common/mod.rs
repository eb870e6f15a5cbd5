//! Helpers shared by the integration tests: where the real captures are, reading goldens.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// `../shared/captures` beside the repository, if present.
pub fn captures() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/captures");
    if p.join("golden").is_dir() {
        Some(p)
    } else {
        eprintln!(
            "SKIP: {} is absent: real-capture checks not run",
            p.display()
        );
        None
    }
}

/// Reads a little-endian f32 dump of records of `fields` values.
pub fn read_f32_records(path: &Path, fields: usize) -> Vec<Vec<f32>> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(
        bytes.len() % (4 * fields),
        0,
        "{}: size not a multiple of the record",
        path.display()
    );
    bytes
        .chunks_exact(4 * fields)
        .map(|r| {
            r.chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect()
        })
        .collect()
}

/// Every UDP payload of a pcap with its capture time and destination port, in file order.
pub fn datagrams(path: &Path) -> Vec<(i64, u16, Vec<u8>)> {
    let mut src = ringscan::source::pcap::PcapSource::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut out = Vec::new();
    while let Some(d) = src
        .next_datagram()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    {
        out.push((d.time_ns, d.dst.port(), d.payload.to_vec()));
    }
    out
}

/// Every datagram of a ROS bag (any kind `source::bag` reads) with its time and destination
/// port, in bag order.
pub fn bag_datagrams(path: &Path) -> Vec<(i64, u16, Vec<u8>)> {
    use ringscan::source::bag::{BagOptions, BagSource};
    let mut src = BagSource::open(path, BagOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut out = Vec::new();
    while let Some(d) = src
        .next_datagram()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    {
        out.push((d.time_ns, d.dst.port(), d.payload.to_vec()));
    }
    out
}

/// A path in a folder of its own in the temporary folder; the folder and everything in it are
/// removed when this is dropped, at the end of the test that holds it, passed or failed (tests
/// of one binary run at once, so each gets its own folder rather than a shared one).
pub struct Scratch {
    dir: PathBuf,
    path: PathBuf,
}

impl Scratch {
    /// A fresh, empty folder `ringscan-{prefix}-{pid}-{n}`.
    pub fn dir(prefix: &str) -> Self {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let dir =
            std::env::temp_dir().join(format!("ringscan-{prefix}-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        Self {
            path: dir.clone(),
            dir,
        }
    }

    /// The path `name` in a fresh folder (the file itself is not created).
    pub fn file(prefix: &str, name: &str) -> Self {
        let mut s = Self::dir(prefix);
        s.path = s.dir.join(name);
        s
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<std::ffi::OsStr> for Scratch {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.path.as_os_str()
    }
}
