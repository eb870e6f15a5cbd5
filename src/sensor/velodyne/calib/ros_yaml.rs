//! ROS `velodyne_pointcloud` calibration YAML (the schema of ros-drivers `calibration.cc`).
//!
//! ```yaml
//! num_lasers: 64                 # optional; when present it must equal the length of `lasers`
//! distance_resolution: 0.002     # optional, metres
//! lasers:
//! - {laser_id: 0, rot_correction: -0.0698, vert_correction: -0.1249,     # radians
//!    dist_correction: 1.2, dist_correction_x: 1.23, dist_correction_y: 1.21,  # metres
//!    two_pt_correction_available: true, vert_offset_correction: 0.2,
//!    horiz_offset_correction: 0.026, focal_distance: 12.0, focal_slope: 1.4,
//!    min_intensity: 30, max_intensity: 235}
//! ```
//!
//! Units are radians and metres throughout, **including `focal_distance`**: the yaml files are
//! made from db.xml by ros-drivers `gen_calibration.py`, which multiplies `focalDistance_` (cm)
//! by 0.01 like every other length (`64e_s2.1-sztaki.xml` has `focalDistance_` 1200 where
//! `64e_s2.1-sztaki.yaml` has `focal_distance: 12.0`). The ROS decoder then divides that metre
//! value by 13100 as if it were centimetres — the 100× error of ros-drivers issue #499 — so the
//! value is taken as metres here and the intensity formula must use `focal_distance / 131`.
//!
//! Required per laser: `laser_id`, `rot_correction`, `vert_correction`. Everything else is
//! optional (velodyne_decoder's own `.yml` files carry only the three): distances, offsets,
//! focal distance and slope default to 0, `two_pt_correction_available` to false,
//! `min_intensity` / `max_intensity` to 0 / 255 (as `calibration.cc`). Intensities may be written
//! as floats (`40.0`, upstream issue #84) and are floored, then must lie in 0..=255. Unknown keys
//! are ignored. A key repeated in one mapping is accepted only with the same text each time
//! (`angles-calibrated.yaml` repeats `vert_offset_correction: 0`). Anchors, aliases and more
//! than one document are refused. Laser entries may come in any order; duplicate ids, gaps and
//! counts other than 16, 32, 64 or 128 are errors.
//!
//! Lasers whose `two_pt_correction_available` is false (or absent) get
//! `dist_correction_x = dist_correction_y = dist_correction` — see the module docs of
//! [`crate::sensor::calib`] for why that is exactly the references' behaviour.

use std::collections::BTreeMap;

use yaml_rust2::parser::{Event, Parser};
use yaml_rust2::scanner::{Marker, ScanError, TScalarStyle};

use crate::sensor::calib::check_size;
use crate::sensor::calib::parse_decimal;
use crate::sensor::calib::CalibError;
use crate::sensor::velodyne::calib::has_advanced_corrections;
use crate::sensor::velodyne::calib::LaserCalibration;
use crate::sensor::velodyne::calib::VelodyneCalibration;

const FORMAT: &str = "YAML";

/// Deepest nesting accepted; a calibration needs 3 (document map, `lasers` list, laser map).
const MAX_DEPTH: usize = 16;

/// Most YAML nodes accepted in one text (a full 128-laser table has about 3 600).
const MAX_NODES: usize = 100_000;

/// Most keys in one mapping (a laser entry has 14); keeps the duplicate-key check cheap.
const MAX_MAP_KEYS: usize = 256;

