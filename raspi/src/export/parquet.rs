//! Parquet: one file per table, one column per exported column ([`super::columns`]), with the
//! Parquet logical type that reads back (in Arrow, pandas, polars) as exactly the column's
//! type: `u8` as UInt8, `f32` as Float32, `ts_us` as a UTC timestamp in microseconds, tags
//! as strings. The file's key-value metadata carries the session's metadata and, per column,
//! what the CSV's `columns.csv` says: label, unit, description and value names, so a reader
//! with the Parquet file alone can decode every enum. Written column by column with the
//! parquet crate's own writer (no Arrow: less to build).

use super::calibration::{self, CalibrationTable};
use super::columns::{TableData, Values};
use super::{ExportError, Written};
use aer::tables::ColumnType;
use parquet::data_type::{
    BoolType, ByteArray, ByteArrayType, DoubleType, FloatType, Int32Type, Int64Type,
};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::parser::parse_message_type;
use std::path::Path;
use std::sync::Arc;

/// Writes one Parquet file per table with rows into `dir`.
pub fn write(
    dir: &Path,
    tables: &[TableData],
    metadata: &[(String, String)],
) -> Result<Vec<Written>, ExportError> {
    super::per_table(dir, tables, "parquet", |path, data| {
        table(path, data, metadata)
    })
}

/// The Parquet type of a column: physical type and logical annotation.
fn parquet_type(ty: ColumnType) -> &'static str {
    match ty {
        ColumnType::Timestamp => "INT64 {} (TIMESTAMP(MICROS,true))",
        ColumnType::Bool => "BOOLEAN {}",
        ColumnType::I8 => "INT32 {} (INTEGER(8,true))",
        ColumnType::I16 => "INT32 {} (INTEGER(16,true))",
        ColumnType::I32 => "INT32 {} (INTEGER(32,true))",
        ColumnType::I64 => "INT64 {} (INTEGER(64,true))",
        ColumnType::U8 => "INT32 {} (INTEGER(8,false))",
        ColumnType::U16 => "INT32 {} (INTEGER(16,false))",
        ColumnType::U32 => "INT32 {} (INTEGER(32,false))",
        ColumnType::U64 => "INT64 {} (INTEGER(64,false))",
        ColumnType::F32 => "FLOAT {}",
        ColumnType::F64 => "DOUBLE {}",
        ColumnType::VarChar(_) => "BINARY {} (STRING)",
    }
}

fn message_type(data: &TableData) -> String {
    let tags = data.table.tags.len();
    let fields: Vec<String> = data
        .columns
        .iter()
        .enumerate()
        .map(|(i, c)| {
            // Tags and `ts` are always there; values may be NULL.
            let repetition = if i <= tags { "REQUIRED" } else { "OPTIONAL" };
            format!(
                "  {repetition} {};",
                parquet_type(c.ty).replace("{}", c.name)
            )
        })
        .collect();
    format!("message {} {{\n{}\n}}", data.table.name, fields.join("\n"))
}

fn key_values(data: &TableData, metadata: &[(String, String)]) -> Vec<KeyValue> {
    let mut out: Vec<KeyValue> = metadata
        .iter()
        .map(|(k, v)| KeyValue::new(format!("aer.{k}"), v.clone()))
        .collect();
    for column in &data.columns {
        let d = column.description;
        let mut add = |what: &str, text: String| {
            if !text.is_empty() {
                out.push(KeyValue::new(format!("aer.{what}.{}", column.name), text));
            }
        };
        add("label", d.label.to_owned());
        add("unit", d.unit.to_owned());
        add("description", d.description.to_owned());
        add("values", super::value_names(d.values));
    }
    out
}

fn table(path: &Path, data: &TableData, metadata: &[(String, String)]) -> Result<(), ExportError> {
    let columns = data.columns().map(|(c, values)| (c.ty, values));
    write_file(
        path,
        &message_type(data),
        key_values(data, metadata),
        columns,
    )
}

