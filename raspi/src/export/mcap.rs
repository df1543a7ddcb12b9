//! MCAP for Foxglove and PlotJuggler: one channel per table (the telemetry packet, each CAN
//! message) on the topic the live service publishes it on, JSON messages in receive-time
//! order, each channel with a JSON Schema generated from the schema (labels, units, enum
//! values), the session's metadata as an MCAP metadata record, and each entry of its
//! calibration record as a `calibration` metadata record.

use super::columns::ExportColumn;
use super::columns::{TableData, Values};
use super::{ExportError, Written};
use crate::column_descriptions::{self, Property};
use crate::store::calibration::{Entry, number};
use std::collections::BTreeMap;
use std::io::{BufWriter, Write as _};
use std::path::Path;

/// The live topic of a table below `root` (`aer/<car>`): `telemetry` or `can/<message>`.
pub fn topic(root: &str, table: &str) -> String {
    match table.strip_prefix("can_") {
        Some(message) => format!("{root}/can/{message}"),
        None => format!("{root}/{table}"),
    }
}

/// Writes `tables` (those with rows) into the MCAP file `path`.
pub fn write(
    path: &Path,
    tables: &[TableData],
    calibration: &[Entry],
    metadata: &[(String, String)],
    topic_root: &str,
) -> Result<Written, ExportError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| ExportError::write(dir, e))?;
    }
    let file = std::fs::File::create(path).map_err(|e| ExportError::write(path, e))?;
    let mut out = mcap::Writer::new(BufWriter::new(file))?;
    let mut channels = Vec::with_capacity(tables.len());
    for data in tables {
        if data.rows == 0 {
            channels.push(0);
            continue;
        }
        let tags = data.table.tags.len();
        let properties = data.columns.iter().enumerate().map(|(i, column)| Property {
            name: column.name,
            ty: column.ty,
            description: column.description,
            required: i <= tags,
        });
        let schema = column_descriptions::schema_of(data.table.name, properties);
        let schema_id =
            out.add_schema(data.table.name, "jsonschema", schema.to_string().as_bytes())?;
        let channel_metadata = BTreeMap::from([("table".to_owned(), data.table.name.to_owned())]);
        channels.push(out.add_channel(
            schema_id,
            &topic(topic_root, data.table.name),
            "json",
            &channel_metadata,
        )?);
    }
    // Every row of every table, in receive-time order (ties in table, then arrival, order).
    let mut order: Vec<(i64, usize, usize)> = tables
        .iter()
        .enumerate()
        .flat_map(|(t, data)| {
            data.timestamps()
                .iter()
                .enumerate()
                .map(move |(row, ts)| (ts.unwrap_or(0), t, row))
        })
        .collect();
    order.sort_unstable();
    let mut sequences = vec![0u32; tables.len()];
    let mut json = Vec::with_capacity(4096);
    for &(ts, t, row) in &order {
        let (Some(data), Some(&channel_id), Some(sequence)) =
            (tables.get(t), channels.get(t), sequences.get_mut(t))
        else {
            continue;
        };
        json.clear();
        message(&mut json, data, row);
        *sequence = sequence.wrapping_add(1);
        let nanos = u64::try_from(ts).unwrap_or(0).saturating_mul(1000);
        out.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id,
                sequence: *sequence,
                log_time: nanos,
                publish_time: nanos,
            },
            &json,
        )?;
    }
    out.write_metadata(&mcap::records::Metadata {
        name: "session".into(),
        metadata: metadata.iter().cloned().collect(),
    })?;
    for entry in calibration {
        out.write_metadata(&mcap::records::Metadata {
            name: super::calibration::NAME.into(),
            metadata: calibration_record(entry),
        })?;
    }
    out.finish()?;
    drop(out);
    Written::file(path, order.len())
}

/// An entry of the calibration record as MCAP metadata (the CSV's columns, as text).
fn calibration_record(e: &Entry) -> BTreeMap<String, String> {
    let optional = |v: Option<f64>| v.map(number).unwrap_or_default();
    BTreeMap::from([
        ("ts_us".to_owned(), e.at_us.to_string()),
        ("utc".to_owned(), crate::store::utc(e.at_us)),
        ("master".to_owned(), e.master.clone()),
        ("kind".to_owned(), e.kind.name().to_owned()),
        ("parameter".to_owned(), e.parameter.clone()),
        (
            "element".to_owned(),
            e.element.map(|i| i.to_string()).unwrap_or_default(),
        ),
        ("old".to_owned(), optional(e.old)),
        ("new".to_owned(), optional(e.new)),
        ("accepted".to_owned(), e.accepted.to_string()),
        ("reason".to_owned(), e.reason.clone()),
        (
            "checksum".to_owned(),
            e.checksum.map(|c| format!("0x{c:08x}")).unwrap_or_default(),
        ),
    ])
}

/// One row as a JSON object: every exported column (`ts_us` in microseconds, as in the other
/// formats), with `<name>_label` after each enum value that has a name.
fn message(out: &mut Vec<u8>, data: &TableData, row: usize) {
    out.push(b'{');
    let mut first = true;
    for (column, values) in data.columns() {
        if !first {
            out.push(b',');
        }
        first = false;
        let ExportColumn {
            name,
            description: d,
            ..
        } = column;
        let _ = write!(out, "\"{name}\":");
        let raw = value(out, values, row);
        if !d.values.is_empty() {
            let _ = write!(out, ",\"{name}_label\":");
            let label = raw.and_then(|raw| {
                d.values
                    .iter()
                    .find(|(value, _)| *value == i128::from(raw))
                    .map(|(_, label)| *label)
            });
            match label {
                Some(label) => {
                    let _ = serde_json::to_writer(&mut *out, label);
                }
                None => out.extend_from_slice(b"null"),
            }
        }
    }
    out.push(b'}');
}

/// Writes row `row` of a column as JSON (NULL, and a float that is not finite, as `null`);
/// returns the integer, for enum labels.
fn value(out: &mut Vec<u8>, values: &Values, row: usize) -> Option<i64> {
    let mut integer = None;
    let written = match values {
        Values::Bool(v) => v.get(row).copied().flatten().map(|b| {
            let _ = write!(out, "{b}");
        }),
        Values::Int(v) => v.get(row).copied().flatten().map(|i| {
            integer = Some(i);
            let _ = write!(out, "{i}");
        }),
        Values::UInt(v) => v.get(row).copied().flatten().map(|u| {
            let _ = write!(out, "{u}");
        }),
        Values::F32(v) => v
            .get(row)
            .copied()
            .flatten()
            .filter(|f| f.is_finite())
            .map(|f| {
                let _ = write!(out, "{f}");
            }),
        Values::F64(v) => v
            .get(row)
            .copied()
            .flatten()
            .filter(|f| f.is_finite())
            .map(|f| {
                let _ = write!(out, "{f}");
            }),
        Values::Text(v) => v.get(row).and_then(|t| t.as_deref()).map(|t| {
            let _ = serde_json::to_writer(&mut *out, t);
        }),
    };
    if written.is_none() {
        out.extend_from_slice(b"null");
    }
    integer
}
