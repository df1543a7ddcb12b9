//! The telemetry packet as the schema describes it: every field's label, unit, group and
//! thresholds, read from the generated tables rather than written per field, so a field added
//! to schema/telemetry.yaml appears on the dashboard without a code change.

use aer::runtime::{SignalMeta, SignalVisitor, Value};
use aer::telemetry::{FieldDisplay, Level, Telemetry};

/// A table of fields: what the pit view and the alarms read. [`Schema::TELEMETRY`] is the
/// car's; tests build others.
#[derive(Debug, Clone, Copy)]
pub struct Schema {
    pub fields: &'static [SignalMeta],
    pub display: &'static [FieldDisplay],
}

/// One field of a [`Schema`].
#[derive(Debug, Clone, Copy)]
pub struct Field {
    /// Position in the schema (and in every value list).
    pub index: usize,
    pub meta: &'static SignalMeta,
    pub display: &'static FieldDisplay,
}

/// One field's value in one packet.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldValue {
    /// The physical value (a flag is 0 or 1; an enum its raw value).
    pub value: f64,
    /// The name of an enum value, when the schema names it.
    pub label: Option<&'static str>,
}

impl Schema {
    /// The car's telemetry packet.
    pub const TELEMETRY: Self = Self {
        fields: Telemetry::FIELDS,
        display: Telemetry::DISPLAY,
    };

    /// Every field, in schema order.
    pub fn fields(&self) -> impl Iterator<Item = Field> + '_ {
        self.fields
            .iter()
            .zip(self.display)
            .enumerate()
            .map(|(index, (meta, display))| Field {
                index,
                meta,
                display,
            })
    }

    /// The field at `index`.
    pub fn get(&self, index: usize) -> Option<Field> {
        Some(Field {
            index,
            meta: self.fields.get(index)?,
            display: self.display.get(index)?,
        })
    }

    /// The field called `name`.
    pub fn field(&self, name: &str) -> Option<Field> {
        self.fields().find(|f| f.meta.name == name)
    }

    /// Field indices grouped by their pit-view section, sections in the order they first
    /// appear in the schema.
    pub fn groups(&self) -> Vec<(&'static str, Vec<usize>)> {
        let mut groups: Vec<(&'static str, Vec<usize>)> = Vec::new();
        for field in self.fields() {
            match groups.iter_mut().find(|(g, _)| *g == field.display.group) {
                Some((_, members)) => members.push(field.index),
                None => groups.push((field.display.group, vec![field.index])),
            }
        }
        groups
    }
}

impl Field {
    /// A one-bit field: on or off.
    pub fn is_flag(&self) -> bool {
        self.meta.len == 1 && self.meta.labels.is_empty()
    }

    /// A flag with thresholds in the schema: set means a fault or warning to show by name.
    pub fn is_alarm(&self) -> bool {
        self.is_flag() && self.display.has_thresholds()
    }

    /// How `value` stands against the field's thresholds.
    pub fn level(&self, value: f64) -> Level {
        self.display.level(value)
    }

    /// The value as text: enum names, on/off for flags, numbers to the resolution the wire
    /// carries.
    pub fn format(&self, value: FieldValue) -> String {
        format(self.meta, value)
    }

    /// The unit as shown (none for a status code shown in hex).
    pub fn unit(&self) -> &'static str {
        unit(self.meta)
    }

    /// What the schema says about the field (its description), for a tooltip.
    pub fn description(&self) -> &'static str {
        self.meta.comment
    }
}

/// A packet field's or a CAN signal's value as text: enum names, on/off for one-bit values,
/// vendor status codes in hex, numbers to the resolution the wire carries.
pub fn format(meta: &SignalMeta, value: FieldValue) -> String {
    if meta.len == 1 && meta.labels.is_empty() {
        return if value.value != 0.0 { "ON" } else { "off" }.to_owned();
    }
    if !meta.labels.is_empty() {
        return match value.label {
            Some(label) => label.to_owned(),
            None => format!("unknown ({})", value.value),
        };
    }
    if is_code(meta) {
        // A vendor's status code without names in the schema: in hex, as manuals list them.
        return format!("0x{:02X}", value.value as i64);
    }
    format!("{:.*}", decimals(meta.factor), value.value)
}