/// Writes the session's calibration record as `dir/calibration.parquet`, the columns'
/// descriptions in its metadata.
pub fn write_calibration(
    dir: &Path,
    record: &CalibrationTable,
    metadata: &[(String, String)],
) -> Result<Written, ExportError> {
    std::fs::create_dir_all(dir).map_err(|e| ExportError::write(dir, e))?;
    let fields: Vec<String> = calibration::COLUMNS
        .iter()
        .map(|c| {
            let repetition = if c.required { "REQUIRED" } else { "OPTIONAL" };
            format!(
                "  {repetition} {};",
                parquet_type(c.ty).replace("{}", c.name)
            )
        })
        .collect();
    let message = format!(
        "message {} {{\n{}\n}}",
        calibration::NAME,
        fields.join("\n")
    );
    let mut key_values: Vec<KeyValue> = metadata
        .iter()
        .map(|(k, v)| KeyValue::new(format!("aer.{k}"), v.clone()))
        .collect();
    key_values.extend(calibration::COLUMNS.iter().map(|c| {
        KeyValue::new(
            format!("aer.description.{}", c.name),
            c.description.to_owned(),
        )
    }));
    let path = dir.join(format!("{}.parquet", calibration::NAME));
    let columns = record.columns().map(|(c, values)| (c.ty, values));
    write_file(&path, &message, key_values, columns)?;
    Written::file(&path, record.rows)
}

/// Writes one row group of `columns` (each column's type and values, in `message`'s order).
fn write_file<'v>(
    path: &Path,
    message: &str,
    key_values: Vec<KeyValue>,
    mut columns: impl Iterator<Item = (ColumnType, &'v Values)>,
) -> Result<(), ExportError> {
    let schema = Arc::new(parse_message_type(message)?);
    let properties = WriterProperties::builder()
        .set_created_by(format!("aer-raspi {}", env!("CARGO_PKG_VERSION")))
        .set_key_value_metadata(Some(key_values))
        .build();
    let file = std::fs::File::create(path).map_err(|e| ExportError::write(path, e))?;
    let mut writer = SerializedFileWriter::new(file, schema, Arc::new(properties))?;
    let mut group = writer.next_row_group()?;
    while let Some(mut column) = group.next_column()? {
        let Some((ty, values)) = columns.next() else {
            return Err(ExportError::Internal("more Parquet columns than values"));
        };
        let wide = matches!(ty, ColumnType::Timestamp | ColumnType::I64);
        match values {
            Values::Bool(v) => {
                let (present, levels) = split(v, |b| b);
                column
                    .typed::<BoolType>()
                    .write_batch(&present, Some(&levels), None)?;
            }
            Values::Int(v) if wide => {
                let (present, levels) = split(v, |i| i);
                column
                    .typed::<Int64Type>()
                    .write_batch(&present, Some(&levels), None)?;
            }
            Values::Int(v) => {
                // Unsigned 32-bit values keep their bits in Parquet's INT32.
                let (present, levels) = split(v, |i| i as i32);
                column
                    .typed::<Int32Type>()
                    .write_batch(&present, Some(&levels), None)?;
            }
            Values::UInt(v) => {
                let (present, levels) = split(v, |u| u as i64);
                column
                    .typed::<Int64Type>()
                    .write_batch(&present, Some(&levels), None)?;
            }
            Values::F32(v) => {
                let (present, levels) = split(v, |f| f);
                column
                    .typed::<FloatType>()
                    .write_batch(&present, Some(&levels), None)?;
            }
            Values::F64(v) => {
                let (present, levels) = split(v, |f| f);
                column
                    .typed::<DoubleType>()
                    .write_batch(&present, Some(&levels), None)?;
            }
            Values::Text(v) => {
                let present: Vec<ByteArray> = v
                    .iter()
                    .flatten()
                    .map(|s| ByteArray::from(s.as_str()))
                    .collect();
                let levels: Vec<i16> = v.iter().map(|s| i16::from(s.is_some())).collect();
                column
                    .typed::<ByteArrayType>()
                    .write_batch(&present, Some(&levels), None)?;
            }
        }
        column.close()?;
    }
    group.close()?;
    writer.close()?;
    Ok(())
}

/// The present values (converted) and the definition levels (1 present, 0 NULL).
fn split<T: Copy, U>(values: &[Option<T>], convert: impl Fn(T) -> U) -> (Vec<U>, Vec<i16>) {
    let present = values.iter().flatten().map(|&v| convert(v)).collect();
    let levels = values.iter().map(|v| i16::from(v.is_some())).collect();
    (present, levels)
}

#[cfg(test)]
mod tests {
    use super::parquet_type;
    use aer::tables::{ColumnType, TABLES};

    #[test]
    fn every_generated_column_type_has_a_parquet_type_that_parses() {
        for table in TABLES {
            for column in table.local_columns() {
                let text = format!(
                    "message t {{ OPTIONAL {}; }}",
                    parquet_type(column.ty).replace("{}", "c")
                );
                assert!(
                    parquet::schema::parser::parse_message_type(&text).is_ok(),
                    "{text}"
                );
            }
        }
        assert!(parquet_type(ColumnType::U8).contains("INTEGER(8,false)"));
    }
}
