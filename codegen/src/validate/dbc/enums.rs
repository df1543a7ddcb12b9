//! Enums from value tables: `VAL_TABLE_`s become named types, and a signal's `VAL_` list shares
//! the table's type when they name the same values.

use std::collections::HashSet;

use super::{Builder, first_free};
use crate::diagnostic::Code;
use crate::model::Encoding;
use crate::model::{EnumType, IntType, Signal, Variant};
use crate::naming::camel;

impl Builder<'_, '_> {
    /// Finds or creates the enum for a signal's value descriptions. A signal whose descriptions
    /// equal a `VAL_TABLE_` shares that table's type, so one enum serves every signal using it.
    pub(super) fn enum_for(
        &mut self,
        s: &Signal,
        choices: &[can_dbc::ValDescription],
        line: usize,
        where_: &str,
        type_name: &str,
        enums: &mut Vec<EnumType>,
    ) -> Option<usize> {
        let kept = self.named_values(s, choices, line, where_);
        let raw = s.raw_int();
        if let Some((i, e)) = self
            .table_enums
            .get(&kept)
            .and_then(|&i| Some((i, enums.get_mut(i)?)))
        {
            let (a, b) = e.repr.range();
            let (c, d) = raw.range();
            e.repr = IntType::smallest_for(a.min(c), b.max(d));
            return Some(i);
        }
        if kept.is_empty() {
            self.r.report(
                Code::UnusableValues,
                line,
                format!("{where_} has no usable value descriptions"),
                "remove its VAL_ line",
            );
        }
        let wanted = format!("{type_name}{}", camel(&s.name));
        let name = self.claim_type_name(&wanted, [], line, || format!("the enum of {where_}"));
        enums.push(EnumType {
            type_name: name,
            variants: variants(&kept),
            repr: raw,
        });
        Some(enums.len() - 1)
    }

    /// A signal's value descriptions as raw values, sorted and without repeats; values its raw
    /// bits cannot hold are reported and left out.
    pub(super) fn named_values(
        &mut self,
        s: &Signal,
        choices: &[can_dbc::ValDescription],
        line: usize,
        where_: &str,
    ) -> Vec<(i128, String)> {
        let (lo, hi) = s.raw_range();
        let mut kept = Vec::new();
        for c in choices {
            let v = i128::from(c.id);
            // VAL_ values are written as raw bit patterns or as signed raw values; accept both.
            let v = if s.encoding == Encoding::Signed && v > hi && v < (1i128 << s.len) {
                v - (1i128 << s.len)
            } else {
                v
            };
            if v < lo || v > hi {
                self.r.report(
                    Code::UnusableValues,
                    line,
                    format!(
                        "{where_} names value {} (`{}`), which its {}-bit raw value can never hold",
                        c.id, c.description, s.len
                    ),
                    "remove the value from the VAL_ line or fix the signal's length or sign",
                );
                continue;
            }
            kept.push((v, c.description.clone()));
        }
        kept.sort_by_key(|(v, _)| *v);
        kept.dedup_by_key(|(v, _)| *v);
        kept
    }

    /// An enum for each `VAL_TABLE_` (each with its own type name), and which of them a `VAL_`
    /// list with the same values shares (the first table with those values).
    pub(super) fn value_tables(&mut self) -> Vec<EnumType> {
        let tables = &self.loaded.dbc.value_tables;
        let mut enums = Vec::with_capacity(tables.len());
        for (i, t) in tables.iter().enumerate() {
            let kept = sorted_values(&t.descriptions);
            let lo = kept.first().map_or(0, |(v, _)| *v);
            let hi = kept.last().map_or(0, |(v, _)| *v);
            let line = self
                .loaded
                .lines
                .value_tables
                .get(&t.name)
                .copied()
                .unwrap_or(1);
            let name = self.claim_type_name(&camel(&t.name), [], line, || {
                format!("value table `{}`", t.name)
            });
            self.table_enums.entry(kept.clone()).or_insert(i);
            enums.push(EnumType {
                type_name: name,
                variants: variants(&kept),
                repr: IntType::smallest_for(lo.min(0), hi),
            });
        }
        enums
    }

    /// Takes `wanted` as a Rust type name, or the first free variant of it (with a W0204 that
    /// names `what` was renamed).
    pub(super) fn claim_type_name(
        &mut self,
        wanted: &str,
        suffixes: impl IntoIterator<Item = String>,
        line: usize,
        what: impl FnOnce() -> String,
    ) -> String {
        let name = first_free(wanted, suffixes, |n| !self.taken.type_names.contains_key(n));
        if name != wanted {
            let first = self.taken.type_names.get(wanted).copied().unwrap_or(0);
            let taken_by = if first == 0 {
                "a name the generated code uses itself".to_owned()
            } else {
                format!("a name already taken (line {first})")
            };
            self.r.report(
                Code::Renamed,
                line,
                format!(
                    "{} would be the Rust type `{wanted}`, {taken_by}; it is `{name}`",
                    what()
                ),
                "keep message, value-table and signal names distinct after conversion to CamelCase",
            );
        }
        self.taken.type_names.insert(name.clone(), line);
        name
    }
}

/// Enum variants with unique identifiers; `Unknown` is reserved for the fallback variant.
fn variants(values: &[(i128, String)]) -> Vec<Variant> {
    let mut taken: HashSet<String> = HashSet::from(["Unknown".to_owned()]);
    values
        .iter()
        .map(|(value, label)| {
            let mut ident = camel(label);
            if !taken.insert(ident.clone()) {
                ident = format!("{ident}{}", value.unsigned_abs());
                while !taken.insert(ident.clone()) {
                    ident.push('_');
                }
            }
            Variant {
                ident,
                value: *value,
                label: label.clone(),
            }
        })
        .collect()
}

/// (value, label) pairs by value, the first label kept where a value repeats.
fn sorted_values(descriptions: &[can_dbc::ValDescription]) -> Vec<(i128, String)> {
    let mut values: Vec<(i128, String)> = descriptions
        .iter()
        .map(|d| (i128::from(d.id), d.description.clone()))
        .collect();
    values.sort_by_key(|(v, _)| *v);
    values.dedup_by_key(|(v, _)| *v);
    values
}
