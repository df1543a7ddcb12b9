//! The pit stream's producer (`aer_host::formats::pit_stream`): ingest's input (bus names, frames as
//! received, packets the kernel reassembled) is copied to a task that batches it over a short
//! window and publishes each batch on `aer-pit/<car>/stream` ([`aer_host::formats::pit_stream::topic`]).
//! Ingest never waits on it: a full queue drops the input from the stream only (counted in
//! `pit_dropped`; the raw log and the store keep it). Each published batch is also kept for
//! pits that missed it ([`history`]).

pub mod history;

use crate::sink::mqtt::Publisher;
use crate::source::Input;
use aer_host::formats::pit_stream::{BatchEncoder, MAX_BATCH_PAYLOAD};
use aer_host::reports::counters::{Counters, worth_logging};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::mpsc::{Receiver, Sender, error::TrySendError};
use tokio_util::sync::CancellationToken;
use tracing::warn;

/// Hand-overs the task may be behind by (each up to [`HAND_OVER`] inputs: seconds of the
/// car's traffic, a replay's burst).
const QUEUE: usize = 256;
/// Inputs handed over at once: one channel operation per input would cost more than the
/// encoding.
const HAND_OVER: usize = 512;

/// Ingest's end: copies every input to the stream's task without waiting.
pub struct PitTap {
    inputs: Sender<Vec<Input>>,
    pending: Vec<Input>,
    counters: Arc<Counters>,
    /// The kernel reassembles telemetry: its packets are on the stream, so the ISO-TP frames
    /// they came in are left out (the pit would otherwise get every packet twice).
    kernel_isotp: bool,
}

impl PitTap {
    /// A tap and the receiving end for [`run`].
    pub fn new(counters: Arc<Counters>, kernel_isotp: bool) -> (Self, Receiver<Vec<Input>>) {
        let (inputs, receiver) = tokio::sync::mpsc::channel(QUEUE);
        let tap = Self {
            inputs,
            pending: Vec::with_capacity(HAND_OVER),
            counters,
            kernel_isotp,
        };
        (tap, receiver)
    }

    /// Copies `input` to the stream.
    pub fn take(&mut self, input: &Input) {
        if self.kernel_isotp
            && let Input::Frame(frame) = input
            && is_telemetry_transport(frame.id)
        {
            return;
        }
        self.pending.push(input.clone());
        if self.pending.len() >= HAND_OVER {
            self.flush();
        }
    }

    /// Hands what it holds to the task: ingest calls it before it waits for input.
    pub fn flush(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        let inputs = std::mem::replace(&mut self.pending, Vec::with_capacity(HAND_OVER));
        match self.inputs.try_send(inputs) {
            Ok(()) => {}
            Err(TrySendError::Full(inputs)) => {
                let count = self
                    .counters
                    .pit_dropped
                    .fetch_add(inputs.len() as u64, std::sync::atomic::Ordering::Relaxed)
                    + inputs.len() as u64;
                if worth_logging(count) {
                    warn!(count, "pit stream behind: input left out of the stream");
                }
            }
            // The task has ended (the service is stopping): nothing to stream to.
            Err(TrySendError::Closed(_)) => {}
        }
    }
}

impl Drop for PitTap {
    fn drop(&mut self) {
        self.flush();
    }
}

/// A frame of the telemetry's ISO-TP transfer (data or flow control).
fn is_telemetry_transport(id: embedded_can::Id) -> bool {
    use aer::telemetry::Telemetry;
    matches!(id, embedded_can::Id::Standard(id)
        if id.as_raw() == Telemetry::TX_ID || id.as_raw() == Telemetry::FLOW_CONTROL_ID)
}

/// The batch being filled and the buses' names.
struct Batcher {
    publisher: Publisher,
    topic: String,
    counters: Arc<Counters>,
    buses: Vec<Arc<str>>,
    current: Option<BatchEncoder>,
    number: u32,
    ring: Arc<Mutex<history::Ring>>,
}

impl Batcher {
    fn batch(&mut self, ts_us: u64) -> &mut BatchEncoder {
        let (number, buses) = (self.number, &self.buses);
        self.current
            .get_or_insert_with(|| BatchEncoder::new(number, ts_us, buses))
    }

