//! VeloView calibration xml and HDL-64E `db.xml`: the same boost-serialization layout.
//!
//! ```xml
//! <boost_serialization ...><DB ...>
//!   <distLSB_>0.2</distLSB_>                        <!-- cm, optional -->
//!   <enabled_><count>64</count><item>1</item>…</enabled_>          <!-- optional -->
//!   <minIntensity_><count>64</count><item>0</item>…</minIntensity_>  <!-- optional -->
//!   <maxIntensity_><count>64</count><item>255</item>…</maxIntensity_><!-- optional -->
//!   <points_><count>64</count>
//!     <item><px><id_>0</id_><rotCorrection_>-7.15</rotCorrection_>       <!-- deg -->
//!       <vertCorrection_>-8.77</vertCorrection_>                          <!-- deg -->
//!       <distCorrection_>151.9</distCorrection_>                          <!-- cm -->
//!       <distCorrectionX_>155.0</distCorrectionX_><distCorrectionY_>152.3</distCorrectionY_>
//!       <vertOffsetCorrection_>19.5</vertOffsetCorrection_>               <!-- cm -->
//!       <horizOffsetCorrection_>2.6</horizOffsetCorrection_>              <!-- cm -->
//!       <focalDistance_>1200</focalDistance_>                             <!-- cm -->
//!       <focalSlope_>1.4</focalSlope_></px></item> …
//! ```
//!
//! Conversion follows ros-drivers `gen_calibration.py`, so that a db.xml and the yaml made from
//! it give the same table: degrees → radians, centimetres (`distLSB_`, distance and offset
//! corrections, `focalDistance_`) × 0.01 → metres, `focalSlope_` unchanged (VeloView's own
//! decoder divides it by 100 on load; ringscan keeps the db.xml / ROS value). Only lasers whose
//! `enabled_` item is non-zero are kept (VeloView files list 64 points and enable 16 or 32);
//! without `enabled_` every point is used. `minIntensity_` / `maxIntensity_` are indexed by
//! laser id; when absent (`test_db_without_intensities.xml`) the ROS defaults 0 / 255 apply.
//! Without `distLSB_` the distance resolution is left to the model default (0.2 cm for the
//! HDL-64E — the value `gen_calibration.py` means to default to). Two-point correction is taken
//! as available for a laser when both `distCorrectionX_` and `distCorrectionY_` are non-zero
//! (`gen_calibration.py`, fix for ros-drivers #473); otherwise both are set to
//! `distCorrection_` (see [`crate::sensor::calib`]). Ids may be written as `0.0` (VeloView's
//! `HDL-64.xml`) and must be whole numbers.
//!
//! Hostile input: the text is capped at [`MAX_CALIB_BYTES`](crate::sensor::calib::MAX_CALIB_BYTES) and
//! [`MAX_NODES`] nodes; an entity declaration is refused (real files carry only
//! `<!DOCTYPE boost_serialization>`; roxmltree stops expansion loops but not a large entity
//! referenced many times, and nodes_limit does not count merged text, so 4 MiB could ask for a
//! terabyte); the tree is walked along fixed paths without recursion, so nesting depth is
//! harmless.

use std::collections::BTreeMap;

use roxmltree::{Document, Node, ParsingOptions};

use crate::sensor::calib::check_size;
use crate::sensor::calib::parse_decimal;
use crate::sensor::calib::CalibError;
use crate::sensor::velodyne::calib::has_advanced_corrections;
use crate::sensor::velodyne::calib::LaserCalibration;
use crate::sensor::velodyne::calib::VelodyneCalibration;

const FORMAT: &str = "XML";

/// Most XML nodes accepted (real files have about 5 000).
pub const MAX_NODES: u32 = 200_000;

