//! The sensor simulator: a spinning Velodyne or Ouster moving through a ray-cast scene, written
//! as a pcap or sent live over UDP, with per-point ground truth and the true trajectory.
//!
//! ```text
//! cargo run --release --example simulate -- --model vlp16 --seconds 1 --out fixtures/demo-vlp16.pcap
//! # deskew: 15 m/s with 60 °/s yaw, per-point world truth
//! cargo run --release --example simulate -- --model hdl32e --scene urban --speed 15 --yaw-rate 60 \
//!     --seconds 2 --out drive.pcap --truth drive.truth --poses-out drive.tum
//! # Ouster with IMU, from a real metadata file
//! cargo run --release --example simulate -- --model ouster \
//!     --metadata ../shared/captures/ouster-lidar__ouster-sdk/tests/metadata/3_0_1_os-122246000293-128.json \
//!     --scene urban --speed 15 --yaw-rate 60 --imu --seconds 1 --out os.pcap --truth os.truth
//! # icp: the 500 m urban loop (≈ 41 s), true poses
//! cargo run --release --example simulate -- --model vlp16 --scene urban --route urban \
//!     --out loop.pcap --poses-out loop.tum
//! # live: paced in real time to a UDP port
//! cargo run --release --example simulate -- --model vlp16 --scene urban --route urban --udp 127.0.0.1:2368
//! ```
//!
//! Sensor and output:
//! - `--model M`: vlp16, puck-hires, hdl32e, vlp32c, hdl64e-s2, hdl64e-s3, vls128, `mid360` /
//!   `hap` / `avia` (Livox; `--data-type 1|2|3` for the MID-360 and the HAP, `--imu` adds
//!   their 200 Hz IMU packets; with `--udp ADDR:PORT` an SDK2 model's IMU goes to PORT + 100),
//!   or `ouster` (needs `--metadata FILE.json`; `--profile NAME` overrides its lidar profile, e.g.
//!   `RNG15_RFL8_NIR8`; `--columns W --fps F` its mode). Velodyne: `--mode
//!   strongest|last|dual`, `--hz F` (rotation rate), `--calib FILE` (required for HDL-64E /
//!   VLS-128 unless `--spread`), `--gps` (position packets with PPS locked and a GPRMC sentence),
//!   `--drop-every N` (drop every N-th data packet).
//! - `--model` a Hesai model: `pandar40p`, `pandar64`, `pandarqt64`, `pandarqt128`, `pandarxt16`,
//!   `pandarxt32`, `pandarxt32m`, `pandarat128`, `pandarot128`; `--calib FILE` (required: its
//!   angle correction CSV, or the AT128's `.dat`), `--mode strongest|dual`, `--hz F` (turns per
//!   second; AT128: frames per second). Packets from 192.168.1.201 to port 2368.
//! - `--imu`: Ouster IMU packets (the metadata's IMU profile, 100 Hz samples) consistent with
//!   the motion.
//! - `--out FILE.pcap` or `--udp ADDR:PORT` (data to PORT; Velodyne position packets to 8308,
//!   Ouster IMU to the metadata's IMU port or 7503, on ADDR), paced in real time, or `--rate X`
//!   times faster (`--rate 0`: as fast as possible).
//! - `--seconds S` of sensor time (default 1 s; with `--route` / `--poses` their duration).
//!
//! Scene and motion:
//! - `--scene room|urban|corridor|flat_floor|flat|slope10|ramp|kerbs` (default `room`, a
//!   sensor-centred room; the others are `ringscan::sim::scenes`, ground at z = 0).
//! - `--speed M/S --yaw-rate DEG/S`: a constant twist (forward speed, yaw rate) from the start
//!   pose; `--route urban`: the urban loop (`Route::urban`, use with `--scene urban`);
//!   `--poses FILE.tum`: interpolate a TUM trajectory (`t x y z qx qy qz qw`, world_from_sensor;
//!   the run starts at its first time and lasts to its last unless `--seconds`);
//!   none of these: a static sensor. The start pose is `--start X,Y,Z,YAW_DEG` (default
//!   0,0,0,0 in `room`, 0,0,1.8,0 elsewhere; the urban street's (40,0,1.8,0) in `urban`).
//!
//! Truth:
//! - `--truth FILE`: one 40-byte record per simulated return (sensor-frame xyz at its firing
//!   time, world xyz, firing time ns, label 0 = ground / object id, channel, ring, return):
//!   the format of `ringscan::sim::truth`, which reads it.
//! - `--poses-out FILE.tum`: the true `world_from_sensor` every `--poses-step-ms` (default 1 ms)
//!   over the run, TUM text, times in seconds on the packets' clock.
//!
//! Time: the run starts at 2024-05-01 12:00:00 UTC (Velodyne top-of-hour 0), or at the first
//! time of `--poses`; truth times and pcap timestamps are ns since the epoch on that clock. Sources: Velodyne 192.168.1.201,
//! Ouster 192.168.1.202.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::time::{Duration, Instant};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use ringscan::sensor::hesai::family::parse_hesai_calibration;
use ringscan::sensor::hesai::sim::HesaiSim;
use ringscan::sensor::hesai::{HesaiCalibration, HesaiModel};
use ringscan::sensor::livox::model::{LivoxModel, Protocol};
use ringscan::sensor::livox::sim::LivoxSim;
use ringscan::sensor::ouster::calib::OusterInfo;
use ringscan::sensor::ouster::model::Profile;
use ringscan::sensor::ouster::sim::OusterSim;
use ringscan::sensor::velodyne::calib::builtin::builtin;
use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::calib::LaserCalibration;
use ringscan::sensor::velodyne::calib::VelodyneCalibration;
use ringscan::sensor::velodyne::sim::encode_position_packet;
use ringscan::sensor::velodyne::sim::VelodyneSim;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sim::motion::PoseTable;
use ringscan::sim::motion::Route;
use ringscan::sim::motion::Trajectory;
use ringscan::sim::net::udp_frame;
use ringscan::sim::net::PcapWriter;
use ringscan::sim::scene::Scene;
use ringscan::sim::scene::Shapes;
use ringscan::sim::scenes;
use ringscan::sim::truth::TruthRecord;
use ringscan::sim::truth::TruthWriter;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn num<T: std::str::FromStr>(args: &[String], name: &str) -> Res<Option<T>>
where
    T::Err: std::error::Error + 'static,
{
    Ok(arg(args, name).map(|s| s.parse::<T>()).transpose()?)
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

/// Where packets go: a pcap or a UDP socket, paced.
enum Sink {
    Pcap(PcapWriter<BufWriter<File>>),
    Udp {
        sock: UdpSocket,
        host: Ipv4Addr,
        start: Instant,
        t0_ns: i64,
        rate: f64,
    },
}

impl Sink {
    fn send(
        &mut self,
        host_ns: i64,
        src: SocketAddrV4,
        port: u16,
        id: u16,
        payload: &[u8],
    ) -> Res<()> {
        match self {
            Sink::Pcap(w) => {
                let dst = SocketAddrV4::new(Ipv4Addr::new(255, 255, 255, 255), port);
                w.write(host_ns, &udp_frame(src, dst, id, payload))?;
            }
            Sink::Udp {
                sock,
                host,
                start,
                t0_ns,
                rate,
            } => {
                if *rate > 0.0 {
                    let due = Duration::from_secs_f64(
                        ((host_ns - *t0_ns) as f64 * 1e-9 / *rate).max(0.0),
                    );
                    if let Some(wait) = due.checked_sub(start.elapsed()) {
                        std::thread::sleep(wait);
                    }
                }
                sock.send_to(payload, SocketAddr::V4(SocketAddrV4::new(*host, port)))?;
            }
        }
        Ok(())
    }

    fn finish(self) -> Res<()> {
        if let Sink::Pcap(w) = self {
            w.into_inner()?;
        }
        Ok(())
    }
}

fn start_pose(args: &[String], scene: &str) -> Res<Isometry3<f64>> {
    let default = match scene {
        "room" => [0.0, 0.0, 0.0, 0.0],
        "urban" => [40.0, 0.0, scenes::SENSOR_HEIGHT_M, 0.0],
        _ => [0.0, 0.0, scenes::SENSOR_HEIGHT_M, 0.0],
    };
    let v = match arg(args, "--start") {
        None => default,
        Some(s) => {
            let f: Vec<f64> = s
                .split(',')
                .map(|x| x.trim().parse())
                .collect::<Result<_, _>>()?;
            if f.len() != 4 {
                return Err("--start X,Y,Z,YAW_DEG".into());
            }
            [f[0], f[1], f[2], f[3]]
        }
    };
    Ok(Isometry3::from_parts(
        Translation3::new(v[0], v[1], v[2]),
        UnitQuaternion::from_euler_angles(0.0, 0.0, v[3].to_radians()),
    ))
}

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    // 2024-05-01 12:00:00 UTC, sensor top-of-hour counter at 0; with --poses, the table's
    // first time (the run follows the table's clock).
    let poses = match arg(&args, "--poses") {
        Some(p) => Some(
            PoseTable::parse_tum(&std::fs::read_to_string(&p)?).map_err(|e| format!("{p}: {e}"))?,
        ),
        None => None,
    };
    let t0_ns: i64 = poses
        .as_ref()
        .map_or(1_714_564_800_000_000_000, PoseTable::first_ns);

    let scene_name = arg(&args, "--scene").unwrap_or_else(|| "room".into());
    let scene: Box<dyn Scene> = if scene_name == "room" {
        Box::new(Shapes::room(14.0, 9.0, 1.8, 4.5))
    } else {
        Box::new(scenes::named(&scene_name).ok_or_else(|| {
            format!(
                "unknown --scene {scene_name} (room, {})",
                scenes::NAMES.join(", ")
            )
        })?)
    };

    let start = start_pose(&args, &scene_name)?;
    let speed: Option<f64> = num(&args, "--speed")?;
    let yaw_rate: Option<f64> = num(&args, "--yaw-rate")?;
    let mut route_s = None;
    let trajectory = if let Some(r) = arg(&args, "--route") {
        if r != "urban" {
            return Err(format!("unknown --route {r} (urban)").into());
        }
        let route = Route::urban();
        route_s = Some(route.duration_s());
        Trajectory::route(t0_ns, route)
    } else if let Some(table) = poses {
        let last = table.poses.last().map_or(t0_ns, |p| p.0);
        route_s = Some((last - t0_ns) as f64 * 1e-9);
        Trajectory::poses(table)
    } else if speed.is_some() || yaw_rate.is_some() {
        Trajectory::twist(
            t0_ns,
            start,
            Vector3::new(speed.unwrap_or(0.0), 0.0, 0.0),
            Vector3::new(0.0, 0.0, yaw_rate.unwrap_or(0.0).to_radians()),
        )
    } else {
        Trajectory::fixed(start)
    };
    let seconds: f64 = num(&args, "--seconds")?.or(route_s).unwrap_or(1.0);
    let rate: f64 = num(&args, "--rate")?.unwrap_or(1.0);

    let mut sink = match (arg(&args, "--out"), arg(&args, "--udp")) {
        (Some(out), None) => Sink::Pcap(PcapWriter::new(BufWriter::new(File::create(out)?))?),
        (None, Some(addr)) => {
            let a: SocketAddrV4 = addr.parse()?;
            let sock = UdpSocket::bind("0.0.0.0:0")?;
            sock.set_broadcast(true)?;
            Sink::Udp {
                sock,
                host: *a.ip(),
                start: Instant::now(),
                t0_ns,
                rate,
            }
        }
        _ => return Err("give one of --out FILE.pcap or --udp ADDR:PORT".into()),
    };
    let udp_port = arg(&args, "--udp")
        .and_then(|a| a.parse::<SocketAddrV4>().ok())
        .map(|a| a.port());
    let mut truth_out = match arg(&args, "--truth") {
        Some(p) => Some(TruthWriter::new(BufWriter::new(File::create(p)?))?),
        None => None,
    };
    let end_ns = t0_ns + (seconds * 1e9).round() as i64;
    let model_name = arg(&args, "--model").unwrap_or_else(|| "vlp16".into());
    let mut records = 0u64;

    if let Some(model) = ringscan::sensor::livox::LivoxModel::from_id(&model_name)
        .filter(|m| matches!(m, LivoxModel::Mid360 | LivoxModel::Hap | LivoxModel::Avia))
    {
        // Livox: MID-360 (SDK2; points from 56300 to 56301, IMU from 56400 to 56401), HAP
        // (SDK2; points from and to 57000, IMU from and to 58000) or Avia (SDK1; points and IMU
        // to 56001), IMU packets at 200 Hz with `--imu`.
        let mut sim = LivoxSim::new(model, t0_ns);
        sim.trajectory = trajectory.clone();
        if let Some(dt) = num::<u8>(&args, "--data-type")? {
            sim.data_type = dt;
        }
        let imu = args.iter().any(|a| a == "--imu");
        let ip = Ipv4Addr::new(192, 168, 1, 12);
        let (psrc, isrc) = match model {
            LivoxModel::Mid360 => (SocketAddrV4::new(ip, 56_300), SocketAddrV4::new(ip, 56_400)),
            LivoxModel::Hap => (SocketAddrV4::new(ip, 57_000), SocketAddrV4::new(ip, 58_000)),
            _ => (SocketAddrV4::new(ip, 65_000), SocketAddrV4::new(ip, 65_000)),
        };
        let mut truth = Vec::new();
        let mut imu_truth = Vec::new();
        let packets = sim.run_until(scene.as_ref(), end_ns, &mut truth, &mut imu_truth);
        let mut n = 0u64;
        for (host, port, bytes) in &packets {
            let is_imu = *port == model.imu_port().unwrap_or(0)
                && (model.protocol() == Protocol::Sdk2 || bytes.len() == 42);
            if is_imu && !imu {
                continue;
            }
            let (src, dst) = if is_imu && model.protocol() == Protocol::Sdk2 {
                (isrc, udp_port.map_or(*port, |p| p + 100))
            } else {
                (psrc, udp_port.unwrap_or(*port))
            };
            sink.send(*host, src, dst, n as u16, bytes)?;
            n += 1;
        }
        if let Some(w) = truth_out.as_mut() {
            for t in &truth {
                w.write(&TruthRecord {
                    sensor: t.xyz.map(|v| v as f32),
                    world: t.world.map(|v| v as f32),
                    time_ns: t.time_ns,
                    label: t.label,
                    channel: t.line,
                    ring: t.line as u8,
                    ret: 0,
                })?;
            }
        }
        records += truth.len() as u64;
        eprintln!(
            "{n} {} packets, {seconds} s, scene {scene_name}, {records} returns",
            model.name()
        );
    } else if let Some(model) = HesaiModel::from_id(&model_name) {
        // Hesai: from 192.168.1.201 to port 2368, the beams from the sensor's own angle
        // correction (the CSV, or the AT128's or ATX's .dat).
        let path = arg(&args, "--calib").ok_or_else(|| {
            format!("--model {model_name} needs --calib FILE (its angle correction CSV or .dat)")
        })?;
        let calib = parse_hesai_calibration(&std::fs::read(&path)?)
            .ok_or_else(|| format!("{path}: not a Hesai angle correction"))?
            .map_err(|e| format!("{path}: {e}"))?;
        // Ring = rank of the channel's elevation (0 = lowest), as the decoder numbers them.
        let elevations: Vec<f64> = match &calib {
            HesaiCalibration::Csv(rows) => rows.iter().map(|r| r.elevation_deg).collect(),
            HesaiCalibration::At128(a) => a.elevation.iter().map(|&e| e as f64).collect(),
            HesaiCalibration::Atx(a) => a.elevation_deg.clone(),
            HesaiCalibration::AtxFiretimes(_) => {
                return Err(format!("{path}: an ATX firetime file, not an angle correction").into())
            }
        };
        let ring = |c: usize| {
            let e = elevations.get(c).copied().unwrap_or(0.0);
            elevations
                .iter()
                .enumerate()
                .filter(|&(k, &x)| x < e || (x == e && k < c))
                .count() as u8
        };
        let mut sim = HesaiSim::new(model, calib, t0_ns);
        sim.trajectory = trajectory.clone();
        match arg(&args, "--mode").as_deref() {
            None | Some("strongest") => {}
            Some("dual") => sim.return_mode = 0x39,
            Some(m) => return Err(format!("--mode {m}: strongest or dual for Hesai").into()),
        }
        if let Some(hz) = num::<f64>(&args, "--hz")? {
            // The AT128's encoder turns a third of a turn per frame (three mirrors).
            let per_frame = if model == HesaiModel::PandarAt128 {
                120.0
            } else {
                360.0
            };
            sim.deg_per_s = hz * per_frame;
        }
        let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 2368);
        let mut truth = Vec::new();
        let mut n = 0u64;
        loop {
            truth.clear();
            let (host_ns, bytes) = sim.next_packet(scene.as_ref(), &mut truth);
            if host_ns > end_ns {
                break;
            }
            sink.send(host_ns, src, udp_port.unwrap_or(2368), n as u16, &bytes)?;
            n += 1;
            if let Some(w) = truth_out.as_mut() {
                for t in &truth {
                    w.write(&TruthRecord {
                        sensor: t.xyz.map(|v| v as f32),
                        world: t.world.map(|v| v as f32),
                        time_ns: t.time_ns,
                        label: t.label,
                        channel: t.channel as u16,
                        ring: ring(t.channel),
                        ret: t.ret,
                    })?;
                }
            }
            records += truth.len() as u64;
        }
        eprintln!(
            "{n} {} packets, {seconds} s, scene {scene_name}, {records} returns",
            model.name()
        );
    } else if model_name == "ouster" {
        let meta = arg(&args, "--metadata").ok_or("--model ouster needs --metadata FILE.json")?;
        let mut info: OusterInfo =
            ringscan::sensor::ouster::calib::parse(&std::fs::read_to_string(&meta)?, &meta)?;
        if let Some(p) = arg(&args, "--profile") {
            let profile = Profile::from_name(&p).ok_or_else(|| format!("unknown --profile {p}"))?;
            info.format.profile = profile;
            info.lidar_profile_name = profile.name().to_owned();
        }
        if let Some(w) = num::<usize>(&args, "--columns")? {
            info.columns_per_frame = w;
            info.column_window = (0, w.saturating_sub(1));
        }
        if let Some(f) = num::<u32>(&args, "--fps")? {
            info.fps = f;
        }
        let rings = ringscan::sensor::ouster::OusterDecoder::new(&info)?
            .rings()
            .to_vec();
        let mut sim = OusterSim::new(info.clone(), t0_ns);
        sim.trajectory = trajectory.clone();
        let imu = args.iter().any(|a| a == "--imu");
        let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 202), 7502);
        let lidar_port = udp_port.unwrap_or(if info.udp_port_lidar != 0 {
            info.udp_port_lidar
        } else {
            7502
        });
        let imu_port = if info.udp_port_imu != 0 {
            info.udp_port_imu
        } else {
            7503
        };
        let mut truth = Vec::new();
        let mut n = 0u64;
        // IMU packets generated but not yet sent (sent in host-time order with the lidar
        // packets, none before the first lidar packet, which identifies the sensor).
        let mut pending: std::collections::VecDeque<(i64, Vec<u8>)> = Default::default();
        loop {
            let t_next = t0_ns + (sim.packet_index as f64 * sim.packet_period_ns()).round() as i64;
            if t_next >= end_ns {
                break;
            }
            truth.clear();
            let (host, payload) = sim.next_packet(scene.as_ref(), &mut truth);
            while imu && sim.next_imu_time_ns() < end_ns.min(host) {
                match sim.next_imu_packet() {
                    Some(p) => pending.push_back(p),
                    None => break,
                }
            }
            if n > 0 {
                while pending.front().is_some_and(|p| p.0 <= host) {
                    if let Some((h, b)) = pending.pop_front() {
                        sink.send(h, src, imu_port, n as u16, &b)?;
                    }
                }
            }
            sink.send(host, src, lidar_port, n as u16, &payload)?;
            if let Some(w) = truth_out.as_mut() {
                for t in &truth {
                    let ring = rings.get(usize::from(t.row)).copied().unwrap_or(0);
                    w.write(&TruthRecord::from_ouster(t, ring))?;
                }
            }
            records += truth.len() as u64;
            n += 1;
        }
        for (h, b) in pending {
            sink.send(h, src, imu_port, n as u16, &b)?;
        }
        eprintln!(
            "{n} {} {} {}x{} packets, {seconds} s, scene {scene_name}, {records} returns",
            info.prod_line,
            info.format.profile.name(),
            info.columns_per_frame,
            info.fps
        );
    } else {
        let model = VelodyneModel::from_id(&model_name).ok_or("unknown --model")?;
        let mode = match arg(&args, "--mode").as_deref() {
            None | Some("strongest") => ReturnMode::Strongest,
            Some("last") => ReturnMode::Last,
            Some("dual") => ReturnMode::Dual,
            Some(m) => return Err(format!("unknown --mode {m}").into()),
        };
        let hz: f64 = num(&args, "--hz")?.unwrap_or(10.0);
        let drop_every: usize = num(&args, "--drop-every")?.unwrap_or(0);
        let gps = args.iter().any(|a| a == "--gps");
        let calib = match arg(&args, "--calib") {
            Some(p) => parse_velodyne(&std::fs::read_to_string(&p)?, &p)?,
            None if args.iter().any(|a| a == "--spread") => spread(model.lasers()).validate()?,
            None => builtin(model).ok_or("this model needs --calib FILE (or --spread)")?,
        };
        let rings = calib.rings();
        let mut sim = VelodyneSim::new(model, mode, calib, t0_ns);
        sim.toh0_us = (t0_ns.rem_euclid(3_600_000_000_000) / 1_000) as u32;
        sim.deg_per_s = 360.0 * hz;
        sim.azimuth0_deg = 200.0;
        sim.trajectory = trajectory.clone();
        let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 2368);
        let pos_src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 8308);
        let data_port = udp_port.unwrap_or(2368);
        let n = ((end_ns - t0_ns) as f64 / sim.period_ns()).round() as u64;
        let mut truth = Vec::new();
        let mut next_pos_s = 0u64;
        for i in 0..n {
            truth.clear();
            let (host, payload) = sim.next_packet(scene.as_ref(), &mut truth);
            if gps && (host - t0_ns) / 1_000_000_000 >= next_pos_s as i64 {
                let s = next_pos_s;
                let body = format!(
                    "GPRMC,12{:02}{:02},A,3707.8324,N,12139.2864,W,000.0,144.7,010524,013.8,E,D",
                    s / 60,
                    s % 60
                );
                let cs = body.bytes().fold(0u8, |a, c| a ^ c);
                let pos = encode_position_packet(
                    (s * 1_000_000) as u32,
                    2,
                    &format!("${body}*{cs:02X}\r\n"),
                );
                sink.send(host, pos_src, 8308, i as u16, &pos)?;
                next_pos_s += 1;
            }
            if drop_every > 0 && (i as usize + 1) % drop_every == 0 {
                continue;
            }
            sink.send(host, src, data_port, i as u16, &payload)?;
            if let Some(w) = truth_out.as_mut() {
                for t in &truth {
                    w.write(&TruthRecord::from_velodyne(t, rings[t.laser]))?;
                }
            }
            records += truth.len() as u64;
        }
        eprintln!(
            "{n} {} packets ({mode}), {seconds} s at {hz} Hz, scene {scene_name}, {records} returns",
            model.name()
        );
    }
    sink.finish()?;
    if let Some(w) = truth_out {
        w.into_inner()?;
    }
    if let Some(p) = arg(&args, "--poses-out") {
        let step_ms: f64 = num(&args, "--poses-step-ms")?.unwrap_or(1.0);
        let table = trajectory.sample(t0_ns, end_ns, (step_ms * 1e6).round().max(1.0) as i64);
        let mut f = BufWriter::new(File::create(&p)?);
        f.write_all(b"# world_from_sensor, ringscan simulator: t x y z qx qy qz qw\n")?;
        f.write_all(table.to_tum().as_bytes())?;
        f.flush()?;
    }
    Ok(())
}
