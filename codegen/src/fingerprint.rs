//! A stable fingerprint of the wire layout, computed from the model (not from file bytes), so
//! reformatting the schema or reordering its sections does not change it, while any change a
//! receiver would mis-decode does.

use crate::model::{ByteOrder, Database, Encoding, PhysType};

/// FNV-1a, 32 bits: small enough for a CAN signal, stable across platforms and Rust versions.
pub(crate) struct Fnv1a(u32);

impl Fnv1a {
    pub(crate) fn new() -> Self {
        Self(0x811C_9DC5)
    }

    pub(crate) fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u32::from(b);
            self.0 = self.0.wrapping_mul(0x0100_0193);
        }
    }

    /// Writes a field followed by a separator, so adjacent fields cannot run together.
    pub(crate) fn field(&mut self, text: &str) {
        self.write(text.as_bytes());
        self.write(&[0x1F]);
    }

    pub(crate) fn finish(&self) -> u32 {
        self.0
    }
}

impl Default for Fnv1a {
    fn default() -> Self {
        Self::new()
    }
}

/// Fingerprint of a CAN database's wire layout.
pub fn database(db: &Database) -> u32 {
    let mut h = Fnv1a::new();
    write_database(&mut h, db);
    h.finish()
}

/// Feeds a database's wire layout into `h` (shared with the telemetry fingerprint).
pub(crate) fn write_database(h: &mut Fnv1a, db: &Database) {
    let mut messages: Vec<_> = db.messages.iter().collect();
    messages.sort_by_key(|m| (m.extended, m.id));
    for m in messages {
        h.field(&format!("msg {} {} {} {}", m.id, m.extended, m.len, m.name));
        for s in &m.signals {
            let enc = match s.encoding {
                Encoding::Unsigned => "u",
                Encoding::Signed => "s",
                Encoding::Float32 => "f32",
                Encoding::Float64 => "f64",
            };
            let order = if s.byte_order == ByteOrder::LittleEndian {
                "le"
            } else {
                "be"
            };
            let mux = s
                .mux
                .as_ref()
                .map(|c| {
                    format!(
                        "{}:{:?}",
                        m.signals.get(c.selector).map_or("", |x| x.name.as_str()),
                        c.ranges
                    )
                })
                .unwrap_or_default();
            h.field(&format!(
                "sig {} {} {} {order} {enc} {:016x} {:016x} {mux}",
                s.name,
                s.start_bit,
                s.len,
                s.factor.to_bits(),
                s.offset.to_bits()
            ));
            if let PhysType::Enum(i) = s.phys {
                if let Some(e) = db.enums.get(i) {
                    for v in &e.variants {
                        h.field(&format!("val {} {}", v.value, v.label));
                    }
                }
            }
        }
    }
}

/// Fingerprint of the telemetry packet: its layout plus the CAN database it references, so a
/// firmware built from a different schema is detected by the Pi.
pub fn telemetry(db: &Database, t: &crate::model::Telemetry) -> u32 {
    let mut h = Fnv1a::new();
    write_database(&mut h, db);
    h.field(&format!(
        "telemetry {} {} {} {}",
        t.type_name, t.tx_id, t.flow_control_id, t.len
    ));
    for f in &t.fields {
        h.field(&format!(
            "field {} {:?} {:?} {:016x} {:016x} {:?}",
            f.name,
            f.wire,
            f.placement,
            f.scale.to_bits(),
            f.offset.to_bits(),
            f.phys
        ));
    }
    h.finish()
}

/// Fingerprint of the calibration's layout: what a saved page or a calibration tool's
/// description must agree on (names, types, offsets, counts, limits, change conditions, axes),
/// the internals' block (names, order, ranges) and the XCP slave's settings (ids, bit rate,
/// port, DAQ resources, events). Defaults and texts are left out: changing them changes no
/// page's meaning.
pub fn calibration(c: &crate::model::Calibration) -> u32 {
    let mut h = Fnv1a::new();
    h.field(&format!("calibration {} {}", c.name, c.page_len));
    for p in &c.parameters {
        h.field(&format!(
            "param {} {} {} {} {:016x} {:016x} {} {:?}",
            p.name,
            p.element.rust(),
            p.offset,
            p.defaults.len(),
            p.min.to_bits(),
            p.max.to_bits(),
            p.increasing,
            p.change
        ));
        if let Some(axis) = &p.axis {
            h.field(&format!("axis {} {}", axis.parameter, axis.input));
        }
    }
    for i in &c.internals {
        h.field(&format!(
            "internal {} {:016x} {:016x}",
            i.name,
            i.min.to_bits(),
            i.max.to_bits()
        ));
    }
    let x = &c.xcp;
    h.field(&format!(
        "xcp {} {} {} {} {} {} {} {} {}",
        x.can_id_master,
        x.can_id_slave,
        x.bit_rate,
        x.response_cycle_ms,
        x.tcp_port,
        x.max_daq,
        x.odt_entries,
        x.max_odt_entry_size,
        x.bus.as_deref().unwrap_or("")
    ));
    h.field(&format!(
        "session {} {} {}",
        x.idle_timeout_ms, x.unlock_delay_ms, x.unlock_delay_max_ms
    ));
    for e in &x.events {
        h.field(&format!("event {} {}", e.name, e.period_us));
    }
    h.finish()
}
