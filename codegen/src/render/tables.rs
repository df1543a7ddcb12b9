//! Renders the car's tables: one for the telemetry packet and one per CAN message, each a
//! TDengine super table and the Pi's SQLite table with the same name and columns, so a stored
//! row is forwarded column for column. Lossless column types: exact integers stay integers.

use askama::Template;

use crate::model::{Database, IntType, PhysType, Telemetry};

#[derive(Template)]
#[template(path = "tables.rs", escape = "none")]
pub(crate) struct TablesRust<'a> {
    pub source: &'a str,
    pub column_type: &'static str,
    pub tables: Vec<Table>,
}

#[derive(Template)]
#[template(path = "tdengine.sql", escape = "none")]
pub(crate) struct TdengineSql<'a> {
    pub source: &'a str,
    pub tables: Vec<Table>,
}

#[derive(Template)]
#[template(path = "sqlite.sql", escape = "none")]
pub(crate) struct SqliteSql<'a> {
    pub source: &'a str,
    pub tables: Vec<Table>,
}

pub(crate) use crate::runtime::column_type::ColumnType;

impl ColumnType {
    /// The type holding every physical value exactly.
    fn of(db: &Database, phys: PhysType) -> Self {
        match phys {
            PhysType::Bool => Self::Bool,
            PhysType::F32 => Self::F32,
            PhysType::F64 => Self::F64,
            PhysType::Int(t) => Self::int(t),
            // Enums are stored as their raw value; labels come from the schema.
            PhysType::Enum(i) => db.enums.get(i).map_or(Self::I64, |e| Self::int(e.repr)),
        }
    }

    fn int(t: IntType) -> Self {
        match t {
            IntType::U8 => Self::U8,
            IntType::U16 => Self::U16,
            IntType::U32 => Self::U32,
            IntType::U64 => Self::U64,
            IntType::I8 => Self::I8,
            IntType::I16 => Self::I16,
            IntType::I32 => Self::I32,
            IntType::I64 => Self::I64,
            // Wider than any TDengine integer: the decimal text is exact.
            IntType::U128 | IntType::I128 => Self::VarChar(40),
        }
    }

    /// The generated enum's variant.
    pub(crate) fn variant(self) -> String {
        match self {
            Self::VarChar(n) => format!("VarChar({n})"),
            other => format!("{other:?}"),
        }
    }
}

pub(crate) struct Column {
    pub name: String,
    pub ty: ColumnType,
}

impl Column {
    fn new(name: &str, ty: ColumnType) -> Self {
        Self {
            name: name.to_owned(),
            ty,
        }
    }
}

pub(crate) struct Table {
    pub name: String,
    pub const_name: String,
    pub doc: String,
    /// What tells sub-tables apart (car, bus) and the schema fingerprint.
    pub tags: Vec<Column>,
    /// `ts` first, then one per field or signal in schema order.
    pub columns: Vec<Column>,
    /// The message's `AnyMessage` variant; `None` for the telemetry table.
    pub message: Option<String>,
}

impl Table {
    /// The path of the schema's description of the values (the packet's fields or the
    /// message's signals), which fill the last columns.
    pub(crate) fn signals(&self) -> String {
        match &self.message {
            Some(message) => format!("super::can::{message}::META.signals"),
            None => "super::telemetry::Telemetry::FIELDS".to_owned(),
        }
    }

    fn new(name: String, doc: String, tags: Vec<Column>, columns: Vec<Column>) -> Self {
        Self {
            const_name: name.to_ascii_uppercase(),
            name,
            doc,
            tags,
            columns,
            message: None,
        }
    }

    /// `CREATE STABLE IF NOT EXISTS ...`.
    pub(crate) fn tdengine_create(&self) -> String {
        let list = |columns: &[Column]| {
            columns
                .iter()
                .map(|c| format!("`{}` {}", c.name, c.ty.tdengine()))
                .collect::<Vec<_>>()
                .join(", ")
        };
        format!(
            "CREATE STABLE IF NOT EXISTS `{}` ({}) TAGS ({})",
            self.name,
            list(&self.columns),
            list(&self.tags)
        )
    }