/// Parses a VeloView xml / db.xml text; `source_name` is kept as the table's source.
pub fn parse(text: &str, source_name: &str) -> Result<VelodyneCalibration, CalibError> {
    check_size(text.len())?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    if let Some(at) = text.find("<!ENTITY") {
        let before = &text[..at];
        return Err(CalibError::Syntax {
            format: FORMAT,
            line: before.matches('\n').count() + 1,
            column: before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1,
            message: "an entity declaration; a calibration file has none".into(),
        });
    }
    let options = ParsingOptions {
        allow_dtd: true,
        nodes_limit: MAX_NODES,
        ..Default::default()
    };
    let doc = Document::parse_with_options(text, options).map_err(|e| {
        let p = e.pos();
        CalibError::Syntax {
            format: FORMAT,
            line: p.row as usize,
            column: p.col as usize,
            message: e.to_string(),
        }
    })?;
    let x = Xml { doc: &doc };

    let root = doc.root_element();
    let db = if root.has_tag_name("DB") {
        root
    } else {
        child(root, "DB").ok_or_else(|| CalibError::MissingKey {
            key: "DB".into(),
            context: format!(
                " (root element is <{}> at {}; expected <boost_serialization><DB>)",
                root.tag_name().name(),
                x.at(root).trim_start_matches(" at ")
            ),
        })?
    };

    let distance_resolution = match child(db, "distLSB_") {
        Some(n) => Some(x.number(n, "DB/distLSB_", "")? * 0.01),
        None => None,
    };
    let enabled = match child(db, "enabled_") {
        Some(list) => Some(
            x.items(list, "DB/enabled_")?
                .into_iter()
                .map(|v| v != 0.0)
                .collect::<Vec<_>>(),
        ),
        None => None,
    };
    let min_intensity = match child(db, "minIntensity_") {
        Some(list) => Some(x.intensities(list, "DB/minIntensity_")?),
        None => None,
    };
    let max_intensity = match child(db, "maxIntensity_") {
        Some(list) => Some(x.intensities(list, "DB/maxIntensity_")?),
        None => None,
    };

    let points = child(db, "points_").ok_or_else(|| CalibError::MissingKey {
        key: "DB/points_".into(),
        context: format!(" (the per-laser table; <DB>{})", x.at(db)),
    })?;

    let mut lasers = Vec::new();
    let mut seen: BTreeMap<u16, Node> = BTreeMap::new();
    for (index, item) in points
        .children()
        .filter(|n| n.has_tag_name("item"))
        .enumerate()
    {
        let Some(px) = child(item, "px") else {
            return Err(CalibError::MissingKey {
                key: "px".into(),
                context: format!(" in DB/points_ item {index}{}", x.at(item)),
            });
        };
        let ctx = |id: Option<u16>| match id {
            Some(id) => format!(" in DB/points_ item {index} (laser id {id})"),
            None => format!(" in DB/points_ item {index}"),
        };
        let id_node = child(px, "id_").ok_or_else(|| CalibError::MissingKey {
            key: "id_".into(),
            context: format!("{}{}", ctx(None), x.at(px)),
        })?;
        let id_value = x.number(id_node, "id_", &ctx(None))?;
        if id_value.fract() != 0.0 || !(0.0..=f64::from(u16::MAX)).contains(&id_value) {
            return Err(CalibError::BadValue {
                key: "id_".into(),
                context: format!("{}{}", ctx(None), x.at(id_node)),
                expected: "a whole number in 0..=65535".into(),
                found: x.text(id_node).to_owned(),
            });
        }
        let id = id_value as u16;
        let slot = usize::from(id);

        if let Some(enabled) = &enabled {
            match enabled.get(slot) {
                Some(true) => {}
                Some(false) => continue,
                None => {
                    return Err(CalibError::BadValue {
                        key: "DB/enabled_".into(),
                        context: format!("{}{}", ctx(Some(id)), x.at(id_node)),
                        expected: format!("an entry for laser {id}"),
                        found: format!("{} entries", enabled.len()),
                    })
                }
            }
        }
        if let Some(first) = seen.insert(id, px) {
            return Err(CalibError::Invalid(format!(
                "duplicate laser id {id} in DB/points_ item {index}{} (already given{})",
                x.at(id_node),
                x.at(first)
            )));
        }

        let ctx = ctx(Some(id));
        let field = |name: &str, required: bool| -> Result<f64, CalibError> {
            match child(px, name) {
                Some(n) => x.number(n, name, &ctx),
                None if required => Err(CalibError::MissingKey {
                    key: name.into(),
                    context: format!("{ctx}{}", x.at(px)),
                }),
                None => Ok(0.0),
            }
        };
        let limit = |list: &Option<Vec<u8>>, name: &str, default: u8| -> Result<u8, CalibError> {
            match list {
                None => Ok(default),
                Some(v) => v.get(slot).copied().ok_or_else(|| CalibError::BadValue {
                    key: format!("DB/{name}"),
                    context: ctx.clone(),
                    expected: format!("an entry for laser {id}"),
                    found: format!("{} entries", v.len()),
                }),
            }
        };

        let cm = 0.01;
        let dist_correction = field("distCorrection_", false)? * cm;
        let mut dist_correction_x = field("distCorrectionX_", false)? * cm;
        let mut dist_correction_y = field("distCorrectionY_", false)? * cm;
        if dist_correction_x == 0.0 || dist_correction_y == 0.0 {
            dist_correction_x = dist_correction;
            dist_correction_y = dist_correction;
        }
        lasers.push(LaserCalibration {
            laser_id: id,
            rot_correction: field("rotCorrection_", true)?.to_radians(),
            vert_correction: field("vertCorrection_", true)?.to_radians(),
            dist_correction,
            dist_correction_x,
            dist_correction_y,
            vert_offset_correction: field("vertOffsetCorrection_", false)? * cm,
            horiz_offset_correction: field("horizOffsetCorrection_", false)? * cm,
            focal_distance: field("focalDistance_", false)? * cm,
            focal_slope: field("focalSlope_", false)?,
            min_intensity: limit(&min_intensity, "minIntensity_", 0)?,
            max_intensity: limit(&max_intensity, "maxIntensity_", 255)?,
        });
    }
    if lasers.is_empty() {
        return Err(CalibError::Invalid(format!(
            "DB/points_{} holds no enabled laser",
            x.at(points)
        )));
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

/// First child element with this tag name.
fn child<'a, 'input>(node: Node<'a, 'input>, name: &str) -> Option<Node<'a, 'input>> {
    node.children().find(|n| n.has_tag_name(name))
}

/// Helpers that need the document for positions.
struct Xml<'a, 'input> {
    doc: &'a Document<'input>,
}

impl Xml<'_, '_> {
    /// ` at line L, column C` of a node's start.
    fn at(&self, node: Node) -> String {
        let p = self.doc.text_pos_at(node.range().start);
        format!(" at line {}, column {}", p.row, p.col)
    }

    fn text<'n>(&self, node: Node<'n, '_>) -> &'n str {
        node.text().unwrap_or("").trim()
    }

    /// The element's text as a finite number.
    fn number(&self, node: Node, key: &str, context: &str) -> Result<f64, CalibError> {
        let t = self.text(node);
        match parse_decimal(t) {
            Some(v) if v.is_finite() => Ok(v),
            _ => Err(CalibError::BadValue {
                key: key.into(),
                context: format!("{context}{}", self.at(node)),
                expected: "a finite number".into(),
                found: if t.is_empty() {
                    "nothing".into()
                } else {
                    format!("{:?}", t.chars().take(40).collect::<String>())
                },
            }),
        }
    }

    /// The numbers of a boost list's `<item>` children.
    fn items(&self, list: Node, key: &str) -> Result<Vec<f64>, CalibError> {
        list.children()
            .filter(|n| n.has_tag_name("item"))
            .enumerate()
            .map(|(i, n)| self.number(n, key, &format!(" item {i}")))
            .collect()
    }

    /// A list of intensity limits (floored like the ROS yaml reader, then 0..=255).
    fn intensities(&self, list: Node, key: &str) -> Result<Vec<u8>, CalibError> {
        list.children()
            .filter(|n| n.has_tag_name("item"))
            .enumerate()
            .map(|(i, n)| {
                let v = self.number(n, key, &format!(" item {i}"))?.floor();
                if (0.0..=255.0).contains(&v) {
                    Ok(v as u8)
                } else {
                    Err(CalibError::BadValue {
                        key: key.into(),
                        context: format!(" item {i}{}", self.at(n)),
                        expected: "an intensity in 0..=255".into(),
                        found: self.text(n).to_owned(),
                    })
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn db(n: usize, enabled: usize, px_extra: &str) -> String {
        let mut s = String::from(
            "<?xml version=\"1.0\"?>\n<!DOCTYPE boost_serialization>\n\
             <boost_serialization signature=\"serialization::archive\" version=\"4\">\n\
             <DB class_id=\"0\">\n<distLSB_>0.2</distLSB_>\n<enabled_>\n",
        );
        s.push_str(&format!("<count>{n}</count>\n"));
        for i in 0..n {
            s.push_str(&format!("<item>{}</item>\n", u8::from(i < enabled)));
        }
        s.push_str("</enabled_>\n<points_>\n");
        for i in 0..n {
            s.push_str(&format!(
                "<item><px><id_>{i}</id_><rotCorrection_>1.5</rotCorrection_>\
                 <vertCorrection_>{}</vertCorrection_>{px_extra}</px></item>\n",
                -15.0 + i as f64
            ));
        }
        s.push_str("</points_>\n</DB>\n</boost_serialization>\n");
        s
    }

    #[test]
    fn an_entity_declaration_is_refused_before_expansion() {
        // 64 KiB of text referenced 60,000 times: 4 GB expanded, in a 400 kB file.
        let big = "A".repeat(1 << 16);
        let refs = "&a;".repeat(60_000);
        let text = format!(
            "<?xml version=\"1.0\"?>\n<!DOCTYPE boost_serialization [\n<!ENTITY a \"{big}\">]>\n\
             <boost_serialization><DB><distLSB_>{refs}</distLSB_></DB></boost_serialization>\n"
        );
        match parse(&text, "hostile.xml") {
            Err(CalibError::Syntax { line, column, .. }) => assert_eq!((line, column), (3, 1)),
            other => panic!("{other:?}"),
        }
        // A plain DOCTYPE, as real files have, still parses.
        assert!(parse(&db(16, 16, ""), "db.xml").is_ok());
    }

    #[test]
    fn converts_degrees_and_centimetres() {
        let extra =
            "<distCorrection_>150</distCorrection_><distCorrectionX_>155</distCorrectionX_>\
                     <distCorrectionY_>152</distCorrectionY_><focalDistance_>1200</focalDistance_>";
        let c = parse(&db(64, 16, extra), "t.xml").unwrap();
        assert_eq!(c.num_lasers(), 16);
        assert_eq!(c.distance_resolution, Some(0.2 * 0.01));
        assert!(c.advanced);
        let l = &c.lasers[2];
        assert_eq!(l.vert_correction, (-13.0f64).to_radians());
        assert_eq!(l.rot_correction, 1.5f64.to_radians());
        assert_eq!(l.dist_correction, 1.5);
        assert_eq!(l.dist_correction_x, 1.55);
        assert_eq!(l.focal_distance, 12.0);
        assert_eq!((l.min_intensity, l.max_intensity), (0, 255));
    }

    #[test]
    fn one_zero_near_correction_means_no_two_point() {
        let extra = "<distCorrection_>150</distCorrection_><distCorrectionX_>0</distCorrectionX_>\
                     <distCorrectionY_>152</distCorrectionY_>";
        let c = parse(&db(16, 16, extra), "t.xml").unwrap();
        assert_eq!(c.lasers[0].dist_correction_x, 1.5);
        assert_eq!(c.lasers[0].dist_correction_y, 1.5);
    }

    #[test]
    fn positions_are_reported() {
        let s = db(16, 16, "").replacen("<rotCorrection_>1.5<", "<rotCorrection_>x<", 1);
        let e = parse(&s, "t").unwrap_err().to_string();
        assert!(e.contains("rotCorrection_") && e.contains("line 26"), "{e}");
    }
}
