//! What Foxglove and Lichtblick need of an MCAP to show it, checked without
//! a browser. Each check mirrors a fault those viewers met in our outputs:
//!
//! - **Time range from the chunk indexes.** The viewers take the smallest
//!   message start time of all chunk indexes as the start of the log; a chunk
//!   holding only schema and channel records has start = end = 0 and opens
//!   the log on 1970-01-01 with every panel empty.
//! - **ROS 2 message definitions.** A dependency's `MSG:` name must be the
//!   type exactly as the fields spell it (`std_msgs/Header`, as `ros2 bag`
//!   writes it); `MSG: std_msgs/msg/Header` hides the topic ("Expected 1 top
//!   level type definition for 'std_msgs/Header' but found 0").
//! - **JSON schemas.** The viewers' `parseJsonSchema` reads one `type` string
//!   per property: objects, scalars, arrays of scalars or of objects; a
//!   `$ref`, a type list, a bare `enum`, an array of arrays hides the topic.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// All three checks on one file; panics naming the file and what is wrong.
pub fn assert_opens_in_viewers(path: &Path) {
    let bytes = std::fs::read(path).unwrap();
    let mut problems = chunk_time_problems(&bytes);
    let summary = mcap::Summary::read(&bytes)
        .expect("a readable summary")
        .expect("a summary section");
    for schema in summary.schemas.values() {
        let text = String::from_utf8_lossy(&schema.data);
        let result = match schema.encoding.as_str() {
            "ros2msg" => ros2_definition_problem(&schema.name, &text),
            "jsonschema" => json_schema_problem(&text),
            _ => Ok(()),
        };
        if let Err(why) = result {
            problems.push(format!(
                "schema {} ({}): {why}",
                schema.name, schema.encoding
            ));
        }
    }
    assert!(
        problems.is_empty(),
        "{} would not open right in Foxglove / Lichtblick:\n  {}",
        path.display(),
        problems.join("\n  ")
    );
}

/// Every chunk index lies within the messages' time span, no chunk holds no
/// message, and the statistics' start and end are the messages' min and max.
pub fn chunk_time_problems(bytes: &[u8]) -> Vec<String> {
    let mut problems = Vec::new();
    let mut bounds: Option<(u64, u64)> = None;
    for message in mcap::MessageStream::new(bytes).unwrap() {
        let t = message.unwrap().log_time;
        bounds = Some(bounds.map_or((t, t), |(lo, hi)| (lo.min(t), hi.max(t))));
    }
    let Some((first, last)) = bounds else {
        return problems;
    };
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    for chunk in &summary.chunk_indexes {
        if chunk.message_index_offsets.is_empty() {
            problems.push(format!(
                "the chunk at byte {} holds no message (its index says {}..{})",
                chunk.chunk_start_offset, chunk.message_start_time, chunk.message_end_time
            ));
        }
        if chunk.message_start_time < first || chunk.message_end_time > last {
            problems.push(format!(
                "the chunk at byte {} claims messages {}..{} ns, outside the messages' {first}..{last}",
                chunk.chunk_start_offset, chunk.message_start_time, chunk.message_end_time
            ));
        }
    }
    match &summary.stats {
        Some(stats) if (stats.message_start_time, stats.message_end_time) != (first, last) => {
            problems.push(format!(
                "statistics say {}..{} ns, the messages span {first}..{last}",
                stats.message_start_time, stats.message_end_time
            ))
        }
        Some(_) => {}
        None => problems.push("no statistics record".into()),
    }
    problems
}

const ROS_PRIMITIVES: &[&str] = &[
    "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
    "uint64", "float32", "float64", "string", "wstring", "time", "duration",
];

