//! Real sweeps for the pipeline tests, the pipeline bench and `tools/pipeline_dump.rs`,
//! decoded by ringscan's own stream assemblers from the captures in `../shared/captures`.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use ringscan::sensor::ouster::calib as ouster;
use ringscan::sensor::ouster::OusterStream;
use ringscan::sensor::ouster::OusterStreamConfig;
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::StreamConfig;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::velodyne::VelodyneStream;
use ringscan::sensor::DecodeOptions;
use ringscan::source::pcap::PcapSource;
use ringscan::Point;

/// HDL-32E, 10 Hz, about 50 k points per sweep (VeloView's Monterey capture).
pub const HDL32: (&str, &str) = (
    "Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap",
    "ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml",
);
/// OS-2-128, 1024 × 10, one complete frame of 119 682 points.
pub const OS2_128: (&str, &str) = (
    "ouster-lidar__ouster-sdk/tests/pcaps/OS-2-128-U1_v2.3.0_1024x10.pcap",
    "ouster-lidar__ouster-sdk/tests/pcaps/OS-2-128-U1_v2.3.0_1024x10.json",
);

/// `../shared/captures` beside the repository, if present (prints a SKIP line if not).
pub fn captures() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/captures");
    if p.join("INVENTORY.md").is_file() {
        Some(p)
    } else {
        eprintln!("SKIP: {} is absent: real-sweep checks not run", p.display());
        None
    }
}

fn datagrams(path: &Path) -> Vec<(i64, u16, Vec<u8>)> {
    let mut src = PcapSource::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut out = Vec::new();
    while let Some(d) = src
        .next_datagram()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    {
        out.push((d.time_ns, d.dst.port(), d.payload.to_vec()));
    }
    out
}

/// Every sweep of the HDL-32E capture (the first and last are partial turns).
pub fn hdl32_sweeps(root: &Path) -> Vec<Vec<Point>> {
    let calib_path = root.join(HDL32.1);
    let calib = parse_velodyne(
        &std::fs::read_to_string(&calib_path).expect("32db.yaml"),
        "32db.yaml",
    )
    .expect("32db.yaml parses");
    let mut stream = VelodyneStream::new(StreamConfig {
        model: Some(VelodyneModel::Hdl32e),
        calibrations: vec![calib],
        ..StreamConfig::default()
    });
    let mut out = Vec::new();
    for (t, port, payload) in datagrams(&root.join(HDL32.0)) {
        if port == 2368 || port == 8308 {
            stream
                .push(t, &payload, &mut |s, _| out.push(s.points.clone()))
                .expect("HDL-32E stream");
        }
    }
    stream
        .finish(&mut |s, _| out.push(s.points.clone()))
        .expect("HDL-32E stream");
    out
}

/// One full HDL-32E turn: the second sweep of the capture.
pub fn hdl32_sweep(root: &Path) -> Vec<Point> {
    hdl32_sweeps(root).swap_remove(1)
}

/// The complete OS-2-128 frame.
pub fn os2_128_sweep(root: &Path) -> Vec<Point> {
    let meta = root.join(OS2_128.1);
    let info = ouster::parse(
        &std::fs::read_to_string(&meta).expect("OS-2-128 metadata"),
        "OS-2-128 metadata",
    )
    .expect("OS-2-128 metadata parses");
    let port = info.udp_port_lidar;
    let mut stream = OusterStream::new(OusterStreamConfig {
        info,
        metadata_name: "OS-2-128-U1_v2.3.0_1024x10.json".into(),
        crc: None,
        decode: DecodeOptions::default(),
        keep_extras: false,
        keep_columns: false,
    })
    .expect("OS-2-128 stream");
    let mut out: Vec<Vec<Point>> = Vec::new();
    for (t, p, payload) in datagrams(&root.join(OS2_128.0)) {
        if p == port {
            stream.push(t, &payload, &mut |s, _| out.push(s.points.clone()));
        }
    }
    stream.finish(&mut |s, _| out.push(s.points.clone()));
    out.into_iter()
        .max_by_key(|s| s.len())
        .expect("an OS-2-128 frame")
}
