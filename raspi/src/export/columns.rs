//! The columns as every export names and types them, the same in MCAP, Parquet and CSV:
//!
//! - one time base, `ts_us`: when the Pi received the frame (for telemetry, the packet's last
//!   ISO-TP frame), microseconds since the Unix epoch, UTC; Parquet marks it a UTC timestamp;
//! - two fingerprints under two names, in the firmware's own hex form (`0xa7b512d5`, as the
//!   boards print it and the metadata says it): `telemetry_fingerprint` (the packet layout the
//!   Pi decoded the telemetry with) and `dbc_fingerprint` (the CAN database it decoded the
//!   frames with);
//! - the CCM's clock, `timestamp_us`, unwrapped: the wire carries 32 bits, which wrap every
//!   71.6 minutes; an export counts the wraps within the session, so the column rises with
//!   the CCM's time however long the session (a CCM restart still shows, as a drop).
//!
//! The store keeps the wire's values; only the exports change them, here, once.

use crate::column_descriptions::{self, Description};
use aer::tables::{ColumnType, TELEMETRY, Table};

/// One column's values, typed as the generated column type says; `None` is SQL NULL (a
/// multiplexed signal that was absent, a value the wire could not carry).
#[derive(Debug, Clone, PartialEq)]
pub enum Values {
    Bool(Vec<Option<bool>>),
    /// Timestamps and every integer type up to `u32` and `i64`.
    Int(Vec<Option<i64>>),
    UInt(Vec<Option<u64>>),
    F32(Vec<Option<f32>>),
    F64(Vec<Option<f64>>),
    Text(Vec<Option<String>>),
}

/// A table's selected rows, as the exports name and type them.
#[derive(Debug, Clone, PartialEq)]
pub struct TableData {
    pub table: &'static Table,
    pub rows: usize,
    /// The exported columns: tags, then columns, as [`Table::local_columns`] lists them.
    pub columns: Vec<ExportColumn>,
    /// Each column's values.
    pub values: Vec<Values>,
}

impl TableData {
    /// Each column with its values.
    pub fn columns(&self) -> impl Iterator<Item = (&ExportColumn, &Values)> {
        self.columns.iter().zip(&self.values)
    }

    /// The `ts_us` column (microseconds since the epoch).
    pub(crate) fn timestamps(&self) -> &[Option<i64>] {
        let ts = self.table.tags.len();
        match self.values.get(ts) {
            Some(Values::Int(v)) => v,
            _ => &[],
        }
    }
}

/// One exported column.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExportColumn {
    /// Its name in every format.
    pub name: &'static str,
    /// Its type in every format.
    pub ty: ColumnType,
    /// What it means.
    pub description: Description,
    /// The store's column it comes from.
    pub stored: &'static str,
}

/// The exported columns of `table`, in the store's order (tags, then columns).
pub fn of(table: &'static Table) -> Vec<ExportColumn> {
    let telemetry = std::ptr::eq(table, &TELEMETRY);
    column_descriptions::columns(table)
        .into_iter()
        .map(|(column, description)| {
            let (name, ty, description) = match column.name {
                "ts" => (
                    "ts_us",
                    ColumnType::Timestamp,
                    Description {
                        label: "Receive time (UTC)",
                        unit: "us",
                        description: "When the Pi received the frame (for telemetry: the packet's last ISO-TP frame), microseconds since the Unix epoch, UTC. The one time base of every export.",
                        ..description
                    },
                ),
                "schema_fingerprint" if telemetry => (
                    "telemetry_fingerprint",
                    FINGERPRINT,
                    Description {
                        label: "Telemetry fingerprint",
                        description: "Fingerprint of the telemetry packet layout (schema/telemetry.yaml) the packet carried and the Pi decoded it with, as the CCM prints it.",
                        ..description
                    },
                ),
                "schema_fingerprint" => (
                    "dbc_fingerprint",
                    FINGERPRINT,
                    Description {
                        label: "CAN database fingerprint",
                        description: "Fingerprint of the CAN database (schema/aer.dbc) the Pi decoded the frame with, as the boards print it.",
                        ..description
                    },
                ),
                "timestamp_us" if telemetry => (
                    "timestamp_us",
                    ColumnType::I64,
                    Description {
                        label: "CCM time",
                        description: "The CCM's clock when it took the snapshot, microseconds since the CCM started: the packet's 32-bit counter with its wraps (every 71.6 min) counted in; a drop is a CCM restart. Not the time of day: see ts_us.",
                        ..description
                    },
                ),
                name => (name, column.ty, description),
            };
            ExportColumn {
                name,
                ty,
                description,
                stored: column.name,
            }
        })
        .collect()
}

