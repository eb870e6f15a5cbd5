//! The sensor simulator: a spinning Velodyne in a ray-cast room, written as a pcap.
//!
//! ```text
//! cargo run --release --example simulate -- --model vlp16 --seconds 1 --out fixtures/demo-vlp16.pcap
//! ```
//! Options: `--model M` (vlp16, puck-hires, hdl32e, vlp32c, hdl64e-s2, hdl64e-s3, vls128),
//! `--mode strongest|last|dual`, `--seconds S`, `--hz F` (rotation rate), `--calib FILE`
//! (required for HDL-64E / VLS-128 unless `--spread`), `--gps` (position packets with PPS
//! locked and a GPRMC sentence), `--drop-every N` (drop every N-th data packet), `--out FILE`.
//! Sources: sensor 192.168.1.201, data to port 2368, position packets to 8308.

use std::fs::File;
use std::io::BufWriter;
use std::net::{Ipv4Addr, SocketAddrV4};

use ringscan::calib::{builtin::builtin, parse_velodyne, LaserCalibration, VelodyneCalibration};
use ringscan::model::{ReturnMode, VelodyneModel};
use ringscan::sim::net::{udp_frame, PcapWriter};
use ringscan::sim::scene::Shapes;
use ringscan::sim::velodyne::{encode_position_packet, VelodyneSim};

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn spread(n: usize) -> VelodyneCalibration {
    let lasers = (0..n)
        .map(|i| {
            LaserCalibration::angles(
                i as u16,
                (-24.9 + 26.9 * i as f64 / (n - 1) as f64).to_radians(),
                0.0,
            )
        })
        .collect();
    VelodyneCalibration {
        lasers,
        distance_resolution: None,
        advanced: false,
        source: "evenly spread".into(),
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let model = VelodyneModel::from_id(&arg(&args, "--model").unwrap_or_else(|| "vlp16".into()))
        .ok_or("unknown --model")?;
    let mode = match arg(&args, "--mode").as_deref() {
        None | Some("strongest") => ReturnMode::Strongest,
        Some("last") => ReturnMode::Last,
        Some("dual") => ReturnMode::Dual,
        Some(m) => return Err(format!("unknown --mode {m}").into()),
    };
    let seconds: f64 = arg(&args, "--seconds")
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(1.0);
    let hz: f64 = arg(&args, "--hz")
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(10.0);
    let out = arg(&args, "--out").ok_or("--out FILE is required")?;
    let drop_every: usize = arg(&args, "--drop-every")
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(0);
    let gps = args.iter().any(|a| a == "--gps");
    let calib = match arg(&args, "--calib") {
        Some(p) => parse_velodyne(&std::fs::read_to_string(&p)?, &p)?,
        None if args.iter().any(|a| a == "--spread") => spread(model.lasers()).validate()?,
        None => builtin(model).ok_or("this model needs --calib FILE (or --spread)")?,
    };
    // 2024-05-01 12:00:00 UTC, sensor top-of-hour counter at 0.
    let t0_ns: i64 = 1_714_564_800_000_000_000;
    let mut sim = VelodyneSim::new(model, mode, calib, t0_ns);
    sim.deg_per_s = 360.0 * hz;
    sim.azimuth0_deg = 200.0;
    let scene = Shapes::room(14.0, 9.0, 1.8, 4.5);
    let mut pcap = PcapWriter::new(BufWriter::new(File::create(&out)?))?;
    let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 2368);
    let dst = SocketAddrV4::new(Ipv4Addr::new(255, 255, 255, 255), 2368);
    let pos_src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 8308);
    let pos_dst = SocketAddrV4::new(Ipv4Addr::new(255, 255, 255, 255), 8308);
    let n = (seconds * 1e9 / sim.period_ns()).round() as u64;
    let mut truth = Vec::new();
    let mut next_pos_s = 0u64;
    for i in 0..n {
        truth.clear();
        let (host, payload) = sim.next_packet(&scene, &mut truth);
        if gps && (host - t0_ns) / 1_000_000_000 >= next_pos_s as i64 {
            let s = next_pos_s;
            let body = format!(
                "GPRMC,12{:02}{:02},A,3707.8324,N,12139.2864,W,000.0,144.7,010524,013.8,E,D",
                s / 60,
                s % 60
            );
            let cs = body.bytes().fold(0u8, |a, c| a ^ c);
            let pos =
                encode_position_packet((s * 1_000_000) as u32, 2, &format!("${body}*{cs:02X}\r\n"));
            pcap.write(host, &udp_frame(pos_src, pos_dst, i as u16, &pos))?;
            next_pos_s += 1;
        }
        if drop_every > 0 && (i as usize + 1) % drop_every == 0 {
            continue;
        }
        pcap.write(host, &udp_frame(src, dst, i as u16, &payload))?;
    }
    pcap.into_inner()?;
    eprintln!(
        "wrote {out}: {n} {} packets ({mode}), {seconds} s at {hz} Hz",
        model.name()
    );
    Ok(())
}
