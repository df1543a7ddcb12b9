//! CSV: one file per table (header = the exported column names, one line per row, empty for
//! NULL, `ts_us` in microseconds since the epoch, UTC), `columns.csv` beside them with each
//! column's type, unit, label, description and value names, and `session.csv` with the
//! session's metadata; `calibration.csv` with the session's calibration record, if it has one.

use super::calibration::{self, CalibrationTable};
use super::columns::{TableData, Values};
use super::{ExportError, Written};
use std::fmt::Write as _;
use std::path::Path;

/// Writes the CSV files of `tables` (those with rows) and of the calibration `record` (if it
/// has rows) into `dir`.
pub fn write(
    dir: &Path,
    tables: &[TableData],
    record: &CalibrationTable,
    metadata: &[(String, String)],
) -> Result<Vec<Written>, ExportError> {
    std::fs::create_dir_all(dir).map_err(|e| ExportError::write(dir, e))?;
    let mut columns = writer(&dir.join("columns.csv"))?;
    columns.write_record([
        "table",
        "column",
        "type",
        "unit",
        "label",
        "description",
        "values",
    ])?;
    let mut written = super::per_table(dir, tables, "csv", |path, data| {
        table(path, data)?;
        for column in &data.columns {
            let d = column.description;
            columns.write_record([
                data.table.name,
                column.name,
                &column.ty.tdengine(),
                d.unit,
                d.label,
                d.description,
                &super::value_names(d.values),
            ])?;
        }
        Ok(())
    })?;
    if record.rows > 0 {
        let path = dir.join(format!("{}.csv", calibration::NAME));
        let mut out = writer(&path)?;
        out.write_record(calibration::COLUMNS.iter().map(|c| c.name))?;
        write_rows(&mut out, record.rows, &record.values)?;
        out.flush().map_err(|e| ExportError::write(&path, e))?;
        written.push(Written::file(&path, record.rows)?);
        for column in &calibration::COLUMNS {
            columns.write_record([
                calibration::NAME,
                column.name,
                &column.ty.tdengine(),
                "",
                "",
                column.description,
                "",
            ])?;
        }
    }
    columns.flush().map_err(|e| ExportError::write(dir, e))?;
    written.push(Written::file(&dir.join("columns.csv"), 0)?);
    let path = dir.join("session.csv");
    let mut session = writer(&path)?;
    session.write_record(["key", "value"])?;
    for (key, value) in metadata {
        session.write_record([key, value])?;
    }
    session.flush().map_err(|e| ExportError::write(&path, e))?;
    written.push(Written::file(&path, 0)?);
    Ok(written)
}

fn writer(path: &Path) -> Result<csv::Writer<std::fs::File>, ExportError> {
    let file = std::fs::File::create(path).map_err(|e| ExportError::write(path, e))?;
    Ok(csv::Writer::from_writer(file))
}

fn table(path: &Path, data: &TableData) -> Result<(), ExportError> {
    let mut out = writer(path)?;
    out.write_record(data.columns.iter().map(|c| c.name))?;
    write_rows(&mut out, data.rows, &data.values)?;
    out.flush().map_err(|e| ExportError::write(path, e))
}

/// `rows` lines, one field per column of `values`.
fn write_rows(
    out: &mut csv::Writer<std::fs::File>,
    rows: usize,
    values: &[Values],
) -> Result<(), ExportError> {
    let mut field = String::new();
    for row in 0..rows {
        for values in values {
            field.clear();
            cell(&mut field, values, row);
            out.write_field(&field)?;
        }
        out.write_record(None::<&[u8]>)?;
    }
    Ok(())
}

/// Row `row` of a column as text: integers exactly, floats as the shortest text that reads
/// back to the same value (`f32` as `f32`) and always as a float (`0.0`, not `0`: readers that
/// infer a column's type from its first rows, as polars and pandas do, must not take a float
/// column for integers), flags as `true`/`false`, NULL as nothing.
fn cell(out: &mut String, values: &Values, row: usize) {
    let _ = match values {
        Values::Bool(v) => match v.get(row).copied().flatten() {
            Some(b) => write!(out, "{b}"),
            None => Ok(()),
        },
        Values::Int(v) => match v.get(row).copied().flatten() {
            Some(i) => write!(out, "{i}"),
            None => Ok(()),
        },
        Values::UInt(v) => match v.get(row).copied().flatten() {
            Some(i) => write!(out, "{i}"),
            None => Ok(()),
        },
        Values::F32(v) => match v.get(row).copied().flatten() {
            Some(f) => float(out, f, f.is_finite()),
            None => Ok(()),
        },
        Values::F64(v) => match v.get(row).copied().flatten() {
            Some(f) => float(out, f, f.is_finite()),
            None => Ok(()),
        },
        Values::Text(v) => match v.get(row).and_then(|t| t.as_deref()) {
            Some(t) => write!(out, "{t}"),
            None => Ok(()),
        },
    };
}

/// `value` in its shortest round-trip form, with `.0` added to a finite whole number (Rust
/// writes `1.0_f32` as `1`, and never uses an exponent).
fn float(out: &mut String, value: impl std::fmt::Display, finite: bool) -> std::fmt::Result {
    let start = out.len();
    write!(out, "{value}")?;
    if finite && !out[start..].contains('.') {
        out.push_str(".0");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_are_always_written_as_floats_and_read_back_equal() {
        let values = Values::F32(vec![Some(0.0), Some(19.2), Some(-3.0), Some(1e20), None]);
        let mut text = Vec::new();
        for row in 0..5 {
            let mut field = String::new();
            cell(&mut field, &values, row);
            text.push(field);
        }
        assert_eq!(text, ["0.0", "19.2", "-3.0", "100000000000000000000.0", ""]);
        assert_eq!(text[1].parse::<f32>(), Ok(19.2));
        let wide = Values::F64(vec![Some(203.84000000000003), Some(f64::NAN)]);
        let mut field = String::new();
        cell(&mut field, &wide, 0);
        assert_eq!(field.parse::<f64>(), Ok(203.84000000000003));
        field.clear();
        cell(&mut field, &wide, 1);
        assert_eq!(field, "NaN");
    }
}
