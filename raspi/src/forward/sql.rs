//! TDengine SQL for local-store rows: typed literals per column (BOOL, integers, DOUBLE,
//! VARCHAR, TIMESTAMP in us), one sub-table per car (and bus), statements under TDengine's
//! 1 MB limit. Batched SQL keeps every column's type, unlike schemaless line protocol.

use aer::tables::{ColumnType, Table};
use rusqlite::types::Value as Sql;
use std::fmt::Write as _;

/// TDengine refuses statements over 1 MB; stay well below.
pub(crate) const MAX_STATEMENT_BYTES: usize = 900 * 1024;

/// The literal for `value` in a column of type `ty`.
pub fn literal(value: &Sql, ty: ColumnType) -> String {
    match value {
        Sql::Null => "NULL".into(),
        Sql::Integer(i) if ty == ColumnType::Bool => {
            (if *i != 0 { "true" } else { "false" }).into()
        }
        Sql::Integer(i) => i.to_string(),
        Sql::Real(f) if f.is_finite() => format!("{f:?}"),
        Sql::Real(_) => "NULL".into(),
        Sql::Text(text) => quote(text),
        Sql::Blob(_) => "NULL".into(),
    }
}

/// A quoted string literal; backslashes and quotes escaped.
pub(crate) fn quote(text: &str) -> String {
    let mut quoted = String::with_capacity(text.len() + 2);
    quoted.push('\'');
    for c in text.chars() {
        if matches!(c, '\'' | '\\') {
            quoted.push('\\');
        }
        quoted.push(c);
    }
    quoted.push('\'');
    quoted
}

/// An identifier part made safe for a sub-table name.
fn ident_part(text: &str) -> String {
    text.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect()
}

/// Writes a table's local rows (tags, then columns) as TDengine inserts into `database`.
pub struct Mapping {
    table: &'static Table,
    database: String,
}

impl Mapping {
    /// Inserts into `table`'s super table in `database`.
    pub fn new(table: &'static Table, database: &str) -> Self {
        Self {
            table,
            database: database.to_owned(),
        }
    }

    /// `INSERT` statements for `rows` (local rows without `id`), each under
    /// [`MAX_STATEMENT_BYTES`], grouped by sub-table.
    pub(crate) fn inserts(&self, rows: &[Vec<Sql>]) -> Vec<String> {
        let database = &self.database;
        let columns: Vec<String> = self
            .table
            .columns
            .iter()
            .map(|c| format!("`{}`", c.name))
            .collect();
        let column_list = columns.join(", ");
        let mut statements = Vec::new();
        let mut current = String::new();
        let mut current_table = String::new();
        for row in rows {
            let tag_values = row.get(..self.table.tags.len()).unwrap_or_default();
            let sub_table = self.sub_table(tag_values);
            let values = self.values(row);
            let grows_into_new_clause = sub_table != current_table;
            let clause = if grows_into_new_clause {
                let tags: Vec<String> = self
                    .table
                    .tags
                    .iter()
                    .zip(tag_values)
                    .map(|(column, value)| literal(value, column.ty))
                    .collect();
                format!(
                    " `{database}`.`{sub_table}` USING `{database}`.`{}` TAGS ({}) ({column_list}) VALUES {values}",
                    self.table.name,
                    tags.join(", ")
                )
            } else {
                format!(" {values}")
            };
            if !current.is_empty() && current.len() + clause.len() > MAX_STATEMENT_BYTES {
                statements.push(std::mem::take(&mut current));
                current_table.clear();
                // The new statement needs the full clause with its USING part.
                let restart = self.inserts(std::slice::from_ref(row));
                current = restart.into_iter().next().unwrap_or_default();
                current_table = sub_table;
                continue;
            }
            if current.is_empty() {
                current.push_str("INSERT INTO");
            }
            current.push_str(&clause);
            current_table = sub_table;
        }
        if !current.is_empty() {
            statements.push(current);
        }
        statements
    }

