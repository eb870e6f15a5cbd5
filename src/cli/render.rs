//! `ringscan render RUN.mcap --sweep N --out bev.png`: a bird's-eye picture of one sweep of a
//! file written with `--pipeline`: ground grey, obstacles coloured by cluster, each cluster's
//! yaw-oriented box outlined, a 1 m / 10 m grid and a scale note. Drawn here pixel by pixel;
//! the `png` crate only encodes the image.
//!
//! The file is streamed (`mcap`'s sans-IO linear reader over 1 MiB reads) and reading stops
//! once the sweep's messages are in: memory does not grow with the file.

use std::fs::File;
use std::io::{Read, Seek};
use std::path::PathBuf;
use std::process::ExitCode;

use crate::sink::read::{PointCloud, Quaternion, SceneUpdate};
use crate::sink::scene::cluster_color;
use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader};
use prost::Message as _;

use super::run::RunError;

/// `ringscan render`.
#[derive(clap::Args, Debug)]
pub struct RenderCmd {
    /// An MCAP written by `ringscan decode --pipeline …` (either `--format`).
    input: PathBuf,
    /// Sweep to draw (0 = the first the pipeline processed).
    #[arg(long, default_value_t = 0)]
    sweep: u32,
    /// Output PNG.
    #[arg(long, short)]
    out: PathBuf,
    /// Sensor topic prefix when the file holds several sensors (e.g. `/vlp16-201`).
    #[arg(long, default_value = "")]
    sensor: String,
    /// Half-width of the square drawn, metres (0.5 … 10000).
    #[arg(long, default_value_t = 40.0, value_parser = parse_range_m, allow_negative_numbers = true)]
    range_m: f64,
    /// Image side, pixels (64 … 4096).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u32).range(64..=4096))]
    size_px: u32,
}

/// One sweep's pipeline outputs, as read back.
#[derive(Default)]
struct Frame {
    ground: Vec<[f32; 2]>,
    /// x, y, cluster.
    obstacles: Vec<(f32, f32, u32)>,
    /// centre x, y, length, width, yaw (rad), cluster index.
    boxes: Vec<(f64, f64, f64, f64, f64, u32)>,
    frame_id: String,
}

/// Asked for what the file does not hold (exit 2).
fn bad(path: &str, msg: impl std::fmt::Display) -> RunError {
    RunError::Usage(format!("{path}: {msg}"))
}

/// The file could not be read, parsed or written (exit 1).
fn failed(path: &str, msg: impl std::fmt::Display) -> RunError {
    RunError::File(format!("{path}: {msg}"))
}

/// x, y (and the `cluster` field, if any) of a point cloud's points.
fn points_of(pc: &PointCloud) -> Option<Vec<(f32, f32, u32)>> {
    let (x, y) = (pc.offset("x")?, pc.offset("y")?);
    let stride = pc.point_stride as usize;
    if stride == 0 || x + 4 > stride || y + 4 > stride {
        return None;
    }
    let clusters: Vec<u32> = match pc.offset("cluster") {
        Some(c) if c + 4 <= stride => pc.u32s(c).collect(),
        Some(_) => return None,
        None => Vec::new(),
    };
    Some(
        pc.f32s(x)
            .zip(pc.f32s(y))
            .enumerate()
            .map(|(i, (x, y))| (x, y, clusters.get(i).copied().unwrap_or(0)))
            .collect(),
    )
}

