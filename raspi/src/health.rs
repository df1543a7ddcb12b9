//! What is failing right now, part by part, for the status topic and the log: each part
//! records its error when it fails and clears it when it works again.

use aer_host::reports::status::Problems;
use std::collections::BTreeMap;
use std::sync::Mutex;

/// One part's current error, if any.
#[derive(Debug, Default)]
pub struct PartHealth {
    error: Mutex<Option<String>>,
}

impl PartHealth {
    /// The part failed with `error`.
    pub fn failed(&self, error: &str) {
        if let Ok(mut slot) = self.error.lock() {
            *slot = Some(error.to_owned());
        }
    }

    /// The part works; true if it was failing until now.
    pub(crate) fn recovered(&self) -> bool {
        self.error
            .lock()
            .is_ok_and(|mut slot| slot.take().is_some())
    }

    /// The current error.
    pub fn error(&self) -> Option<String> {
        self.error.lock().ok().and_then(|slot| slot.clone())
    }
}

/// The CAN interfaces that cannot be opened or read now, each with its error.
#[derive(Debug, Default)]
pub struct BusHealth {
    errors: Mutex<BTreeMap<String, String>>,
}

impl BusHealth {
    /// `interface` failed with `error`.
    pub fn failed(&self, interface: &str, error: &str) {
        if let Ok(mut errors) = self.errors.lock() {
            errors.insert(interface.to_owned(), error.to_owned());
        }
    }

    /// `interface` works.
    pub(crate) fn recovered(&self, interface: &str) {
        if let Ok(mut errors) = self.errors.lock() {
            errors.remove(interface);
        }
    }

    /// `can0: No such device; can1: ...`, or `None` when every interface works.
    pub fn error(&self) -> Option<String> {
        let errors = self.errors.lock().ok()?;
        (!errors.is_empty()).then(|| {
            errors
                .iter()
                .map(|(interface, error)| format!("{interface}: {error}"))
                .collect::<Vec<_>>()
                .join("; ")
        })
    }
}

/// Every part's health.
#[derive(Debug, Default)]
pub struct Health {
    /// The local store's writes.
    pub store: PartHealth,
    /// A damaged store moved aside at start-up: where it went and why.
    pub store_recovered: PartHealth,
    /// The raw log's writes.
    pub raw_log: PartHealth,
    /// The store's file system under its free-space floor with nothing left to prune.
    pub disk: PartHealth,
    /// Forwarding to TDengine: an outage, cleared once it works again.
    pub forward: PartHealth,
    /// Rows TDengine refused (set aside in the store): stays until the service restarts.
    pub forward_refused: PartHealth,
    /// The service's own link to the broker.
    pub mqtt: PartHealth,
    /// The CAN interfaces `run` reads.
    pub can: BusHealth,
    /// The XCP gateway's start.
    pub xcp_gateway: PartHealth,
}

impl Health {
    /// The problems as the status reports them.
    pub fn problems(&self) -> Problems {
        Problems {
            store: self.store.error(),
            store_recovered: self.store_recovered.error(),
            raw_log: self.raw_log.error(),
            disk: self.disk.error(),
            forward: self.forward.error(),
            forward_refused: self.forward_refused.error(),
            mqtt: self.mqtt.error(),
            can: self.can.error(),
            // The status fills these from what the ingest counted and what the gate measures.
            firmware: None,
            mqtt_clients: None,
            xcp_gateway: self.xcp_gateway.error(),
            // The status fills it from the messages the ingest saw.
            never_arrived: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_failing_interface_shows_until_it_recovers() {
        let health = Health::default();
        assert_eq!(health.problems().can, None);
        health.can.failed("can1", "No such device");
        health.can.failed("can0", "Network is down");
        health.can.failed("can0", "No such device");
        assert_eq!(
            health.problems().can.as_deref(),
            Some("can0: No such device; can1: No such device")
        );
        health.can.recovered("can0");
        assert_eq!(
            health.problems().can.as_deref(),
            Some("can1: No such device")
        );
        health.can.recovered("can1");
        assert_eq!(health.problems().can, None);
    }
}