/// Parses a ROS velodyne calibration YAML text; `source_name` is kept as the table's source.
pub fn parse(text: &str, source_name: &str) -> Result<VelodyneCalibration, CalibError> {
    check_size(text.len())?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let Some(root) = load(text)? else {
        return Err(CalibError::MissingKey {
            key: "lasers".into(),
            context: " (the text holds no YAML document)".into(),
        });
    };
    let Value::Map(top) = &root.value else {
        return Err(CalibError::BadValue {
            key: "(document)".into(),
            context: root.pos.at(),
            expected: "a mapping with a `lasers` list".into(),
            found: root.describe(),
        });
    };

    let Some(lasers_node) = find(top, "lasers") else {
        return Err(CalibError::MissingKey {
            key: "lasers".into(),
            context: " at the top level of the document".into(),
        });
    };
    let Value::Seq(items) = &lasers_node.value else {
        return Err(bad(
            "lasers",
            lasers_node.pos.at(),
            "a list of laser mappings",
            lasers_node,
        ));
    };

    if let Some(n_node) = find(top, "num_lasers") {
        let n = integer(n_node, "num_lasers", &n_node.pos.at())?;
        if usize::try_from(n).ok() != Some(items.len()) {
            return Err(CalibError::BadValue {
                key: "num_lasers".into(),
                context: n_node.pos.at(),
                expected: format!("{} (the number of entries in `lasers`)", items.len()),
                found: n.to_string(),
            });
        }
    }
    if !matches!(items.len(), 16 | 32 | 64 | 128) {
        return Err(CalibError::Invalid(format!(
            "`lasers` (line {}) holds {} entries; expected 16, 32, 64 or 128",
            lasers_node.pos.line,
            items.len()
        )));
    }

    let distance_resolution = match find(top, "distance_resolution") {
        Some(node) => Some(number(node, "distance_resolution", &node.pos.at())?),
        None => None,
    };

    let mut lasers = Vec::with_capacity(items.len());
    let mut seen: BTreeMap<u16, Pos> = BTreeMap::new();
    for (index, item) in items.iter().enumerate() {
        let laser = parse_laser(index, item)?;
        if let Some(first) = seen.insert(laser.laser_id, item.pos) {
            return Err(CalibError::Invalid(format!(
                "duplicate laser_id {} in lasers[{index}] at line {} (already given at line {})",
                laser.laser_id, item.pos.line, first.line
            )));
        }
        lasers.push(laser);
    }

    let advanced = has_advanced_corrections(&lasers);
    VelodyneCalibration {
        lasers,
        distance_resolution,
        advanced,
        source: source_name.to_owned(),
    }
    .validate()
}

/// One entry of `lasers`.
fn parse_laser(index: usize, item: &Node) -> Result<LaserCalibration, CalibError> {
    let Value::Map(map) = &item.value else {
        return Err(bad(
            &format!("lasers[{index}]"),
            item.pos.at(),
            "a mapping of laser corrections",
            item,
        ));
    };
    let where_ = |pos: Pos, id: Option<i64>| -> String {
        match id {
            Some(id) => format!(" in lasers[{index}] (laser_id {id}){}", pos.at()),
            None => format!(" in lasers[{index}]{}", pos.at()),
        }
    };
    let required = |key: &str, id: Option<i64>| -> Result<&Node, CalibError> {
        find(map, key).ok_or_else(|| CalibError::MissingKey {
            key: key.into(),
            context: where_(item.pos, id),
        })
    };

    let id_node = required("laser_id", None)?;
    let id = integer(id_node, "laser_id", &where_(id_node.pos, None))?;
    let laser_id = u16::try_from(id).map_err(|_| CalibError::BadValue {
        key: "laser_id".into(),
        context: where_(id_node.pos, None),
        expected: "an integer in 0..=65535".into(),
        found: id.to_string(),
    })?;
    let id = Some(id);

    let num = |key: &str| -> Result<f64, CalibError> {
        let node = required(key, id)?;
        number(node, key, &where_(node.pos, id))
    };
    let opt = |key: &str, default: f64| -> Result<f64, CalibError> {
        match find(map, key) {
            Some(node) => number(node, key, &where_(node.pos, id)),
            None => Ok(default),
        }
    };
    let intensity = |key: &str, default: u8| -> Result<u8, CalibError> {
        let Some(node) = find(map, key) else {
            return Ok(default);
        };
        let v = number(node, key, &where_(node.pos, id))?.floor();
        if (0.0..=255.0).contains(&v) {
            Ok(v as u8)
        } else {
            Err(CalibError::BadValue {
                key: key.into(),
                context: where_(node.pos, id),
                expected: "an intensity in 0..=255".into(),
                found: node.text().unwrap_or_default().to_owned(),
            })
        }
    };

    let dist_correction = opt("dist_correction", 0.0)?;
    let two_point = match find(map, "two_pt_correction_available") {
        Some(node) => boolean(node, "two_pt_correction_available", &where_(node.pos, id))?,
        None => false,
    };
    let (dist_correction_x, dist_correction_y) = if two_point {
        (
            opt("dist_correction_x", 0.0)?,
            opt("dist_correction_y", 0.0)?,
        )
    } else {
        // Still type-check the values that are there, then fold the flag in (see module docs).
        opt("dist_correction_x", 0.0)?;
        opt("dist_correction_y", 0.0)?;
        (dist_correction, dist_correction)
    };

    Ok(LaserCalibration {
        laser_id,
        vert_correction: num("vert_correction")?,
        rot_correction: num("rot_correction")?,
        dist_correction,
        dist_correction_x,
        dist_correction_y,
        vert_offset_correction: opt("vert_offset_correction", 0.0)?,
        horiz_offset_correction: opt("horiz_offset_correction", 0.0)?,
        focal_distance: opt("focal_distance", 0.0)?,
        focal_slope: opt("focal_slope", 0.0)?,
        min_intensity: intensity("min_intensity", 0)?,
        max_intensity: intensity("max_intensity", 255)?,
    })
}