fn read_frame(cmd: &RenderCmd) -> Result<Frame, RunError> {
    let path = cmd.input.display().to_string();
    let mut file = File::open(&cmd.input).map_err(|e| failed(&path, e))?;
    // Said plainly, rather than as the MCAP reader's `Bad magic number`.
    let mut magic = [0u8; 8];
    let is_mcap = match file.read_exact(&mut magic) {
        Ok(()) => magic[..] == *mcap::MAGIC,
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => false,
        Err(e) => return Err(failed(&path, e)),
    };
    if !is_mcap {
        return Err(failed(
            &path,
            "not an MCAP file (render draws the MCAP that `ringscan decode --pipeline default \
             --out RUN.mcap` writes)",
        ));
    }
    file.seek(std::io::SeekFrom::Start(0))
        .map_err(|e| failed(&path, e))?;
    let mut reader = LinearReader::new();
    let topics = [
        format!("{}/ground", cmd.sensor),
        format!("{}/obstacles", cmd.sensor),
        format!("{}/clusters", cmd.sensor),
    ];
    let mut ids: [Option<u16>; 3] = [None; 3];
    // `--format ros2` files hold the same topics in CDR (`PointCloud2`, `MarkerArray`).
    let mut cdr = [false; 3];
    let mut got = [false; 3];
    let mut frame = Frame::default();
    // Every pipeline prefix in the file, to name them when the one asked for is absent.
    let mut prefixes: Vec<String> = Vec::new();
    // Sweeps the file holds (its ground messages), for the error of a sweep it does not.
    let mut ground_messages = 0u64;
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| failed(&path, e))? {
            LinearReadEvent::ReadRequest(n) => {
                let buf = reader.insert(n.clamp(4096, 1 << 20));
                let read = file.read(buf).map_err(|e| failed(&path, e))?;
                reader.notify_read(read);
            }
            LinearReadEvent::Record { data, opcode } => {
                match mcap::parse_record(opcode, data).map_err(|e| failed(&path, e))? {
                    Record::Channel(c) => {
                        if let Some(i) = topics.iter().position(|t| *t == c.topic) {
                            ids[i] = Some(c.id);
                            cdr[i] = c.message_encoding == "cdr";
                        }
                        if let Some(p) = c.topic.strip_suffix("/ground") {
                            if prefixes.len() < 64 && !prefixes.iter().any(|q| q == p) {
                                prefixes.push(p.to_string());
                            }
                        }
                    }
                    Record::Message { header, data } => {
                        let Some(i) = ids.iter().position(|&id| id == Some(header.channel_id))
                        else {
                            continue;
                        };
                        if i == 0 {
                            ground_messages += 1;
                        }
                        if header.sequence != cmd.sweep || got[i] {
                            continue;
                        }
                        got[i] = true;
                        if i < 2 {
                            let pc = if cdr[i] {
                                PointCloud::from_cdr(&data).map_err(|e| failed(&path, e))?
                            } else {
                                PointCloud::decode(&data[..]).map_err(|e| failed(&path, e))?
                            };
                            let pts = points_of(&pc)
                                .ok_or_else(|| failed(&path, "a point cloud without x, y"))?;
                            frame.frame_id = pc.frame_id.clone();
                            if i == 0 {
                                frame.ground = pts.iter().map(|p| [p.0, p.1]).collect();
                            } else {
                                frame.obstacles = pts;
                            }
                        } else {
                            let u = if cdr[i] {
                                SceneUpdate::from_cdr_markers(&data)
                                    .map_err(|e| failed(&path, e))?
                            } else {
                                SceneUpdate::decode(&data[..]).map_err(|e| failed(&path, e))?
                            };
                            for e in &u.entities {
                                let k: u32 = e.id.parse().unwrap_or(0);
                                for c in &e.cubes {
                                    let pose = c.pose.clone().unwrap_or_default();
                                    let p = pose.position.unwrap_or_default();
                                    let q = pose.orientation.unwrap_or(Quaternion {
                                        x: 0.0,
                                        y: 0.0,
                                        z: 0.0,
                                        w: 1.0,
                                    });
                                    let yaw = 2.0 * q.z.atan2(q.w);
                                    let s = c.size.clone().unwrap_or_default();
                                    frame.boxes.push((p.x, p.y, s.x, s.y, yaw, k));
                                }
                            }
                        }
                        if got.iter().all(|&g| g) {
                            return Ok(frame);
                        }
                    }
                    _ => {}
                }
            }
        }
    }
    if ids.iter().any(Option::is_none) {
        return Err(bad(
            &path,
            if prefixes.is_empty() {
                format!(
                    "no {} channels: write the file with `ringscan decode --pipeline default`",
                    topics.join(", ")
                )
            } else {
                format!(
                    "no {} channels; pipeline outputs here: --sensor {}",
                    topics.join(", "),
                    prefixes
                        .iter()
                        .map(|p| if p.is_empty() { "\"\"" } else { p.as_str() })
                        .collect::<Vec<_>>()
                        .join(" or --sensor ")
                )
            },
        ));
    }
    Err(bad(
        &path,
        format!(
            "sweep {} is not in the file, which holds {ground_messages} (--sweep 0 … {})",
            cmd.sweep,
            ground_messages.saturating_sub(1)
        ),
    ))
}

/// An RGB image with clipped drawing.
struct Canvas {
    w: u32,
    h: u32,
    px: Vec<u8>,
}