/// A fingerprint as text: `0x` and eight lower-case hex digits.
const FINGERPRINT: ColumnType = ColumnType::VarChar(10);

/// A fingerprint as the boards print it.
pub fn fingerprint(value: u32) -> String {
    format!("{value:#010x}")
}

/// Turns the store's values of `data` into the exported ones: fingerprints as text, the
/// CCM's clock unwrapped.
pub(crate) fn convert(data: &mut TableData) {
    let columns = of(data.table);
    for (column, values) in columns.iter().zip(data.values.iter_mut()) {
        match (column.stored, column.name, &mut *values) {
            ("schema_fingerprint", _, Values::Int(numbers)) => {
                let text = numbers
                    .iter()
                    .map(|n| n.and_then(|n| u32::try_from(n).ok()).map(fingerprint))
                    .collect();
                *values = Values::Text(text);
            }
            ("timestamp_us", "timestamp_us", Values::Int(counts)) => unwrap_u32(counts),
            _ => {}
        }
    }
    data.columns = columns;
}

/// Counts the wraps of a 32-bit counter in arrival order: a step back by more than half its
/// range is a wrap (the CCM's clock cannot step back that far otherwise); a smaller one is a
/// restart and is kept as it is.
fn unwrap_u32(values: &mut [Option<i64>]) {
    const RANGE: i64 = 1 << 32;
    let mut wraps = 0i64;
    let mut last: Option<i64> = None;
    for value in values.iter_mut().flatten() {
        let raw = *value;
        if let Some(previous) = last {
            let step = raw - previous;
            if step < -(RANGE / 2) {
                wraps += 1;
            } else if step < 0 {
                // A restart: the counter begins again from 0, and so do its wraps.
                wraps = 0;
            }
        }
        last = Some(raw);
        *value = raw + wraps * RANGE;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ccm_clock_counts_its_wraps_and_a_restart_starts_it_again() {
        let max = i64::from(u32::MAX);
        let mut values = vec![
            Some(max - 20),
            Some(max - 10),
            None,
            Some(5),
            Some(15),
            Some(max - 5),
            Some(3),
            Some(1_000),
            Some(200),
        ];
        unwrap_u32(&mut values);
        let one = 1i64 << 32;
        assert_eq!(
            values,
            vec![
                Some(max - 20),
                Some(max - 10),
                None,
                Some(one + 5),
                Some(one + 15),
                Some(one + max - 5),
                Some(2 * one + 3),
                Some(2 * one + 1_000),
                Some(200),
            ]
        );
    }

    #[test]
    fn every_table_has_one_time_base_and_its_own_fingerprint_name() {
        for table in aer::tables::TABLES {
            let names: Vec<&str> = of(table).iter().map(|c| c.name).collect();
            assert!(names.contains(&"ts_us"), "{}", table.name);
            assert!(!names.contains(&"ts"), "{}", table.name);
            let fingerprint = if std::ptr::eq(table, &TELEMETRY) {
                "telemetry_fingerprint"
            } else {
                "dbc_fingerprint"
            };
            assert!(names.contains(&fingerprint), "{}", table.name);
        }
        assert_eq!(fingerprint(0xa7b5_12d5), "0xa7b512d5");
        assert_eq!(fingerprint(1), "0x00000001");
    }
}
