//! Helpers shared by the integration tests: where the real captures are, reading goldens.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// CRC-32/MPEG-2 (poly 0x04C11DB7, init 0xFFFFFFFF, not reflected, no final xor) bit by bit:
/// the tests' own, apart from the library's table-driven one.
pub fn crc32_mpeg2_bitwise(data: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in data {
        c ^= u32::from(b) << 24;
        for _ in 0..8 {
            c = if c & 0x8000_0000 != 0 {
                (c << 1) ^ 0x04C1_1DB7
            } else {
                c << 1
            };
        }
    }
    c
}

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

/// What a stream made of a run of datagrams ([`run_stream`]): each sweep's (points, packets),
/// and the run's missing packets, discontinuities and copies dropped.
pub type StreamRun = (Vec<(usize, u32)>, u64, u64, u64);

/// Pushes `packets[k]` (host time, payload) for each `k` of `order` through `stream`, then
/// finishes it.
pub fn run_stream(
    stream: &mut dyn ringscan::sensor::SensorStream,
    packets: &[(i64, Vec<u8>)],
    order: &[usize],
) -> StreamRun {
    let mut sweeps = Vec::new();
    let mut on_sweep = |sw: &mut ringscan::sweep::Sweep, _: &dyn ringscan::sensor::Facts| {
        sweeps.push((sw.points.len(), sw.packets))
    };
    for &k in order {
        stream
            .push(packets[k].0, &packets[k].1, &mut on_sweep)
            .unwrap();
    }
    stream.finish(&mut on_sweep).unwrap();
    let (summary, counts) = stream.summary();
    let discontinuities = summary["discontinuities"].as_u64().unwrap_or(0);
    let copies = summary["duplicates"].as_u64().unwrap_or(0);
    (sweeps, counts.missing, discontinuities, copies)
}

/// `0..len` with two of the `movable` positions sent twice: one a third of the way in at once
/// (a copy right behind its packet), one two thirds in again three of them later (a copy that
/// comes as late as a reordered packet).
pub fn with_copies(len: usize, movable: &[usize]) -> Vec<usize> {
    let n = movable.len();
    let mut order: Vec<usize> = (0..len).collect();
    let (a, b) = (movable[2 * n / 3], movable[2 * n / 3 + 3]);
    order.insert(b + 1, a);
    let c = movable[n / 3];
    order.insert(c + 1, c);
    order
}

/// `0..len` with two of the `movable` positions swapped (a sixth of the way in) and one moved
/// three of them later (half way): a packet a place late and one three places late.
pub fn reordered(len: usize, movable: &[usize]) -> Vec<usize> {
    let n = movable.len();
    let mut order: Vec<usize> = (0..len).collect();
    order.swap(movable[n / 6], movable[n / 6 + 1]);
    let late = order.remove(movable[n / 2]);
    order.insert(movable[n / 2 + 3], late);
    order
}

/// A packet of a simulated run: (device time, host time, payload, points it holds).
pub type SimPacket = (i64, i64, Vec<u8>, usize);

/// Pushes `packets` through `stream` except those whose device time lies in `lost`, then
/// checks what every family's loss test asks: each point handed over once, the loss counted,
/// no discontinuity, and no sweep longer than `max_sweep_ns` (its points' `t`).
pub fn check_a_loss(
    stream: &mut dyn ringscan::sensor::SensorStream,
    packets: &[SimPacket],
    lost: std::ops::Range<i64>,
    max_sweep_ns: i64,
    label: &str,
) {
    let (mut sent, mut got, mut longest) = (0usize, 0usize, 0u32);
    let mut on_sweep = |sw: &mut ringscan::sweep::Sweep, _: &dyn ringscan::sensor::Facts| {
        got += sw.points.len();
        longest = longest.max(sw.points.iter().map(|p| p.t).max().unwrap_or(0));
    };
    for (t, host, bytes, points) in packets {
        if !lost.contains(t) {
            sent += points;
            stream.push(*host, bytes, &mut on_sweep).unwrap();
        }
    }
    stream.finish(&mut on_sweep).unwrap();
    let (summary, counts) = stream.summary();
    assert_eq!(got, sent, "{label}: every point once");
    assert!(counts.missing > 0, "{label}");
    assert_eq!(summary["discontinuities"].as_u64(), Some(0), "{label}");
    assert!(
        i64::from(longest) < max_sweep_ns,
        "{label}: a sweep of {longest} ns"
    );
}
