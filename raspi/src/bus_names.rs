//! Bus numbers to interface names, as the sources announced them: what the MQTT topics and
//! the store's rows call a bus.

use std::sync::Arc;

/// The name of bus number `bus` (`bus<N>` for a number no source announced).
pub(crate) fn bus_name(buses: &[Arc<str>], bus: u8) -> Arc<str> {
    buses
        .get(usize::from(bus))
        .cloned()
        .unwrap_or_else(|| format!("bus{bus}").into())
}