    fn sub_table(&self, tags: &[Sql]) -> String {
        let mut name = self.table.name.to_owned();
        for (column, value) in self.table.tags.iter().zip(tags) {
            // The fingerprint is a tag of the super table but not part of the sub-table's
            // identity: one sub-table per car (and bus) keeps a car's history together.
            if column.name == "schema_fingerprint" {
                continue;
            }
            if let Sql::Text(text) = value {
                let _ = write!(name, "_{}", ident_part(text));
            }
        }
        name
    }

    fn values(&self, row: &[Sql]) -> String {
        // The columns follow the tags in the local row.
        let values = row.get(self.table.tags.len()..).unwrap_or_default();
        let literals: Vec<String> = self
            .table
            .columns
            .iter()
            .enumerate()
            .map(|(i, column)| {
                values
                    .get(i)
                    .map_or_else(|| "NULL".into(), |v| literal(v, column.ty))
            })
            .collect();
        format!("({})", literals.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aer::tables::TABLES;

    #[test]
    fn literals_keep_their_types() {
        assert_eq!(literal(&Sql::Integer(1), ColumnType::Bool), "true");
        assert_eq!(literal(&Sql::Integer(0), ColumnType::Bool), "false");
        assert_eq!(literal(&Sql::Integer(-40), ColumnType::I16), "-40");
        assert_eq!(literal(&Sql::Real(0.1), ColumnType::F64), "0.1");
        assert_eq!(literal(&Sql::Real(f64::NAN), ColumnType::F64), "NULL");
        assert_eq!(literal(&Sql::Null, ColumnType::I32), "NULL");
        assert_eq!(
            literal(&Sql::Text("it's".into()), ColumnType::VarChar(32)),
            "'it\\'s'"
        );
        assert_eq!(quote("a\\b"), "'a\\\\b'");
    }

    fn telemetry_row(car: &str, ts: i64) -> Vec<Sql> {
        let mut row = vec![
            Sql::Text(car.into()),
            Sql::Integer(0x1234),
            Sql::Integer(ts),
        ];
        row.resize(TABLES[0].local_columns().count(), Sql::Integer(1));
        row
    }

    #[test]
    fn rows_become_one_clause_per_sub_table_with_typed_values() {
        let mapping = Mapping::new(TABLES[0], "aer");
        let rows = [
            telemetry_row("car1", 10),
            telemetry_row("car1", 20),
            telemetry_row("car 2", 30),
        ];
        let statements = mapping.inserts(&rows);
        assert_eq!(statements.len(), 1);
        let sql = &statements[0];
        assert!(sql.starts_with("INSERT INTO `aer`.`telemetry_car1` USING `aer`.`telemetry` TAGS ('car1', 4660) (`ts`, "), "{sql}");
        assert_eq!(sql.matches(" USING ").count(), 2, "car1 and car_2");
        assert!(sql.contains("`aer`.`telemetry_car_2`"));
        assert!(sql.contains("(10, "), "timestamps in us as integers");
        // BOOL flags as true/false, not floats.
        assert!(sql.contains("true"));
        assert!(!sql.contains("1.0"), "no everything-as-float");
    }

    #[test]
    fn large_batches_split_under_the_statement_limit() {
        let mapping = Mapping::new(TABLES[0], "aer");
        let rows: Vec<Vec<Sql>> = (0..5_000).map(|i| telemetry_row("car1", i)).collect();
        let statements = mapping.inserts(&rows);
        assert!(statements.len() > 1);
        assert!(statements.iter().all(|s| s.len() <= MAX_STATEMENT_BYTES));
        assert!(
            statements
                .iter()
                .all(|s| s.starts_with("INSERT INTO `aer`.`telemetry_car1` USING"))
        );
        let rows_written: usize = statements
            .iter()
            .map(|s| {
                s.split(" VALUES ")
                    .nth(1)
                    .map_or(0, |v| v.matches(") (").count() + 1)
            })
            .sum();
        assert_eq!(rows_written, 5_000);
    }
}
