//! The run on a 100 Hz grid (`resampled_100hz.csv`): one row every 10 ms from the first
//! telemetry packet to the last, each column the latest value received at or before that
//! instant (a value holds until the next), enum columns with their names beside them; every
//! telemetry field, the derived channels, and the CAN signals asked for
//! (`--signal can_dti_speed.dti_erpm`, as the exports name table and column), so one frame
//! of polars or pandas holds the run without a join.

use super::ReportError;
use super::run::Run;
use crate::export::columns::TableData;
use crate::export::load::{self, Selection};
use aer::tables::TABLES;
use aer_host::run::derived::CHANNELS;
use rusqlite::Connection;
use std::fmt::Write as _;

/// The grid's step.
pub const STEP_US: i64 = 10_000;

/// One resampled column: its name, its values' times (us) and values, its value names.
pub struct Column {
    pub name: String,
    pub times: Vec<i64>,
    pub values: Vec<f64>,
    pub labels: &'static [(i128, &'static str)],
}

/// The columns `table.column` names, read from session `session`'s rows.
pub fn signals(
    db: &Connection,
    session: i64,
    wanted: &[String],
) -> Result<Vec<Column>, ReportError> {
    let mut columns = Vec::new();
    for name in wanted {
        let unknown = || ReportError::UnknownSignal(name.clone());
        let (table_name, column_name) = name.split_once('.').ok_or_else(unknown)?;
        let table = TABLES
            .iter()
            .find(|t| t.name == table_name)
            .ok_or_else(unknown)?;
        let data = load::table(
            db,
            table,
            Selection {
                session: Some(session),
                ..Selection::default()
            },
        )?;
        columns.push(column_of(&data, column_name).ok_or_else(unknown)?);
    }
    Ok(columns)
}

fn column_of(data: &TableData, name: &str) -> Option<Column> {
    let (column, values) = data.columns().find(|(c, _)| c.name == name)?;
    let numbers = super::run::numbers(values)?;
    Some(Column {
        name: format!("{}.{name}", data.table.name),
        times: data
            .timestamps()
            .iter()
            .map(|t| t.unwrap_or(i64::MIN))
            .collect(),
        values: numbers,
        labels: column.description.values,
    })
}

/// The telemetry's columns, as the run read them.
fn telemetry(run: &Run) -> Vec<Column> {
    let times: Vec<i64> = run
        .t
        .iter()
        .map(|t| run.origin_us + (t * 1e6).round() as i64)
        .collect();
    let mut columns: Vec<Column> = aer::telemetry::Telemetry::FIELDS
        .iter()
        .filter_map(|meta| {
            let values = run.fields.get(meta.name)?;
            Some(Column {
                name: meta.name.to_owned(),
                times: times.clone(),
                values: values.clone(),
                labels: meta.labels,
            })
        })
        .collect();
    for (i, channel) in CHANNELS.iter().enumerate() {
        columns.push(Column {
            name: format!("{}_{}", channel.name, channel.unit.replace('/', "_")),
            times: times.clone(),
            values: run
                .derived
                .iter()
                .map(|s| s.values().get(i).copied().unwrap_or(f64::NAN))
                .collect(),
            labels: &[],
        });
    }
    columns
}

/// The table as CSV: `ts_us`, then each column (and `<column>_label` for an enum's name).
pub fn csv(run: &Run, extra: &[Column]) -> String {
    let own = telemetry(run);
    let columns: Vec<&Column> = own.iter().chain(extra).collect();
    let mut out = String::from("ts_us");
    for c in &columns {
        let _ = write!(out, ",{}", c.name);
        if !c.labels.is_empty() {
            let _ = write!(out, ",{}_label", c.name);
        }
    }
    out.push('\n');
    let (Some(first), Some(last)) = (
        own.first().and_then(|c| c.times.first()),
        own.first().and_then(|c| c.times.last()),
    ) else {
        return out;
    };
    let mut next = vec![0usize; columns.len()];
    let mut at = *first;
    while at <= *last {
        let _ = write!(out, "{at}");
        for (c, cursor) in columns.iter().zip(next.iter_mut()) {
            while c.times.get(*cursor).is_some_and(|&t| t <= at) {
                *cursor += 1;
            }
            let value = cursor
                .checked_sub(1)
                .and_then(|i| c.values.get(i))
                .copied()
                .filter(|v| v.is_finite());
            match value {
                Some(v) => {
                    let _ = write!(out, ",{v}");
                }
                None => out.push(','),
            }
            if !c.labels.is_empty() {
                let name = value.and_then(|v| {
                    c.labels
                        .iter()
                        .find(|(raw, _)| *raw as f64 == v)
                        .map(|(_, name)| *name)
                });
                let _ = write!(out, ",{}", name.unwrap_or(""));
            }
        }
        out.push('\n');
        at += STEP_US;
    }
    out
}
