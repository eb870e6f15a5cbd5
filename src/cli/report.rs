//! The text summary of `decode`, `info` and `listen`: the `--json` object, read back for
//! people.

use serde_json::Value;

pub(crate) fn print_text(j: &Value) {
    let g = |v: &Value| v.as_u64().unwrap_or(0);
    let c = &j["capture"];
    outln!("{}", j["input"].as_str().unwrap_or(""));
    outln!(
        "  capture: {} records, {} UDP datagrams ({} reassembled from fragments), {:.3} s{}",
        g(&c["records"]),
        g(&c["datagrams"]),
        g(&c["reassembled"]),
        c["duration_s"].as_f64().unwrap_or(0.0),
        match c["truncated_tail_offset"].as_u64() {
            Some(o) => format!(", last record truncated at byte {o}"),
            None => String::new(),
        }
    );
    if let Some(b) = c["bag"].as_object() {
        outln!(
            "  bag ({}): {} messages, {} with packets; unknown types {}, malformed {}, other topics {}, outside the time window {}",
            b["kind"].as_str().unwrap_or(""),
            g(&b["messages"]),
            g(&b["packet_messages"]),
            g(&b["unknown_type"]),
            g(&b["malformed"]),
            g(&b["unselected"]),
            g(&b["outside_time"])
        );
        for s in b["sensors"].as_array().into_iter().flatten() {
            outln!(
                "    {} ({}) as {}, ports {}/{}: {}{}",
                s["namespace"].as_str().unwrap_or(""),
                s["family"].as_str().unwrap_or(""),
                s["address"].as_str().unwrap_or(""),
                s["data_port"],
                s["aux_port"],
                s["topics"],
                if s["metadata_in_bag"] == true {
                    ", metadata in the bag"
                } else {
                    ""
                }
            );
        }
    }
    for s in j["sensors"].as_array().into_iter().flatten() {
        let kind = s["kind"].as_str().unwrap_or("");
        let Some(family) = crate::sensor::family(kind) else {
            outln!("  sensor of an unknown kind {kind:?}: {s}");
            continue;
        };
        if s["ports"].as_array().is_some_and(|p| p.is_empty()) {
            // Recognised, but every datagram of its went to another port than --port.
            outln!(
                "  {}: {kind}, no datagram decoded (none to --port)",
                crate::sensor::heading(s)
            );
            continue;
        }
        for line in family.describe(s) {
            outln!("{line}");
        }
    }
    if let Some(why) = j["no_sensor"].as_str() {
        outln!("  no sensor found: {why}");
    }
    let p = &j["packets"];
    print_warnings(j);
    outln!(
        "  total: {} sweeps, {} points; packets decoded {}, dropped {}, malformed {}, missing {}, ignored {}",
        g(&j["sweeps"]),
        g(&j["points"]),
        g(&p["decoded"]),
        g(&p["dropped"]),
        g(&p["malformed"]),
        g(&p["missing"]),
        g(&p["ignored"])
    );
    if let Some(n) = p["other_port"].as_u64().filter(|&n| n > 0) {
        outln!("  {n} data packets went to other ports than --port: dropped, not decoded");
    }
    if let Some(o) = j["output"].as_object() {
        outln!(
            "  wrote {} ({}): {}",
            o["path"].as_str().unwrap_or(""),
            o["format"].as_str().unwrap_or(""),
            o["topics"]
        );
        let held_over: u64 = j["sensors"].as_array().map_or(0, |a| {
            a.iter().filter_map(|s| s["raw_dropped"].as_u64()).sum()
        });
        let not_written = o["raw_dropped"].as_u64().unwrap_or(0) + held_over;
        if let Some(n) = Some(not_written).filter(|&n| n > 0) {
            outln!(
                "  {n} raw packets not written (output.raw_dropped: no ROS 2 packet message \
                 of their family holds them, --format foxglove keeps them on /raw; \
                 sensors[].raw_dropped: more than 16 MiB arrived before the sensor was known)"
            );
        }
    }
    outln!("  {:.3} s", j["elapsed_s"].as_f64().unwrap_or(0.0));
}

/// The text summary's warnings (`decode`, `info`, `listen`): calibrations and options no
/// sensor used, sweeps left unskewed.
pub(crate) fn print_warnings(j: &Value) {
    for name in j["unused_calibrations"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
    {
        outln!(
            "  warning: calibration {name} was used by no sensor: it fits none of the sensors \
             found (family, model, laser count, serial or address)"
        );
    }
    for w in (j["warnings"].as_array().into_iter().flatten()).filter_map(Value::as_str) {
        outln!("  warning: {w}");
    }
    for w in j["unused_options"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
    {
        outln!("  warning: {w}");
    }
    let names: Vec<&str> = (j["sensors"].as_array().into_iter().flatten())
        .filter_map(|s| s["name"].as_str())
        .collect();
    for n in (j["pipeline"]["extrinsics_unused"]
        .as_array()
        .into_iter()
        .flatten())
    .filter_map(Value::as_str)
    {
        outln!(
            "  warning: --extrinsics {n}=…: no sensor of that name (sensor names: {}); not applied",
            names.join(", ")
        );
    }
    // What a family found wrong with a sensor's data or its calibration.
    for s in j["sensors"].as_array().into_iter().flatten() {
        for w in (s["warnings"].as_array().into_iter().flatten()).filter_map(Value::as_str) {
            outln!("  warning: {}: {w}", crate::sensor::heading(s));
        }
    }
    // A --model the packets contradict (a family that can tell says so in its summary).
    for s in j["sensors"].as_array().into_iter().flatten() {
        if let Some(seen) = s["model_contradicted"].as_str() {
            outln!(
                "  warning: sensor {}: --model {}, though the packets say {seen}; its points are \
                 likely wrong",
                s["address"].as_str().unwrap_or(""),
                s["model_id"].as_str().unwrap_or("")
            );
        }
    }
    if let Some(n) = j["pipeline"]["deskew_skipped"].as_u64().filter(|&n| n > 0) {
        let why = j["pipeline"]["sensors"]
            .as_array()
            .into_iter()
            .flatten()
            .find_map(|s| s["deskew_last_error"].as_str())
            .unwrap_or("");
        outln!("  warning: deskew skipped on {n} sweeps (kept as measured): {why}");
    }
    if let Some(n) = j["pipeline"]["counts"]["voxel_skipped"]
        .as_u64()
        .filter(|&n| n > 0)
    {
        let leaf = j["pipeline"]["parameters"]["voxel.leaf_m"]
            .as_f64()
            .unwrap_or(0.0);
        outln!(
            "  warning: the voxel grid left out {n} points beyond ±2^20 leaves of {leaf} m ({:.1} m) from the origin; raise voxel.leaf_m",
            leaf * f64::from(1u32 << 20)
        );
    }
}
