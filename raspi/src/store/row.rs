//! A record as a row of its table: the decoded values themselves, bound straight into the
//! table's prepared insert, so nothing is allocated per row.

use aer::can::AnyMessage;
use aer::runtime::{SignalMeta, SignalVisitor, Value};
use aer::tables::{self, Table};
use aer::telemetry::{Telemetry, TelemetryHeader};
use aer_host::decode::{FrameCheck, Record};
use rusqlite::Statement;
use std::sync::Arc;

/// One record on its way into the store: the decoded values themselves. The writer binds
/// them straight into its insert, so the pipeline allocates nothing per row.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub car_id: Arc<str>,
    /// Receive time (us since the epoch).
    pub ts_us: u64,
    pub data: RowData,
}

/// What a row holds.
#[derive(Debug, Clone, PartialEq)]
pub enum RowData {
    Telemetry {
        header: TelemetryHeader,
        telemetry: Telemetry,
    },
    Can {
        /// The bus's interface name.
        bus: Arc<str>,
        message: AnyMessage,
        /// What the message's counter, checksum and freshness limit said of the frame.
        check: FrameCheck,
    },
}

/// The row a record becomes; `bus_names` maps bus numbers to interface names.
pub fn row(record: &Record, car_id: &Arc<str>, bus_names: &[Arc<str>]) -> Row {
    match record {
        Record::Telemetry {
            ts_us,
            header,
            telemetry,
            ..
        } => Row {
            car_id: car_id.clone(),
            ts_us: *ts_us,
            data: RowData::Telemetry {
                header: *header,
                telemetry: **telemetry,
            },
        },
        Record::Can {
            ts_us,
            bus,
            message,
            check,
        } => Row {
            car_id: car_id.clone(),
            ts_us: *ts_us,
            data: RowData::Can {
                bus: crate::bus_names::bus_name(bus_names, *bus),
                message: *message,
                check: *check,
            },
        },
    }
}

impl Row {
    /// The row's table.
    pub fn table(&self) -> &'static Table {
        match &self.data {
            RowData::Telemetry { .. } => &tables::TELEMETRY,
            RowData::Can { message, .. } => tables::for_message(message),
        }
    }

    /// Binds every column of the row into `statement` (its table's insert).
    pub fn bind(&self, statement: &mut Statement<'_>) -> rusqlite::Result<()> {
        let ts = i64::try_from(self.ts_us).unwrap_or(i64::MAX);
        statement.raw_bind_parameter(1, &*self.car_id)?;
        match &self.data {
            RowData::Telemetry { header, telemetry } => {
                statement.raw_bind_parameter(2, aer::telemetry::TELEMETRY_FINGERPRINT)?;
                statement.raw_bind_parameter(3, ts)?;
                statement.raw_bind_parameter(4, header.sequence)?;
                statement.raw_bind_parameter(5, header.timestamp_us)?;
                let mut binder = Binder::new(statement, 6);
                telemetry.visit(&mut binder);
                binder.result
            }
            RowData::Can { bus, message, .. } => {
                // Multiplexed signals that are absent must read NULL, not the previous row's.
                statement.clear_bindings();
                statement.raw_bind_parameter(1, &*self.car_id)?;
                statement.raw_bind_parameter(2, &**bus)?;
                statement.raw_bind_parameter(3, aer::can::SCHEMA_FINGERPRINT)?;
                statement.raw_bind_parameter(4, ts)?;
                let mut binder = Binder::new(statement, 5);
                message.visit(&mut binder);
                binder.result
            }
        }
    }
}

/// Binds visited values at their signal's column: parameter `first` holds signal 0.
struct Binder<'s, 'c> {
    statement: &'s mut Statement<'c>,
    first: usize,
    result: rusqlite::Result<()>,
}

impl<'s, 'c> Binder<'s, 'c> {
    fn new(statement: &'s mut Statement<'c>, first: usize) -> Self {
        Self {
            statement,
            first,
            result: Ok(()),
        }
    }
}

impl SignalVisitor for Binder<'_, '_> {
    fn signal(&mut self, signal: &'static SignalMeta, value: Value, _: Option<&'static str>) {
        if self.result.is_err() {
            return;
        }
        let index = self.first + usize::from(signal.index);
        self.result = match value {
            Value::Int(i) => match i64::try_from(i) {
                Ok(i) => self.statement.raw_bind_parameter(index, i),
                Err(_) => self.statement.raw_bind_parameter(index, i as f64),
            },
            Value::Float(f) if f.is_finite() => self.statement.raw_bind_parameter(index, f),
            Value::Float(_) => self
                .statement
                .raw_bind_parameter(index, rusqlite::types::Null),
        };
    }
}