/// A ROS 2 definition as the viewers read it: the main type, then
/// `MSG: package/Type` sections. Each complex field type (resolved against
/// its section's package) has exactly one section of that name, and each
/// section is a type some field uses.
pub fn ros2_definition_problem(schema_name: &str, text: &str) -> Result<(), String> {
    let separator = "=".repeat(80);
    let mut sections: Vec<(String, Vec<&str>)> = vec![(schema_name.to_owned(), Vec::new())];
    for line in text.lines() {
        let line = line.trim();
        if line == separator {
            continue;
        }
        if let Some(name) = line.strip_prefix("MSG: ") {
            sections.push((name.trim().to_owned(), Vec::new()));
        } else if !line.is_empty() && !line.starts_with('#') {
            sections.last_mut().unwrap().1.push(line);
        }
    }
    let mut defined: BTreeMap<&str, usize> = BTreeMap::new();
    for (name, _) in &sections[1..] {
        *defined.entry(name.as_str()).or_default() += 1;
    }
    let mut referenced = BTreeSet::new();
    for (name, fields) in &sections {
        let package = name.split('/').next().unwrap_or_default();
        for field in fields {
            let Some(field_type) = complex_field_type(field) else {
                continue;
            };
            let full = if field_type.contains('/') {
                field_type.to_owned()
            } else {
                format!("{package}/{field_type}")
            };
            if defined.get(full.as_str()) != Some(&1) {
                return Err(format!(
                    "field `{field}` of {name} needs exactly one `MSG: {full}` section, found {}",
                    defined.get(full.as_str()).copied().unwrap_or(0)
                ));
            }
            referenced.insert(full);
        }
    }
    for name in defined.keys() {
        if !referenced.contains(*name) {
            return Err(format!("`MSG: {name}` is no type any field uses"));
        }
    }
    Ok(())
}

/// The type of a field line when it is not a primitive (constants, whose
/// name is followed by `=`, skipped; `string<=N` is a bounded string).
fn complex_field_type(line: &str) -> Option<&str> {
    let (type_word, rest) = line.split_once(char::is_whitespace)?;
    if rest.contains('=') {
        return None;
    }
    let base = type_word.split('[').next()?.split("<=").next()?;
    (!ROS_PRIMITIVES.contains(&base)).then_some(base)
}

/// A JSON schema in the subset Foxglove's and Lichtblick's
/// `parseJsonSchema` reads.
pub fn json_schema_problem(text: &str) -> Result<(), String> {
    let schema: serde_json::Value =
        serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
    object_problem(&schema, "(root)")
}

fn object_problem(schema: &serde_json::Value, path: &str) -> Result<(), String> {
    if schema.get("type").and_then(|t| t.as_str()) != Some("object") {
        return Err(format!("{path}: an object needs \"type\": \"object\""));
    }
    let Some(properties) = schema.get("properties") else {
        return Ok(());
    };
    let properties = properties
        .as_object()
        .ok_or_else(|| format!("{path}: properties is not an object"))?;
    for (name, property) in properties {
        property_problem(property, &format!("{path}.{name}"))?;
    }
    Ok(())
}

fn property_problem(property: &serde_json::Value, path: &str) -> Result<(), String> {
    for keyword in ["$ref", "oneOf", "anyOf", "allOf"] {
        if property.get(keyword).is_some() {
            return Err(format!("{path}: `{keyword}` is not read"));
        }
    }
    let kind = match property.get("type") {
        Some(serde_json::Value::String(kind)) => kind.as_str(),
        Some(other) => return Err(format!("{path}: \"type\" must be one string, not {other}")),
        None => return Err(format!("{path}: no \"type\"")),
    };
    match kind {
        "boolean" | "number" | "integer" => Ok(()),
        "string" => match property.get("contentEncoding").and_then(|e| e.as_str()) {
            None | Some("base64") => Ok(()),
            Some(other) => Err(format!("{path}: contentEncoding {other} is not read")),
        },
        "object" => object_problem(property, path),
        "array" => {
            let items = property
                .get("items")
                .ok_or_else(|| format!("{path}: an array without items"))?;
            let item_path = format!("{path}[]");
            match items.get("type").and_then(|t| t.as_str()) {
                Some("boolean" | "number" | "integer") => Ok(()),
                Some("string") if items.get("contentEncoding").is_none() => Ok(()),
                Some("object") => object_problem(items, &item_path),
                _ => Err(format!(
                    "{item_path}: items must be a scalar or an object, not {}",
                    items.get("type").unwrap_or(&serde_json::Value::Null)
                )),
            }
        }
        other => Err(format!("{path}: type {other} is not read")),
    }
}
