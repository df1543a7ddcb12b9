//! The ingest stage: batches from the sources in, decoded records out to every sink, on one
//! task. Every frame goes to the raw log first, before anything decodes it. Decoding itself
//! is `aer_host::decode`, shared with the dashboard; this stage keeps the bus names the
//! sources announce, sends ISO-TP flow control back to the source's bus, and flushes the raw
//! log and the sinks whenever it is about to wait.

use crate::pit::PitTap;
use crate::rawlog::RawTap;
use crate::sink::Sink;
use crate::source::replay::{ReplayOptions, ReplayStats, replay};
use crate::source::{self, Input, Receiver, Replies};
use aer_host::decode::{Ingest, Record};
use aer_host::reports::counters::Counters;
use std::sync::Arc;
use tokio_util::sync::CancellationToken;

/// Decoder, bus names and sinks.
pub struct Stage {
    ingest: Ingest,
    counters: Arc<Counters>,
    buses: Vec<Arc<str>>,
    sinks: Vec<Box<dyn Sink>>,
    replies: Replies,
    raw: Option<RawTap>,
    pit: Option<PitTap>,
}

impl Stage {
    /// A stage counting into `counters` and handing records to `sinks`; flow control goes
    /// to `replies`.
    pub fn new(counters: Arc<Counters>, sinks: Vec<Box<dyn Sink>>, replies: Replies) -> Self {
        Self {
            ingest: Ingest::new(counters.clone()),
            counters,
            buses: Vec::new(),
            sinks,
            replies,
            raw: None,
            pit: None,
        }
    }

    /// Copies every input to the pit stream through `tap`.
    pub fn with_pit_stream(mut self, tap: PitTap) -> Self {
        self.pit = Some(tap);
        self
    }

    /// Appends every frame to the raw log through `tap` before decoding it.
    pub fn with_raw_log(mut self, tap: RawTap) -> Self {
        self.raw = Some(tap);
        self
    }

    /// Leaves ISO-TP reassembly to the kernel (whole packets arrive as [`Input::Packet`]).
    pub fn with_kernel_isotp(mut self) -> Self {
        self.ingest.use_kernel_isotp();
        self
    }

    /// Takes one input through decoding to the sinks.
    pub fn take(&mut self, input: Input) {
        if let Some(pit) = &mut self.pit {
            pit.take(&input);
        }
        let Self {
            ingest,
            counters,
            buses,
            sinks,
            replies,
            raw,
            pit: _,
        } = self;
        match input {
            Input::Bus { index, name } => {
                if let Some(raw) = raw {
                    raw.name_bus(index, &name);
                }
                ingest.name_bus(index, &name);
                let index = usize::from(index);
                if buses.len() <= index {
                    buses.resize(index + 1, Arc::from(""));
                }
                if let Some(slot) = buses.get_mut(index) {
                    *slot = name;
                }
            }
            Input::Frame(frame) => {
                if let Some(raw) = raw {
                    raw.frame(&frame);
                }
                ingest.on_frame(
                    &frame,
                    |record| hand_on(sinks, buses, &record),
                    |bus, fc| replies.send(bus, fc),
                )
            }
            Input::Packet { ts_us, bus, packet } => {
                ingest.on_packet(ts_us, bus, &packet, |record| {
                    hand_on(sinks, buses, &record);
                });
            }
            Input::Restart { pass } => {
                tracing::info!(
                    pass,
                    "the looped log starts again: its counters and telemetry sequence start over (the loop point, not a fault)"
                );
                ingest.restart();
                counters.last_replay_pass_us.store(
                    aer_host::clock::now_us(),
                    std::sync::atomic::Ordering::Relaxed,
                );
                Counters::bump(&counters.replay_passes);
            }
        }
    }

    /// Hands whatever the sinks hold back on: call before waiting for input.
    pub fn flush(&mut self) {
        if let Some(raw) = &mut self.raw {
            raw.flush();
        }
        if let Some(pit) = &mut self.pit {
            pit.flush();
        }
        for sink in &mut self.sinks {
            sink.flush();
        }
    }

    /// Runs until every source has hung up: each batch through the sinks, then a flush
    /// before waiting for the next.
    pub async fn run(mut self, mut batches: Receiver) -> Self {
        loop {
            let batch = match batches.try_recv() {
                Ok(batch) => batch,
                Err(_) => {
                    self.flush();
                    match batches.recv().await {
                        Some(batch) => batch,
                        None => break,
                    }
                }
            };
            for input in batch {
                self.take(input);
            }
        }
        self.flush();
        self
    }

    /// Replays `log` flat out with its recorded timestamps through this stage, the replay
    /// source and the stage running side by side as in the service (tests, benchmarks).
    pub async fn replay_all(self, log: &[u8], counters: &Counters) -> (Self, ReplayStats) {
        let (inputs, batches) = source::channel();
        let cancel = CancellationToken::new();
        let (stats, stage) = tokio::join!(
            replay(log, inputs, counters, ReplayOptions::FAST, &cancel),
            self.run(batches)
        );
        (stage, stats)
    }
}

fn hand_on(sinks: &mut [Box<dyn Sink>], buses: &[Arc<str>], record: &Record) {
    for sink in sinks {
        sink.accept(record, buses);
    }
}
