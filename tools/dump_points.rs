//! Decodes the Velodyne data packets of a pcap with ringscan, packet by packet, and writes every
//! point as raw little-endian f32 records, for side-by-side checks against reference decoders
//! (`tools/hdl64e_reference.py`).
//!
//! ```text
//! cargo run --release --example dump_points -- --model hdl64e-s2 --mode strongest \
//!     --calib 64e_s2.1-sztaki.yaml --out points.f32 capture.pcap
//! ```
//! Every UDP payload of 1206 bytes is one packet, decoded on its own with time base 0, so `t`
//! is the firing offset within its packet. Record (8 × f32): `x, y, z` (m, REP 103),
//! `intensity` (raw reflectivity), `ring`, `t` (µs after the packet stamp), `return` (0
//! strongest / only, 1 last), `corrected intensity` (HDL-64E focal formula; single-return
//! packets only, NaN otherwise or without an HDL-64E calibration). No range filter.
//!
//! Ouster (`tools/sim_reference.py`): `--metadata FILE.json --out points.f32 capture.pcap`
//! decodes every datagram of the metadata's lidar packet size (IPv4 fragments reassembled)
//! with `OusterDecoder::decode_with`. Record (10 × f32): `x, y, z` (m, sensor frame),
//! `reflectivity`, `return` (0 / 1), `row`, `column` (measurement id), `frame_id`,
//! `range_mm`, `signal`.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use ringscan::sensor::velodyne::calib::parse_velodyne;
use ringscan::sensor::velodyne::decode::corrected_intensity;
use ringscan::sensor::velodyne::model::BLOCKS;
use ringscan::sensor::velodyne::model::DATA_PACKET_LEN;
use ringscan::sensor::velodyne::model::SLOTS;
use ringscan::sensor::velodyne::wire::DataPacket;
use ringscan::sensor::velodyne::ReturnMode;
use ringscan::sensor::velodyne::VelodyneDecoder;
use ringscan::sensor::velodyne::VelodyneModel;
use ringscan::sensor::DecodeOptions;
use ringscan::source::pcap::PcapSource;

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let Some(meta) = arg(&args, "--metadata") {
        return ouster(&args, &meta);
    }
    let model = VelodyneModel::from_id(&arg(&args, "--model").ok_or("--model M is required")?)
        .ok_or("unknown --model")?;
    let mode = match arg(&args, "--mode").as_deref() {
        None | Some("strongest") => ReturnMode::Strongest,
        Some("last") => ReturnMode::Last,
        Some("dual") => ReturnMode::Dual,
        Some(m) => return Err(format!("unknown --mode {m}").into()),
    };
    let calib_path = arg(&args, "--calib").ok_or("--calib FILE is required")?;
    let calib = parse_velodyne(&std::fs::read_to_string(&calib_path)?, &calib_path)?;
    let out_path = arg(&args, "--out").ok_or("--out FILE is required")?;
    let input = args
        .last()
        .filter(|a| !a.starts_with("--"))
        .ok_or("the last argument is the pcap")?;
    let dec = VelodyneDecoder::new(model, mode, &calib, DecodeOptions::default())?;
    let mut src = PcapSource::open(Path::new(input))?;
    let mut out = BufWriter::new(File::create(&out_path)?);
    let (mut packets, mut points) = (0usize, 0usize);
    let mut pts = Vec::new();
    while let Some(d) = src.next_datagram()? {
        if d.payload.len() != DATA_PACKET_LEN {
            continue;
        }
        let p = DataPacket::new(d.payload)?;
        pts.clear();
        dec.decode(&p, 0, &mut pts);
        // Single return: the points come in (block, slot) order of the non-zero distances.
        let raws: Vec<(usize, u16, u8)> = if mode.is_dual() {
            Vec::new()
        } else {
            (0..BLOCKS)
                .flat_map(|b| (0..SLOTS).map(move |s| (b, s)))
                .filter(|&(b, s)| p.distance(b, s) != 0)
                .map(|(b, s)| {
                    let bank = p.bank(b).unwrap_or(0);
                    (
                        model.laser_of(bank, s),
                        p.distance(b, s),
                        p.reflectivity(b, s),
                    )
                })
                .collect()
        };
        for (i, pt) in pts.iter().enumerate() {
            let corrected = match raws.get(i) {
                Some(&(laser, raw, refl)) if calib.advanced => calib
                    .lasers
                    .get(laser)
                    .map_or(f32::NAN, |l| corrected_intensity(l, refl, raw)),
                _ => f32::NAN,
            };
            let rec = [
                pt.x,
                pt.y,
                pt.z,
                pt.intensity,
                f32::from(pt.ring),
                pt.t as f32 / 1_000.0,
                f32::from(pt.ret),
                corrected,
            ];
            for v in rec {
                out.write_all(&v.to_le_bytes())?;
            }
        }
        packets += 1;
        points += pts.len();
    }
    out.flush()?;
    eprintln!(
        "{out_path}: {points} points from {packets} packets ({} {mode})",
        model.name()
    );
    Ok(())
}

fn ouster(args: &[String], meta: &str) -> Result<(), Box<dyn std::error::Error>> {
    let info = ringscan::sensor::ouster::calib::parse(&std::fs::read_to_string(meta)?, meta)?;
    let dec = ringscan::sensor::ouster::OusterDecoder::new(&info)?;
    let out_path = arg(args, "--out").ok_or("--out FILE is required")?;
    let input = args
        .last()
        .filter(|a| !a.starts_with("--"))
        .ok_or("the last argument is the pcap")?;
    let mut src = PcapSource::open(Path::new(input))?;
    let mut out = BufWriter::new(File::create(&out_path)?);
    let (mut packets, mut points) = (0usize, 0usize);
    let len = info.lidar_packet_bytes();
    let mut recs: Vec<[f32; 10]> = Vec::new();
    while let Some(d) = src.next_datagram()? {
        if d.payload.len() != len {
            continue;
        }
        let p = dec.packet(d.payload)?;
        let frame = p.frame_id() as f32;
        recs.clear();
        dec.decode_with(&p, 0, |pt, x, row, col| {
            recs.push([
                pt.x,
                pt.y,
                pt.z,
                pt.intensity,
                f32::from(pt.ret),
                row as f32,
                col as f32,
                frame,
                x.range_mm as f32,
                f32::from(x.signal),
            ]);
        })?;
        for r in &recs {
            for v in r {
                out.write_all(&v.to_le_bytes())?;
            }
        }
        packets += 1;
        points += recs.len();
    }
    out.flush()?;
    eprintln!("{out_path}: {points} points from {packets} Ouster packets");
    Ok(())
}
