//! One place where a frame goes through decoding to MQTT and the local store.

use crate::candump::LoggedFrame;
use crate::ingest::{Ingest, Record};
use crate::metrics::Counters;
use crate::publish::Publisher;
use crate::store::{self, RowSender};
use aer_isotp::Frame;
use std::sync::Arc;

/// Decoder plus outputs.
pub struct Pipeline {
    ingest: Ingest,
    publisher: Option<Publisher>,
    store: Option<RowSender>,
    car_id: Arc<str>,
    bus_names: Vec<Arc<str>>,
}

impl Pipeline {
    /// A pipeline publishing with `publisher` and storing through `store` (either optional).
    pub fn new(
        counters: Arc<Counters>,
        car_id: String,
        bus_names: Vec<Arc<str>>,
        publisher: Option<Publisher>,
        store: Option<RowSender>,
    ) -> Self {
        Self {
            ingest: Ingest::new(counters),
            publisher,
            store,
            car_id: car_id.into(),
            bus_names,
        }
    }

    /// Leaves ISO-TP reassembly to the kernel (`run` with `isotp = "kernel"`).
    pub fn with_kernel_isotp(mut self) -> Self {
        self.ingest.use_kernel_isotp();
        self
    }

    /// Takes one telemetry packet the kernel reassembled through decoding and the outputs.
    pub fn feed_packet(&mut self, ts_us: u64, bus: u8, packet: &[u8]) {
        let publisher = self.publisher.as_ref();
        let store = self.store.as_ref();
        let (car_id, bus_names) = (&self.car_id, &self.bus_names);
        self.ingest.on_packet(ts_us, bus, packet, |record| {
            output(&record, publisher, store, car_id, bus_names);
        });
    }

    /// Bus names by index (the order interfaces were first seen).
    pub fn bus_names_mut(&mut self) -> &mut Vec<Arc<str>> {
        &mut self.bus_names
    }

    /// Hands what was published to the broker: call before waiting for more input (a record
    /// may otherwise wait for the next one).
    pub fn flush(&self) {
        if let Some(publisher) = &self.publisher {
            publisher.flush();
        }
    }

    /// Takes one frame through the whole pipeline; `reply` gets flow-control frames. Call
    /// [`Self::flush`] before waiting for the next frame.
    pub fn feed(&mut self, frame: &LoggedFrame, reply: impl FnMut(u8, Frame)) {
        let publisher = self.publisher.as_ref();
        let store = self.store.as_ref();
        let car_id = &self.car_id;
        let bus_names = &self.bus_names;
        self.ingest.on_frame(
            frame,
            |record: Record| output(&record, publisher, store, car_id, bus_names),
            reply,
        );
    }
}

impl Drop for Pipeline {
    fn drop(&mut self) {
        self.flush();
    }
}

/// Publishes and stores one record.
fn output(
    record: &Record,
    publisher: Option<&Publisher>,
    store: Option<&RowSender>,
    car_id: &Arc<str>,
    bus_names: &[Arc<str>],
) {
    if let Some(publisher) = publisher {
        publisher.publish(record);
    }
    if let Some(store) = store {
        let row = store::row(record, car_id, bus_names);
        // Blocks while the writer is behind: the store never drops.
        store.send(row);
    }
}
