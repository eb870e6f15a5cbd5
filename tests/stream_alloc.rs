//! "No allocation per packet": once warm, the core's streams allocate nothing while they decode
//! datagrams into sweeps. A counting global allocator (test-only; the library itself forbids
//! `unsafe`), switched on for this thread only, watches each `Demux::push` of a real capture of
//! every family with real packets (Velodyne, Ouster, Hesai, Robosense), through the same
//! family-agnostic interface the CLI and the Python package use. The consumer of the sweeps
//! only counts them.
//!
//! Warm means: after the first sweeps, whose buffers grow to the sensor's size (a sweep's
//! point buffer is reused for the next one). From then on a push may allocate only where a
//! sweep is larger than every sweep before it (its buffer grows, once); so the pushes that
//! allocate are at most a few per sweep, never one per packet.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

use ringscan::sensor::{claim, parse_calibration, CalibrationPool, StreamSettings};
use ringscan::sweep::demux::Demux;

struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

fn note() {
    // `try_with`: the thread-local may be gone while a thread ends.
    if COUNTING.try_with(Cell::get).unwrap_or(false) {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator; counting is the only
// addition.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made by this thread while `f` runs.
fn counted<T>(f: impl FnOnce() -> T) -> (T, u64) {
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    COUNTING.with(|c| c.set(true));
    let r = f();
    COUNTING.with(|c| c.set(false));
    (r, ALLOCATIONS.load(Ordering::Relaxed) - before)
}

struct Run {
    packets: usize,
    sweeps: usize,
    warm_packets: usize,
    warm_sweeps: usize,
    /// Pushes after warm-up that allocated, and their allocations.
    allocating_pushes: usize,
    allocations: u64,
}

/// The datagrams of `pcap`, `copies` times over. The real Ouster captures hold 1–3 frames:
/// each copy's lidar packets (`lidar_len` bytes, standard header) get frame ids after the last
/// copy's, so the stream sees one run of frames.
fn datagrams(pcap: &Path, copies: usize, lidar_len: Option<usize>) -> Vec<(i64, u16, Vec<u8>)> {
    let one = common::datagrams(pcap);
    let span = one.last().map_or(0, |d| d.0 - one[0].0) + 100_000_000;
    let fid = |p: &[u8]| u16::from_le_bytes([p[2], p[3]]);
    let ids: Vec<u16> = one
        .iter()
        .filter(|d| Some(d.2.len()) == lidar_len)
        .map(|d| fid(&d.2))
        .collect();
    let (lo, hi) = (ids.iter().min().copied(), ids.iter().max().copied());
    let frames = lo.zip(hi).map_or(0, |(lo, hi)| hi.wrapping_sub(lo) + 1);
    let mut out = Vec::new();
    for k in 0..copies {
        for (t, port, p) in &one {
            let mut p = p.clone();
            if Some(p.len()) == lidar_len {
                let id = fid(&p).wrapping_add(frames.wrapping_mul(k as u16));
                p[2..4].copy_from_slice(&id.to_le_bytes());
            }
            out.push((t + k as i64 * span, *port, p));
        }
    }
    out
}

/// Every datagram of `pcap` (`copies` times) through a demultiplexer with `calibs`; sweeps
/// after the first `warm_up` are the measured part.
fn run(pcap: &Path, calibs: &[&Path], copies: usize, warm_up: usize) -> Run {
    let ouster_len = calibs.iter().find_map(|p| {
        let name = p.file_name().unwrap().to_string_lossy();
        let text = std::fs::read_to_string(p).ok()?;
        ringscan::sensor::ouster::calib::parse(&text, &name)
            .ok()
            .map(|i| i.lidar_packet_bytes())
    });
    let datagrams = datagrams(pcap, copies, ouster_len);
    let calibs = calibs
        .iter()
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy();
            parse_calibration(&std::fs::read(p).unwrap(), &name, None).unwrap()
        })
        .collect();
    let mut pool = CalibrationPool::new(calibs, StreamSettings::default());
    let mut demux = Demux::new(Box::new(move |d| claim(d, &mut pool)), None);
    let src = std::net::Ipv4Addr::new(10, 0, 0, 1);
    let (mut sweeps, mut points) = (0usize, 0usize);
    let mut r = Run {
        packets: datagrams.len(),
        sweeps: 0,
        warm_packets: 0,
        warm_sweeps: 0,
        allocating_pushes: 0,
        allocations: 0,
    };
    for (t, port, payload) in &datagrams {
        let warm = sweeps >= warm_up;
        let sweeps_before = sweeps;
        let (res, n) = counted(|| {
            let r = demux.push(*t, src, *port, payload, &mut |_, s, _| {
                sweeps += 1;
                points += s.points.len();
            });
            // As the CLI does after every datagram: the IMU and zone queues are drained.
            if let Ok(Some(idx)) = r {
                if let Some(s) = demux.stream_mut(idx) {
                    s.drain_imu(&mut |_, _| {});
                    s.drain_zones(&mut |_| {});
                }
            }
            r
        });
        assert!(res.is_ok(), "{}", pcap.display());
        if warm {
            r.warm_packets += 1;
            r.warm_sweeps += sweeps - sweeps_before;
            if n > 0 {
                r.allocating_pushes += 1;
                r.allocations += n;
            }
        }
    }
    demux.finish(&mut |_, _, _| sweeps += 1).unwrap();
    r.sweeps = sweeps;
    assert!(points > 0, "{}: no points", pcap.display());
    r
}