    fn take(&mut self, input: Input) {
        match input {
            Input::Bus { index, name } => {
                // Later inputs must not be read with the old name: the batch so far goes.
                self.publish();
                let index = usize::from(index);
                if self.buses.len() <= index {
                    self.buses.resize(index + 1, Arc::from(""));
                }
                if let Some(slot) = self.buses.get_mut(index) {
                    *slot = name;
                }
            }
            Input::Frame(frame) => self.batch(frame.ts_us).frame(&frame),
            Input::Packet { ts_us, bus, packet } => self.batch(ts_us).packet(ts_us, bus, &packet),
            // The pit's decoder sees the frames themselves; a loop point carries none.
            Input::Restart { .. } => {}
        }
        if self
            .current
            .as_ref()
            .is_some_and(|batch| batch.payload_len() >= MAX_BATCH_PAYLOAD)
        {
            self.publish();
        }
    }

    fn publish(&mut self) {
        let Some(batch) = self.current.take() else {
            return;
        };
        if batch.items() == 0 {
            return;
        }
        let (number, last_us) = (batch.number(), batch.last_us());
        let message = batch.finish();
        if let Ok(mut ring) = self.ring.lock() {
            ring.push(number, last_us, Arc::from(message.as_slice()));
        }
        self.publisher.publish_bytes(&self.topic, message);
        Counters::bump(&self.counters.pit_batches);
        self.number = self.number.wrapping_add(1);
    }
}

/// Batches `inputs` every `window` and publishes them on `topic` (keeping each in `ring`)
/// until the tap is dropped (then the last batch goes out) or `cancel` fires.
pub async fn run(
    publisher: Publisher,
    topic: String,
    counters: Arc<Counters>,
    mut inputs: Receiver<Vec<Input>>,
    window: Duration,
    ring: Arc<Mutex<history::Ring>>,
    cancel: CancellationToken,
) {
    let mut batcher = Batcher {
        publisher,
        topic,
        counters,
        buses: Vec::new(),
        current: None,
        number: 0,
        ring,
    };
    let mut tick = tokio::time::interval(window);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            handed = inputs.recv() => match handed {
                Some(handed) => handed.into_iter().for_each(|input| batcher.take(input)),
                None => break,
            },
            _ = tick.tick() => batcher.publish(),
            () = cancel.cancelled() => {
                // What ingest handed over before stopping still goes out.
                while let Ok(handed) = inputs.try_recv() {
                    handed.into_iter().for_each(|input| batcher.take(input));
                }
                break;
            }
        }
    }
    batcher.publish();
}

#[cfg(test)]
mod tests {
    use super::*;
    use aer_host::formats::candump::LoggedFrame;
    use embedded_can::{Id, StandardId};

    fn frame(id: u16) -> Input {
        let id = Id::Standard(StandardId::new(id).expect("11 bits"));
        Input::Frame(LoggedFrame::new(1, 0, id, &[1, 2]).expect("a frame"))
    }

    fn handed(kernel_isotp: bool, inputs: &[Input]) -> Vec<Input> {
        let (mut tap, mut receiver) = PitTap::new(Arc::new(Counters::default()), kernel_isotp);
        for input in inputs {
            tap.take(input);
        }
        drop(tap);
        let mut out = Vec::new();
        while let Ok(handed) = receiver.try_recv() {
            out.extend(handed);
        }
        out
    }

    /// With kernel ISO-TP the stream carries the packets, so their ISO-TP frames (0x666 and
    /// the flow control 0x777) are left out; with user-space ISO-TP the frames are the data.
    #[test]
    fn telemetry_goes_once_as_packets_or_as_frames() {
        let packet = Input::Packet {
            ts_us: 2,
            bus: 0,
            packet: vec![0; 76],
        };
        let inputs = [frame(0x666), frame(0x777), frame(0x100), packet.clone()];
        assert_eq!(handed(true, &inputs), [frame(0x100), packet]);
        assert_eq!(handed(false, &inputs), inputs);
    }

    /// A task that is behind loses hand-overs, counted, and ingest does not wait.
    #[test]
    fn a_full_queue_counts_what_it_leaves_out() {
        let counters = Arc::new(Counters::default());
        let (mut tap, _receiver) = PitTap::new(counters.clone(), false);
        for _ in 0..(QUEUE + 1) * HAND_OVER {
            tap.take(&frame(0x100));
        }
        assert_eq!(
            counters
                .pit_dropped
                .load(std::sync::atomic::Ordering::Relaxed),
            HAND_OVER as u64
        );
    }
}