    /// `INSERT INTO ? USING <stable> TAGS (?, ...) VALUES (?, ...)`, for parameter binding.
    pub(crate) fn tdengine_insert(&self) -> String {
        let marks = |n: usize| vec!["?"; n].join(", ");
        format!(
            "INSERT INTO ? USING `{}` TAGS ({}) VALUES ({})",
            self.name,
            marks(self.tags.len()),
            marks(self.columns.len())
        )
    }

    /// The local row: tags, then columns.
    fn local_columns(&self) -> impl Iterator<Item = &Column> {
        self.tags.iter().chain(&self.columns)
    }

    /// `CREATE TABLE IF NOT EXISTS ...`: a row id, then tags and columns; tags and `ts` are
    /// required. Row ids are never reused (`AUTOINCREMENT`), even once every row of a table
    /// was pruned or compacted: the forwarder's cursor and the sessions' row ranges count on
    /// them only growing.
    pub(crate) fn sqlite_create(&self) -> String {
        let defs: Vec<String> = self
            .local_columns()
            .enumerate()
            .map(|(i, c)| {
                let required = i <= self.tags.len();
                format!(
                    "\"{}\" {}{}",
                    c.name,
                    c.ty.sqlite(),
                    if required { " NOT NULL" } else { "" }
                )
            })
            .collect();
        format!(
            "CREATE TABLE IF NOT EXISTS \"{}\" (\"id\" INTEGER PRIMARY KEY AUTOINCREMENT, {})",
            self.name,
            defs.join(", ")
        )
    }

    /// `INSERT INTO ... VALUES (?1, ...)`, one parameter per column of the local row.
    pub(crate) fn sqlite_insert(&self) -> String {
        let names: Vec<String> = self
            .local_columns()
            .map(|c| format!("\"{}\"", c.name))
            .collect();
        let marks: Vec<String> = (1..=names.len()).map(|i| format!("?{i}")).collect();
        format!(
            "INSERT INTO \"{}\" ({}) VALUES ({})",
            self.name,
            names.join(", "),
            marks.join(", ")
        )
    }
}

pub(crate) fn tables(db: &Database, t: &Telemetry) -> Vec<Table> {
    let car = || Column::new("car_id", ColumnType::VarChar(32));
    let schema = || Column::new("schema_fingerprint", ColumnType::U32);
    let ts = || Column::new("ts", ColumnType::Timestamp);
    let mut columns = vec![
        ts(),
        Column::new("sequence", ColumnType::U16),
        Column::new("timestamp_us", ColumnType::U32),
    ];
    columns.extend(
        t.fields
            .iter()
            .map(|f| Column::new(&f.name, ColumnType::of(db, f.phys))),
    );
    let mut out = vec![Table::new(
        "telemetry".to_owned(),
        format!(
            "The telemetry packet ({}), one row per packet.",
            t.type_name
        ),
        vec![car(), schema()],
        columns,
    )];
    for m in &db.messages {
        let mut columns = vec![ts()];
        columns.extend(
            m.signals
                .iter()
                .map(|s| Column::new(s.field.trim_end_matches('_'), ColumnType::of(db, s.phys))),
        );
        let mut table = Table::new(
            format!("can_{}", m.item_name),
            format!(
                "CAN message `{}` (0x{:X}), one row per frame; multiplexed signals are NULL when absent.",
                m.name, m.id
            ),
            vec![car(), Column::new("bus", ColumnType::VarChar(16)), schema()],
            columns,
        );
        table.message = Some(m.type_name.clone());
        out.push(table);
    }
    out
}

pub(crate) fn render_rust(
    db: &Database,
    t: &Telemetry,
    source: &str,
) -> Result<String, askama::Error> {
    TablesRust {
        source,
        column_type: crate::runtime::COLUMN_TYPE,
        tables: tables(db, t),
    }
    .render()
}

pub(crate) fn render_tdengine_sql(
    db: &Database,
    t: &Telemetry,
    source: &str,
) -> Result<String, askama::Error> {
    TdengineSql {
        source,
        tables: tables(db, t),
    }
    .render()
}

pub(crate) fn render_sqlite_sql(
    db: &Database,
    t: &Telemetry,
    source: &str,
) -> Result<String, askama::Error> {
    SqliteSql {
        source,
        tables: tables(db, t),
    }
    .render()
}
