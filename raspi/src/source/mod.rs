//! Where frames come from: a recorded candump log ([`replay`]) or live SocketCAN
//! ([`socketcan`]). A source knows nothing downstream: it
//! names its buses and sends what it reads, in batches, to a [`Sender`], until the channel
//! closes or its cancellation token fires.

#[cfg(target_os = "linux")]
mod failures;
pub mod replay;
#[cfg(target_os = "linux")]
pub mod socketcan;

use aer_host::formats::candump::LoggedFrame;
use std::collections::HashMap;
use std::sync::Arc;
use tokio::sync::mpsc;

/// What a source hands on.
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    /// From now on, frames with bus `index` come from the interface `name`.
    Bus { index: u8, name: Arc<str> },
    /// A frame as received.
    Frame(LoggedFrame),
    /// A telemetry packet the kernel's ISO-TP socket reassembled.
    Packet {
        ts_us: u64,
        bus: u8,
        packet: Vec<u8>,
    },
    /// A looping replay starts its log again (pass `pass`, from 2): not a fault of the car.
    Restart { pass: u64 },
}

/// Inputs in arrival order, handed over together: a hand-off per frame would cost more than
/// decoding it.
pub type Batch = Vec<Input>;

/// Inputs a batch holds before it is sent.
pub(crate) const BATCH: usize = 256;
/// Batches that may wait for ingest before a source waits in turn.
const QUEUED_BATCHES: usize = 16;

/// The sending end of the sources' channel.
pub type Sender = mpsc::Sender<Batch>;
/// The receiving end, read by ingest.
pub type Receiver = mpsc::Receiver<Batch>;

/// A channel from the sources to ingest, bounded in batches.
pub fn channel() -> (Sender, Receiver) {
    mpsc::channel(QUEUED_BATCHES)
}

/// A batch being filled. Sent when full, and by [`Self::flush`] before the source waits for
/// more input, so nothing sits in a half-full batch while the bus is quiet.
pub struct Batcher {
    out: Sender,
    batch: Batch,
}

impl Batcher {
    /// A batcher sending to `out`.
    pub fn new(out: Sender) -> Self {
        Self {
            out,
            batch: Vec::with_capacity(BATCH),
        }
    }

    /// Adds `input`; sends the batch once full. False once nothing downstream listens.
    pub async fn push(&mut self, input: Input) -> bool {
        self.batch.push(input);
        if self.batch.len() >= BATCH {
            return self.flush().await;
        }
        true
    }

    /// Sends what is collected. False once nothing downstream listens.
    pub async fn flush(&mut self) -> bool {
        if self.batch.is_empty() {
            return !self.out.is_closed();
        }
        let batch = std::mem::replace(&mut self.batch, Vec::with_capacity(BATCH));
        self.out.send(batch).await.is_ok()
    }
}

/// Bus numbers for interface names, in the order they are first seen.
#[derive(Debug, Default)]
pub struct BusNames {
    indices: HashMap<String, u8>,
}

impl BusNames {
    /// The number of `name`, and its announcement if it is new.
    pub fn index(&mut self, name: &str) -> (u8, Option<Input>) {
        if let Some(index) = self.indices.get(name) {
            return (*index, None);
        }
        let index = u8::try_from(self.indices.len()).unwrap_or(u8::MAX);
        self.indices.insert(name.to_owned(), index);
        (
            index,
            Some(Input::Bus {
                index,
                name: name.into(),
            }),
        )
    }
}

/// Where ISO-TP flow control goes: the bus's writer, for buses a source can send on.
#[derive(Debug, Clone, Default)]
pub struct Replies {
    buses: HashMap<u8, mpsc::Sender<aer_isotp::Frame>>,
}

impl Replies {
    /// Flow control for bus `index` goes to `writer`.
    pub fn insert(&mut self, index: u8, writer: mpsc::Sender<aer_isotp::Frame>) {
        self.buses.insert(index, writer);
    }

    /// Hands `frame` to bus `index`'s writer. If its queue is full the CCM's sender times out
    /// (N_Bs) and its next packet starts afresh; replays have no writer.
    pub fn send(&self, index: u8, frame: aer_isotp::Frame) {
        if let Some(writer) = self.buses.get(&index) {
            let _ = writer.try_send(frame);
        }
    }
}
