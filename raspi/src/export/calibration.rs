//! The session's calibration record as an export table (`calibration.csv`,
//! `calibration.parquet`, MCAP metadata records): one row per entry of
//! [`crate::store::calibration`], with the parameter's unit from the schema, so a run's data
//! says which calibration produced it and two runs' records compare.

use super::columns::{TableData, Values};
use crate::store::calibration::{ECU_PAGE, Entry, Kind};
use aer::calibration::PARAMETERS;
use aer::tables::ColumnType;

/// The table's name in every format.
pub const NAME: &str = "calibration";

/// One column of the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Column {
    pub name: &'static str,
    pub ty: ColumnType,
    /// Never NULL.
    pub required: bool,
    pub description: &'static str,
}

const fn column(
    name: &'static str,
    ty: ColumnType,
    required: bool,
    description: &'static str,
) -> Column {
    Column {
        name,
        ty,
        required,
        description,
    }
}

/// The columns, in order.
pub const COLUMNS: [Column; 11] = [
    column(
        "ts_us",
        ColumnType::Timestamp,
        true,
        "When the CCM answered, as the Pi's gateway saw it (microseconds since the Unix epoch, UTC)",
    ),
    column(
        "master",
        ColumnType::VarChar(64),
        true,
        "The calibration tool's address (XCP on TCP through the Pi's gateway)",
    ),
    column(
        "kind",
        ColumnType::VarChar(8),
        true,
        "found (the value when a master connected), write, revert (to the reference page), page (the page the CCM runs on: 0 working, 1 reference), save (to flash)",
    ),
    column(
        "parameter",
        ColumnType::VarChar(64),
        true,
        "The calibration parameter (schema/calibration.yaml); ecu_page for a page switch, empty for a save",
    ),
    column(
        "element",
        ColumnType::I32,
        false,
        "The element of a curve or list (empty for a scalar)",
    ),
    column(
        "unit",
        ColumnType::VarChar(16),
        true,
        "The parameter's unit",
    ),
    column(
        "old",
        ColumnType::F64,
        false,
        "The value before (empty if the gateway did not know it)",
    ),
    column(
        "new",
        ColumnType::F64,
        false,
        "The value after, or the value refused",
    ),
    column(
        "accepted",
        ColumnType::Bool,
        true,
        "Whether the CCM took the change",
    ),
    column(
        "reason",
        ColumnType::VarChar(128),
        true,
        "Why the CCM refused it (empty when accepted)",
    ),
    column(
        "checksum",
        ColumnType::U32,
        false,
        "CRC-32 of the page the CCM runs on afterwards, the value CCM_Calibration's CCM_CalChecksum carries",
    ),
];

/// The record as columns.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationTable {
    pub rows: usize,
    /// One per [`COLUMNS`] entry.
    pub values: Vec<Values>,
}

impl CalibrationTable {
    /// The table of `entries`.
    pub fn of(entries: &[Entry]) -> Self {
        let text = |f: &dyn Fn(&Entry) -> String| {
            Values::Text(entries.iter().map(|e| Some(f(e))).collect())
        };
        let unit = |e: &Entry| {
            PARAMETERS
                .iter()
                .find(|p| p.name == e.parameter)
                .map_or("", |p| p.unit)
                .to_owned()
        };
        Self {
            rows: entries.len(),
            values: vec![
                Values::Int(entries.iter().map(|e| Some(e.at_us)).collect()),
                text(&|e| e.master.clone()),
                text(&|e| e.kind.name().to_owned()),
                text(&|e| e.parameter.clone()),
                Values::Int(entries.iter().map(|e| e.element.map(i64::from)).collect()),
                text(&unit),
                Values::F64(entries.iter().map(|e| e.old).collect()),
                Values::F64(entries.iter().map(|e| e.new).collect()),
                Values::Bool(entries.iter().map(|e| Some(e.accepted)).collect()),
                text(&|e| e.reason.clone()),
                Values::Int(entries.iter().map(|e| e.checksum.map(i64::from)).collect()),
            ],
        }
    }

    /// Each column with its values.
    pub fn columns(&self) -> impl Iterator<Item = (&'static Column, &Values)> {
        COLUMNS.iter().zip(&self.values)
    }
}

/// What the export's metadata says of the calibration: the checksums the CCM broadcast
/// (`CCM_Calibration`, in `tables`) in the order they came, whether a master changed anything
/// or not; and of the record, how many changes were accepted and refused, the checksum after
/// each, and the page the CCM ran on at the end.
pub fn metadata(entries: &[Entry], tables: &[TableData]) -> Vec<(String, String)> {
    let changes = entries.iter().filter(|e| e.kind != Kind::Found);
    let (accepted, refused) =
        changes.fold(
            (0, 0),
            |(a, r), e| {
                if e.accepted { (a + 1, r) } else { (a, r + 1) }
            },
        );
    let broadcast = tables
        .iter()
        .find(|t| t.table.name == "can_ccm_calibration")
        .and_then(|t| t.columns().find(|(c, _)| c.name == "ccm_cal_checksum"))
        .map(|(_, values)| match values {
            Values::Int(v) => v.iter().flatten().copied().collect(),
            _ => Vec::new(),
        })
        .unwrap_or_default();
    let listed = |checksums: &mut dyn Iterator<Item = i64>, none: &str| {
        let mut out: Vec<String> = Vec::new();
        for checksum in checksums {
            let hex = format!("0x{checksum:08x}");
            if out.last() != Some(&hex) {
                out.push(hex);
            }
        }
        if out.is_empty() {
            none.to_owned()
        } else {
            out.join(" ")
        }
    };
    let page = entries
        .iter()
        .rev()
        .find(|e| e.parameter == ECU_PAGE && e.accepted)
        .and_then(|e| e.new);
    vec![
        ("calibration_changes".into(), accepted.to_string()),
        ("calibration_refusals".into(), refused.to_string()),
        (
            "ccm_cal_checksums".into(),
            listed(
                &mut broadcast.into_iter(),
                "none (no CCM_Calibration frame in the selection)",
            ),
        ),
        (
            "calibration_record_checksums".into(),
            listed(
                &mut entries.iter().filter_map(|e| e.checksum.map(i64::from)),
                "none (no master connected through the gateway)",
            ),
        ),
        (
            "calibration_page_at_end".into(),
            match page {
                Some(0.0) => "working".into(),
                Some(_) => "reference".into(),
                None => "unknown".into(),
            },
        ),
    ]
}