impl Canvas {
    fn new(w: u32, h: u32, bg: [u8; 3]) -> Self {
        let mut px = Vec::with_capacity((w * h * 3) as usize);
        for _ in 0..w * h {
            px.extend_from_slice(&bg);
        }
        Self { w, h, px }
    }
    fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.w && (y as u32) < self.h {
            let i = ((y as u32 * self.w + x as u32) * 3) as usize;
            self.px[i..i + 3].copy_from_slice(&c);
        }
    }
    fn dot(&mut self, x: f64, y: f64, r: i64, c: [u8; 3]) {
        let (cx, cy) = (x.round() as i64, y.round() as i64);
        for dy in -r..=r {
            for dx in -r..=r {
                if dx * dx + dy * dy <= r * r {
                    self.put(cx + dx, cy + dy, c);
                }
            }
        }
    }
    /// A line of `width` pixels (DDA).
    fn line(&mut self, (x0, y0): (f64, f64), (x1, y1): (f64, f64), width: i64, c: [u8; 3]) {
        let n = (x1 - x0)
            .abs()
            .max((y1 - y0).abs())
            .ceil()
            .clamp(1.0, 100_000.0) as i64;
        for i in 0..=n {
            let t = i as f64 / n as f64;
            let (x, y) = (x0 + (x1 - x0) * t, y0 + (y1 - y0) * t);
            if width <= 1 {
                self.put(x.round() as i64, y.round() as i64, c);
            } else {
                self.dot(x, y, width / 2, c);
            }
        }
    }
    fn text(&mut self, x: i64, y: i64, scale: i64, s: &str, c: [u8; 3]) {
        let mut cx = x;
        for ch in s.chars() {
            if let Some(rows) = glyph(ch) {
                for (r, bits) in rows.iter().enumerate() {
                    for col in 0..5 {
                        if bits & (0b10000 >> col) != 0 {
                            for sy in 0..scale {
                                for sx in 0..scale {
                                    self.put(cx + col * scale + sx, y + r as i64 * scale + sy, c);
                                }
                            }
                        }
                    }
                }
            }
            cx += 6 * scale;
        }
    }
}

/// A 5×7 bitmap of the characters the scale note uses (rows top to bottom, bit 4 = left).
fn glyph(c: char) -> Option<[u8; 7]> {
    Some(match c.to_ascii_uppercase() {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x0A, 0x04, 0x04, 0x04, 0x04],
        '/' => [0x01, 0x01, 0x02, 0x04, 0x08, 0x10, 0x10],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ',' => [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        ' ' => [0; 7],
        _ => return None,
    })
}

/// `--range-m`: a finite half-width of 0.5 … 10,000 m (a bad value was replaced by 40 m
/// without a word).
fn parse_range_m(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(m) if (0.5..=10_000.0).contains(&m) => Ok(m),
        _ => Err(format!("`{s}`: expected metres, 0.5 … 10000")),
    }
}

fn rgb(c: [f32; 3]) -> [u8; 3] {
    c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
}