// ---------------------------------------------------------------------------------------------
// A small YAML tree with positions, built from yaml-rust2's event stream.

/// 1-based line and column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Pos {
    line: usize,
    column: usize,
}

impl Pos {
    fn from_marker(m: &Marker) -> Self {
        // yaml-rust2 markers: 1-based lines, 0-based columns.
        Self {
            line: m.line(),
            column: m.col() + 1,
        }
    }

    fn at(self) -> String {
        format!(" at line {}, column {}", self.line, self.column)
    }
}

#[derive(Debug)]
enum Value {
    /// A scalar and whether it was quoted (a quoted scalar is always a string).
    Scalar(String, bool),
    Seq(Vec<Node>),
    /// Keys are scalars; order kept.
    Map(Vec<(String, Node)>),
}

#[derive(Debug)]
struct Node {
    value: Value,
    pos: Pos,
}

/// What a plain scalar means in the YAML 1.2 core schema (plus YAML 1.1 booleans, which
/// yaml-cpp — used by the ROS driver — also accepts).
enum Scalar {
    Null,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str,
}

impl Node {
    fn text(&self) -> Option<&str> {
        match &self.value {
            Value::Scalar(s, _) => Some(s),
            _ => None,
        }
    }

    fn scalar(&self) -> Option<Scalar> {
        let Value::Scalar(s, quoted) = &self.value else {
            return None;
        };
        if *quoted {
            return Some(Scalar::Str);
        }
        Some(match s.as_str() {
            "" | "~" | "null" | "Null" | "NULL" => Scalar::Null,
            "true" | "True" | "TRUE" | "yes" | "Yes" | "YES" | "on" | "On" | "ON" => {
                Scalar::Bool(true)
            }
            "false" | "False" | "FALSE" | "no" | "No" | "NO" | "off" | "Off" | "OFF" => {
                Scalar::Bool(false)
            }
            ".inf" | ".Inf" | ".INF" | "+.inf" | "+.Inf" | "+.INF" => Scalar::Float(f64::INFINITY),
            "-.inf" | "-.Inf" | "-.INF" => Scalar::Float(f64::NEG_INFINITY),
            ".nan" | ".NaN" | ".NAN" => Scalar::Float(f64::NAN),
            t => {
                let digits = t.strip_prefix(['+', '-']).unwrap_or(t);
                if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) {
                    match t.parse::<i64>() {
                        Ok(i) => Scalar::Int(i),
                        Err(_) => parse_decimal(t).map_or(Scalar::Str, Scalar::Float),
                    }
                } else {
                    parse_decimal(t).map_or(Scalar::Str, Scalar::Float)
                }
            }
        })
    }

    fn describe(&self) -> String {
        match &self.value {
            Value::Seq(_) => "a list".into(),
            Value::Map(_) => "a mapping".into(),
            Value::Scalar(s, _) => match self.scalar() {
                Some(Scalar::Null) => "nothing (null)".into(),
                Some(Scalar::Bool(b)) => format!("boolean `{s}` ({b})"),
                Some(Scalar::Int(_) | Scalar::Float(_)) => format!("number `{s}`"),
                _ => format!("string {:?}", truncate(s, 40)),
            },
        }
    }
}

fn truncate(s: &str, max: usize) -> String {
    if s.chars().count() <= max {
        s.to_owned()
    } else {
        let mut t: String = s.chars().take(max).collect();
        t.push('…');
        t
    }
}

fn find<'a>(map: &'a [(String, Node)], key: &str) -> Option<&'a Node> {
    map.iter().find(|(k, _)| k == key).map(|(_, v)| v)
}

fn bad(key: &str, context: String, expected: &str, node: &Node) -> CalibError {
    CalibError::BadValue {
        key: key.into(),
        context,
        expected: expected.into(),
        found: node.describe(),
    }
}

