//! The black-box raw log: every frame from every bus, appended before anything decodes it, in
//! segment files of checksummed blocks (`aer_host::formats::raw_format`). Ingest encodes frames into
//! blocks ([`RawTap`]); a writer thread appends them, rotates segments, syncs them to disk
//! every second and keeps the folder within its budget ([`writer`]). Neither ever waits on the
//! disk: a block the writer has no room for is dropped and its frames counted.
//!
//! `aer-raspi replay <segment>` reads a segment back; `aer-raspi raw-export <segment>` prints
//! it as `candump -l` text (`crate::export::raw_log`).

pub mod segments;
pub mod writer;

use aer_host::formats::candump::LoggedFrame;
use aer_host::formats::raw_format::BlockEncoder;
use aer_host::reports::counters::{Counters, worth_logging};
use std::sync::Arc;
use std::sync::mpsc::{SyncSender, TrySendError};
use tracing::warn;

/// A block is handed to the writer once it holds this many bytes (or at the next flush).
const BLOCK_BYTES: usize = 32 * 1024;

/// A block on its way to the writer, not yet compressed: the writer joins blocks and
/// compresses them together.
pub struct Block {
    pub encoder: BlockEncoder,
    pub frames: u64,
}

/// Ingest's end of the raw log: frames go into the current block; full blocks (and every
/// block at a flush) go to the writer thread without waiting.
pub struct RawTap {
    blocks: SyncSender<Block>,
    current: Option<BlockEncoder>,
    buses: Vec<Arc<str>>,
    counters: Arc<Counters>,
    /// Blocks dropped so far (for thinning the log lines).
    drops: u64,
}

impl RawTap {
    /// A tap sending blocks to `blocks`, counting into `counters`.
    pub fn new(blocks: SyncSender<Block>, counters: Arc<Counters>) -> Self {
        Self {
            blocks,
            current: None,
            buses: Vec::new(),
            counters,
            drops: 0,
        }
    }

    /// Bus `index` is the interface `name` from now on.
    pub(crate) fn name_bus(&mut self, index: u8, name: &Arc<str>) {
        let index = usize::from(index);
        if self.buses.len() <= index {
            self.buses.resize(index + 1, Arc::from(""));
        }
        if let Some(slot) = self.buses.get_mut(index)
            && slot != name
        {
            *slot = name.clone();
            // Later frames must not be read with the old name.
            self.flush();
        }
    }

    /// Appends `frame` (before it is decoded).
    pub fn frame(&mut self, frame: &LoggedFrame) {
        let block = self
            .current
            .get_or_insert_with(|| BlockEncoder::new(frame.ts_us, &self.buses));
        block.push(frame);
        if block.len() >= BLOCK_BYTES {
            self.flush();
        }
    }

    /// Hands the current block to the writer.
    pub fn flush(&mut self) {
        let Some(block) = self.current.take() else {
            return;
        };
        let frames = block.frames();
        if frames == 0 {
            return;
        }
        let block = Block {
            encoder: block,
            frames,
        };
        match self.blocks.try_send(block) {
            Ok(()) => {}
            Err(TrySendError::Full(block) | TrySendError::Disconnected(block)) => {
                let count = self
                    .counters
                    .raw_dropped
                    .fetch_add(block.frames, std::sync::atomic::Ordering::Relaxed)
                    + block.frames;
                self.drops += 1;
                if worth_logging(self.drops) {
                    warn!(
                        frames = count,
                        "raw log writer behind or stopped: frames not logged"
                    );
                }
            }
        }
    }
}

impl Drop for RawTap {
    fn drop(&mut self) {
        self.flush();
    }
}
