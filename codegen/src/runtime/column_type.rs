/// The type of a column, and how each database spells it. (This item is Rust source the
/// generator compiles and also copies verbatim into the generated `tables.rs`, as svd2rust
/// does with its `generic.rs`: the DDL the generator writes and the runtime's spelling of the
/// same types cannot drift apart.)
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColumnType {
    /// Microseconds since the Unix epoch.
    Timestamp,
    Bool,
    I8,
    I16,
    I32,
    I64,
    U8,
    U16,
    U32,
    U64,
    F32,
    F64,
    /// Text of at most this many bytes (decimal text for 128-bit integers).
    VarChar(u16),
}

impl ColumnType {
    /// TDengine's type, which holds every value exactly.
    pub fn tdengine(self) -> String {
        match self {
            Self::Timestamp => "TIMESTAMP".into(),
            Self::Bool => "BOOL".into(),
            Self::I8 => "TINYINT".into(),
            Self::I16 => "SMALLINT".into(),
            Self::I32 => "INT".into(),
            Self::I64 => "BIGINT".into(),
            Self::U8 => "TINYINT UNSIGNED".into(),
            Self::U16 => "SMALLINT UNSIGNED".into(),
            Self::U32 => "INT UNSIGNED".into(),
            Self::U64 => "BIGINT UNSIGNED".into(),
            Self::F32 => "FLOAT".into(),
            Self::F64 => "DOUBLE".into(),
            Self::VarChar(n) => format!("VARCHAR({n})"),
        }
    }

    /// SQLite's storage class: timestamps, flags and every integer fit its 64-bit INTEGER.
    pub const fn sqlite(self) -> &'static str {
        match self {
            Self::F32 | Self::F64 => "REAL",
            Self::VarChar(_) => "TEXT",
            _ => "INTEGER",
        }
    }
}