/// A finite number (integer or float).
fn number(node: &Node, key: &str, context: &str) -> Result<f64, CalibError> {
    match node.scalar() {
        Some(Scalar::Int(i)) => Ok(i as f64),
        Some(Scalar::Float(f)) if f.is_finite() => Ok(f),
        Some(Scalar::Float(_)) => Err(CalibError::BadValue {
            key: key.into(),
            context: context.into(),
            expected: "a finite number".into(),
            found: format!("`{}`", node.text().unwrap_or_default()),
        }),
        _ => Err(bad(key, context.into(), "a number", node)),
    }
}

fn integer(node: &Node, key: &str, context: &str) -> Result<i64, CalibError> {
    match node.scalar() {
        Some(Scalar::Int(i)) => Ok(i),
        _ => Err(bad(key, context.into(), "an integer", node)),
    }
}

fn boolean(node: &Node, key: &str, context: &str) -> Result<bool, CalibError> {
    match node.scalar() {
        Some(Scalar::Bool(b)) => Ok(b),
        _ => Err(bad(key, context.into(), "true or false", node)),
    }
}

/// A collection being built.
enum Frame {
    Seq(Vec<Node>, Pos),
    /// Entries, start, and the key waiting for its value.
    Map(Vec<(String, Node)>, Pos, Option<(String, Pos)>),
}

fn syntax(pos: Pos, message: impl Into<String>) -> CalibError {
    CalibError::Syntax {
        format: FORMAT,
        line: pos.line,
        column: pos.column,
        message: message.into(),
    }
}

fn scan_error(e: &ScanError) -> CalibError {
    syntax(Pos::from_marker(e.marker()), e.info())
}