/// A packet field's or a CAN signal's unit as shown (none for a status code shown in hex).
pub fn unit(meta: &'static SignalMeta) -> &'static str {
    if is_code(meta) {
        return "";
    }
    display_unit(meta.unit)
}

/// A status code (unit `code`) whose values the schema does not name.
fn is_code(meta: &SignalMeta) -> bool {
    meta.unit == "code" && meta.labels.is_empty()
}

/// Decimal places that show one step of a value scaled by `factor` (0.01 -> 2, 0.004 -> 3).
pub fn decimals(factor: f64) -> usize {
    if !(factor.is_finite() && factor > 0.0) || factor >= 1.0 {
        return 0;
    }
    // The epsilon keeps 0.01 at 2 places although log10(0.01) is not exactly -2.
    ((-factor.log10() - 1e-9).ceil() as usize).min(6)
}

/// A unit as shown on screen.
pub fn display_unit(unit: &'static str) -> &'static str {
    match unit {
        "degC" => "°C",
        "Ohm" => "Ω",
        "kOhm" => "kΩ",
        other => other,
    }
}

/// A group name as a heading: `inverter_faults` -> `Inverter faults`.
pub fn heading(group: &str) -> String {
    let mut text = group.replace('_', " ");
    if let Some(first) = text.get(..1) {
        let upper = first.to_uppercase();
        text.replace_range(..1, &upper);
    }
    text
}

/// Reads every field of `telemetry` into `out` (cleared first), in schema order.
pub fn read(telemetry: &Telemetry, out: &mut Vec<FieldValue>) {
    struct Collect<'a>(&'a mut Vec<FieldValue>);
    impl SignalVisitor for Collect<'_> {
        fn signal(&mut self, _: &'static SignalMeta, value: Value, label: Option<&'static str>) {
            self.0.push(FieldValue {
                value: value.to_f64(),
                label,
            });
        }
    }
    out.clear();
    telemetry.visit(&mut Collect(out));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimals_follow_the_wire_resolution() {
        assert_eq!(decimals(1.0), 0);
        assert_eq!(decimals(0.5), 1);
        assert_eq!(decimals(0.1), 1);
        assert_eq!(decimals(0.01), 2);
        assert_eq!(decimals(0.004), 3);
        assert_eq!(decimals(0.0001), 4);
        assert_eq!(decimals(f64::NAN), 0);
    }

    #[test]
    fn every_field_has_a_value_in_schema_order() {
        let schema = Schema::TELEMETRY;
        let telemetry = Telemetry {
            soc: 64.5,
            vehicle_state: aer::can::VehicleState::Driving,
            ..Telemetry::zeroed()
        };
        let mut values = Vec::new();
        read(&telemetry, &mut values);
        assert_eq!(values.len(), schema.fields.len());
        let soc = schema.field("soc").unwrap();
        assert_eq!(soc.format(values[soc.index]), "64.5");
        let state = schema.field("vehicle_state").unwrap();
        assert_eq!(state.format(values[state.index]), "DRIVING");
    }

    #[test]
    fn groups_keep_schema_order_and_cover_every_field() {
        let groups = Schema::TELEMETRY.groups();
        assert_eq!(groups.first().map(|g| g.0), Some("pedals"));
        let mut all: Vec<usize> = groups.iter().flat_map(|g| g.1.clone()).collect();
        all.sort_unstable();
        assert_eq!(all, (0..Schema::TELEMETRY.fields.len()).collect::<Vec<_>>());
        assert_eq!(heading("inverter_faults"), "Inverter faults");
    }

    #[test]
    fn fault_flags_are_alarms_and_other_fields_are_not() {
        let schema = Schema::TELEMETRY;
        assert!(schema.field("fault_apps").unwrap().is_alarm());
        assert!(schema.field("motor_stall_fault").unwrap().is_alarm());
        assert!(!schema.field("ready_to_drive").unwrap().is_alarm());
        assert!(!schema.field("motor_temp").unwrap().is_alarm());
    }
}