#[test]
fn streams_allocate_nothing_per_packet_once_warm() {
    let Some(root) = common::captures() else {
        return;
    };
    let gt = "tier4__nebula/src/nebula_hesai/nebula_hesai/test_resources/decoder_ground_truth";
    let hesai_cal = "tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration";
    let ouster = "ouster-lidar__ouster-sdk/tests/pcaps";
    // (name, capture, calibration files, copies of the capture); the first two sweeps warm up
    // (one for the QT128 capture, which holds three).
    let cases: Vec<(&str, String, Vec<String>, usize)> = vec![
        (
            "Velodyne HDL-32E",
            "Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap".into(),
            vec!["ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml".into()],
            1,
        ),
        (
            "Velodyne VLP-16 dual",
            "tier4__nebula/src/nebula_velodyne/nebula_velodyne/test_resources/decoder_ground_truth/vlp16/1673400471837873222/1673400471837873222_0.pcap".into(),
            vec![],
            1,
        ),
        (
            "Ouster OS-1-128 low data, fragmented",
            format!("{ouster}/OS-1-128_v2.3.0_1024x10_lb_n3.pcap"),
            vec![format!("{ouster}/OS-1-128_v2.3.0_1024x10.json")],
            5,
        ),
        (
            "Ouster OS-2-128",
            format!("{ouster}/OS-2-128-U1_v2.3.0_1024x10.pcap"),
            vec![format!("{ouster}/OS-2-128-U1_v2.3.0_1024x10.json")],
            5,
        ),
        (
            "Hesai XT32",
            format!("{gt}/xt32/1673400677802009732/1673400677802009732_0.pcap"),
            vec![format!("{hesai_cal}/PandarXT32.csv")],
            1,
        ),
        (
            "Hesai QT128",
            format!("{gt}/qt128/1730273789074637152/1730273789074637152_0.pcap"),
            vec![format!("{hesai_cal}/PandarQT128.csv")],
            1,
        ),
        (
            "Hesai Pandar40P",
            format!("{gt}/40p/1673400149412331409/1673400149412331409_0.pcap"),
            vec![format!("{hesai_cal}/Pandar40P.csv")],
            1,
        ),
        (
            "Robosense Helios-16P",
            "tier4__nebula__pr79/nebula_tests/data/robosense/helios16P/rosbag2_2023_08_03-11_02_46/rosbag2_2023_08_03-11_02_46_0.pcap".into(),
            vec!["tier4__nebula__pr79/nebula_decoders/calibration/robosense/RobosenseHelios16P.csv".into()],
            1,
        ),
    ];
    println!("| capture | packets | sweeps | measured packets (sweeps) | pushes that allocated | allocations |");
    println!("|---|---|---|---|---|---|");
    for (name, pcap, calibs, copies) in cases {
        let calibs: Vec<_> = calibs.iter().map(|c| root.join(c)).collect();
        let calib_refs: Vec<&Path> = calibs.iter().map(|p| p.as_path()).collect();
        let warm_up = if name.contains("QT128") { 1 } else { 2 };
        let r = run(&root.join(&pcap), &calib_refs, copies, warm_up);
        println!(
            "| {name} | {} | {} | {} ({}) | {} | {} |",
            r.packets, r.sweeps, r.warm_packets, r.warm_sweeps, r.allocating_pushes, r.allocations
        );
        assert!(
            r.warm_packets >= 100 && r.warm_sweeps >= 1,
            "{name}: too little measured"
        );
        // A sweep larger than all before it grows its buffer: a few reallocations per sweep at
        // most (doubling), never one per packet.
        assert!(
            r.allocating_pushes <= 4 * (r.warm_sweeps + 1),
            "{name}: {} of {} pushes allocated ({} allocations) over {} sweeps",
            r.allocating_pushes,
            r.warm_packets,
            r.allocations,
            r.warm_sweeps
        );
    }
}

/// A Robosense DIFOP (1 Hz) once the stream is decoding allocates nothing: the facts it renews
/// (serial and firmware as hex) are written over the strings already held. The real capture
/// holds one DIFOP, at its start; it is sent again after the last MSOP packet.
#[test]
fn a_robosense_difop_once_warm_allocates_nothing() {
    let Some(root) = common::captures() else {
        return;
    };
    let pcap = root.join("tier4__nebula__pr79/nebula_tests/data/robosense/helios16P/rosbag2_2023_08_03-11_02_46/rosbag2_2023_08_03-11_02_46_0.pcap");
    let datagrams = common::datagrams(&pcap);
    let difop = datagrams
        .iter()
        .find(|d| d.1 == 7788)
        .cloned()
        .expect("the capture's DIFOP");
    let mut pool = CalibrationPool::new(Vec::new(), StreamSettings::default());
    let mut demux = Demux::new(Box::new(move |d| claim(d, &mut pool)), None);
    let src = std::net::Ipv4Addr::new(10, 0, 0, 1);
    let mut points = 0usize;
    for (t, port, payload) in &datagrams {
        demux
            .push(*t, src, *port, payload, &mut |_, s, _| {
                points += s.points.len()
            })
            .unwrap();
    }
    assert!(points > 0, "the DIFOP's table decodes the capture");
    let t = datagrams.last().unwrap().0 + 1_000_000;
    for k in 0..3 {
        let (res, n) = counted(|| demux.push(t + k, src, 7788, &difop.2, &mut |_, _, _| {}));
        assert!(res.is_ok());
        assert_eq!(n, 0, "DIFOP {k} allocated {n} times");
    }
}