/// Reads the whole text into a tree; `None` for a text with no document.
fn load(text: &str) -> Result<Option<Node>, CalibError> {
    let mut parser = Parser::new_from_str(text);
    let mut stack: Vec<Frame> = Vec::new();
    let mut root: Option<Node> = None;
    let mut documents = 0usize;
    let mut nodes = 0usize;
    loop {
        let (event, marker) = parser.next_token().map_err(|e| scan_error(&e))?;
        let pos = Pos::from_marker(&marker);
        if matches!(
            event,
            Event::Scalar(..) | Event::SequenceStart(..) | Event::MappingStart(..)
        ) {
            nodes += 1;
            if nodes > MAX_NODES {
                return Err(syntax(pos, format!("more than {MAX_NODES} YAML nodes")));
            }
        }
        let node = match event {
            Event::StreamEnd => break,
            Event::Nothing | Event::StreamStart | Event::DocumentEnd => continue,
            Event::DocumentStart => {
                documents += 1;
                if documents > 1 {
                    return Err(syntax(
                        pos,
                        "expected one YAML document, found a second one",
                    ));
                }
                continue;
            }
            Event::Alias(_) => {
                return Err(syntax(
                    pos,
                    "aliases (`*name`) are not supported in calibration files",
                ))
            }
            Event::Scalar(text, style, anchor, _tag) => {
                if anchor != 0 {
                    return Err(syntax(
                        pos,
                        "anchors (`&name`) are not supported in calibration files",
                    ));
                }
                Node {
                    value: Value::Scalar(text, style != TScalarStyle::Plain),
                    pos,
                }
            }
            Event::SequenceStart(anchor, _) | Event::MappingStart(anchor, _) => {
                if anchor != 0 {
                    return Err(syntax(
                        pos,
                        "anchors (`&name`) are not supported in calibration files",
                    ));
                }
                if stack.len() >= MAX_DEPTH {
                    return Err(syntax(
                        pos,
                        format!("nesting deeper than {MAX_DEPTH} levels; a calibration needs 3"),
                    ));
                }
                stack.push(if matches!(event, Event::SequenceStart(..)) {
                    Frame::Seq(Vec::new(), pos)
                } else {
                    Frame::Map(Vec::new(), pos, None)
                });
                continue;
            }
            Event::SequenceEnd | Event::MappingEnd => match stack.pop() {
                Some(Frame::Seq(items, start)) => Node {
                    value: Value::Seq(items),
                    pos: start,
                },
                Some(Frame::Map(entries, start, None)) => Node {
                    value: Value::Map(entries),
                    pos: start,
                },
                Some(Frame::Map(_, _, Some((key, key_pos)))) => {
                    return Err(syntax(key_pos, format!("key `{key}` has no value")))
                }
                None => return Err(syntax(pos, "unbalanced end of a collection")),
            },
        };
        match stack.last_mut() {
            None => {
                if root.is_some() {
                    return Err(syntax(
                        pos,
                        "expected one YAML document, found a second one",
                    ));
                }
                root = Some(node);
            }
            Some(Frame::Seq(items, _)) => items.push(node),
            Some(Frame::Map(entries, _, pending)) => match pending.take() {
                None => match node.value {
                    Value::Scalar(key, _) => *pending = Some((key, node.pos)),
                    _ => {
                        return Err(syntax(
                            node.pos,
                            "mapping keys must be plain words or numbers",
                        ))
                    }
                },
                Some((key, key_pos)) => {
                    if let Some((_, first)) = entries.iter().find(|(k, _)| *k == key) {
                        let same = matches!((&first.value, &node.value),
                            (Value::Scalar(a, _), Value::Scalar(b, _)) if a == b);
                        if !same {
                            return Err(syntax(
                                key_pos,
                                format!(
                                    "key `{key}` is given twice with different values \
                                     (first at line {})",
                                    first.pos.line
                                ),
                            ));
                        }
                    } else if entries.len() >= MAX_MAP_KEYS {
                        return Err(syntax(
                            key_pos,
                            format!("more than {MAX_MAP_KEYS} keys in one mapping"),
                        ));
                    } else {
                        entries.push((key, node));
                    }
                }
            },
        }
    }
    Ok(root)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(n: usize, extra: &str) -> String {
        let mut s = format!("num_lasers: {n}\ndistance_resolution: 0.002\nlasers:\n");
        for i in 0..n {
            let v = (10.0 * i as f64 - 200.0) / 1000.0;
            s.push_str(&format!(
                "- {{laser_id: {i}, rot_correction: 0.0, vert_correction: {v}{extra}}}\n"
            ));
        }
        s
    }

    #[test]
    fn parses_a_minimal_table() {
        let c = parse(&table(16, ""), "t.yaml").unwrap();
        assert_eq!(c.num_lasers(), 16);
        assert_eq!(c.distance_resolution, Some(0.002));
        assert!(!c.advanced);
        assert_eq!(c.lasers[3].vert_correction, -0.17);
        assert_eq!(c.lasers[3].max_intensity, 255);
        assert_eq!(c.source, "t.yaml");
    }

    #[test]
    fn markers_are_one_based() {
        // `vert_correction: abc` on line 4 (1-based); its value starts at column 55 (1-based).
        let mut s = table(16, "");
        s = s.replacen("vert_correction: -0.2}", "vert_correction: abc}", 1);
        let e = parse(&s, "t").unwrap_err().to_string();
        assert!(e.contains("line 4, column 55"), "{e}");
        // The second `:` of `b: c: d` is at line 2, column 5.
        let e = parse("a: 1\nb: c: d\n", "t").unwrap_err();
        assert!(
            matches!(
                e,
                CalibError::Syntax {
                    line: 2,
                    column: 5,
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn two_point_flag_is_folded_into_the_values() {
        let extra = ", dist_correction: 1.5, dist_correction_x: 1.6, dist_correction_y: 1.7";
        let off = parse(&table(16, extra), "t").unwrap();
        assert!(off.advanced);
        assert_eq!(off.lasers[0].dist_correction_x, 1.5);
        assert_eq!(off.lasers[0].dist_correction_y, 1.5);
        let on = parse(
            &table(16, &format!("{extra}, two_pt_correction_available: true")),
            "t",
        )
        .unwrap();
        assert_eq!(on.lasers[0].dist_correction_x, 1.6);
        assert_eq!(on.lasers[0].dist_correction_y, 1.7);
    }

    #[test]
    fn float_intensities_are_floored() {
        let c = parse(
            &table(16, ", min_intensity: 40.0, max_intensity: 230.9"),
            "t",
        )
        .unwrap();
        assert_eq!(
            (c.lasers[0].min_intensity, c.lasers[0].max_intensity),
            (40, 230)
        );
    }

    #[test]
    fn numbers_are_strict() {
        assert!(matches!(parse_decimal("1e300"), Some(v) if v == 1e300));
        for s in [
            "inf", "NaN", "infinity", "1.2.3", "", "-", ".", "1e", "0x10", " 1",
        ] {
            assert_eq!(parse_decimal(s), None, "{s}");
        }
    }
}