fn draw(frame: &Frame, cmd: &RenderCmd) -> Canvas {
    let size = cmd.size_px.clamp(64, 4096);
    let range = if cmd.range_m.is_finite() && cmd.range_m > 0.5 {
        cmd.range_m
    } else {
        40.0
    };
    let px_per_m = f64::from(size) / (2.0 * range);
    let c = f64::from(size) / 2.0;
    // x forward = up, y left = left.
    let to_px = |x: f64, y: f64| (c - y * px_per_m, c - x * px_per_m);
    let mut img = Canvas::new(size, size, [18, 20, 24]);
    // Grid: every metre faint (when at least 4 px apart), every 10 m brighter.
    let r = range.ceil() as i64;
    for m in -r..=r {
        let ten = m % 10 == 0;
        if !ten && px_per_m < 4.0 {
            continue;
        }
        let col = if m == 0 {
            [90, 96, 110]
        } else if ten {
            [60, 66, 78]
        } else {
            [32, 35, 42]
        };
        let v = m as f64;
        img.line(to_px(v, -range), to_px(v, range), 1, col);
        img.line(to_px(-range, v), to_px(range, v), 1, col);
    }
    let dot = if px_per_m >= 20.0 { 1 } else { 0 };
    for p in &frame.ground {
        let (x, y) = to_px(f64::from(p[0]), f64::from(p[1]));
        img.dot(x, y, dot, [150, 150, 150]);
    }
    for &(x, y, k) in &frame.obstacles {
        let (px, py) = to_px(f64::from(x), f64::from(y));
        img.dot(px, py, dot.max(1), rgb(cluster_color(k)));
    }
    for &(x, y, l, w, yaw, k) in &frame.boxes {
        let (cy, sy) = (yaw.cos(), yaw.sin());
        let corner = |a: f64, b: f64| {
            let (dx, dy) = (a * l / 2.0, b * w / 2.0);
            to_px(x + dx * cy - dy * sy, y + dx * sy + dy * cy)
        };
        let cs = [
            corner(1.0, 1.0),
            corner(-1.0, 1.0),
            corner(-1.0, -1.0),
            corner(1.0, -1.0),
        ];
        let col = rgb(cluster_color(k));
        for i in 0..4 {
            img.line(cs[i], cs[(i + 1) % 4], 2, col);
        }
    }
    // The origin of the frame (the sensor, or base_link with extrinsics): a white triangle
    // pointing forward.
    let o = to_px(0.0, 0.0);
    let tip = to_px(1.5, 0.0);
    img.line(o, tip, 2, [255, 255, 255]);
    img.dot(o.0, o.1, 3, [255, 255, 255]);
    // Scale bar of 10 m and the note.
    let s = (f64::from(size) / 500.0).ceil().max(1.0) as i64;
    let y0 = f64::from(size) - 12.0 * s as f64;
    let x0 = 10.0 * s as f64;
    img.line(
        (x0, y0),
        (x0 + 10.0 * px_per_m, y0),
        s.max(2),
        [230, 230, 230],
    );
    img.text(
        x0 as i64,
        (y0 - 12.0 * s as f64) as i64,
        s,
        &format!(
            "10 M   GRID 1 M / 10 M   SWEEP {}   CLUSTERS {}",
            cmd.sweep,
            frame.boxes.len()
        ),
        [230, 230, 230],
    );
    img.text(
        10 * s,
        6 * s,
        s,
        &format!(
            "GROUND {}   OBSTACLES {}   X UP, Y LEFT",
            frame.ground.len(),
            frame.obstacles.len()
        ),
        [230, 230, 230],
    );
    img
}

/// Runs `ringscan render`.
pub fn render_command(cmd: &RenderCmd) -> Result<ExitCode, RunError> {
    // Only PNG is written: a `.jpg` name would hold PNG bytes that its readers refuse.
    if crate::cli::run::same_file(&cmd.out, &cmd.input) {
        return Err(RunError::Usage(format!(
            "--out {}: the same file as the input; the picture would replace the MCAP",
            cmd.out.display()
        )));
    }
    // Without an extension, a viewer would not know the file for a picture.
    if !cmd
        .out
        .extension()
        .is_some_and(|ext| ext.eq_ignore_ascii_case("png"))
    {
        return Err(RunError::Usage(format!(
            "--out {}: render writes PNG only; give a name ending in .png",
            cmd.out.display()
        )));
    }
    // A device or directory at --out would be replaced by the rename: refused first.
    let target = crate::cli::run::output_file_path(&cmd.out, "PNG")?;
    let frame = read_frame(cmd)?;
    let img = draw(&frame, cmd);
    let out = cmd.out.display().to_string();
    // Encoded in memory and renamed into place, so a failed write (disk full) leaves no
    // truncated PNG at the path, nor spoils a picture already there.
    let mut png_bytes = Vec::new();
    let mut enc = png::Encoder::new(&mut png_bytes, img.w, img.h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Best);
    let mut w = enc.write_header().map_err(|e| failed(&out, e))?;
    w.write_image_data(&img.px).map_err(|e| failed(&out, e))?;
    w.finish().map_err(|e| failed(&out, e))?;
    let mut tmp = target.clone().into_os_string();
    tmp.push(".tmp-ringscan");
    let tmp = std::path::PathBuf::from(tmp);
    let written = std::fs::write(&tmp, &png_bytes).and_then(|()| std::fs::rename(&tmp, &target));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(failed(&out, e));
    }
    outln!(
        "{out}: sweep {} of {} ({} frame): {} ground, {} obstacle points, {} clusters",
        cmd.sweep,
        cmd.input.display(),
        frame.frame_id,
        frame.ground.len(),
        frame.obstacles.len(),
        frame.boxes.len()
    );
    Ok(ExitCode::SUCCESS)
}
