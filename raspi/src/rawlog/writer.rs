//! The raw log's writer thread: joins the blocks ingest hands it for up to a second (or
//! 256 KiB), compresses them as one block and appends it to the current segment, starts a new
//! segment by size or age (and after a failure), syncs to disk every second, and keeps the
//! folder within its budget. Joining is what makes compression pay: ingest hands over a block
//! per batch it reads, often a few hundred bytes, and zstd needs kilobytes of context. A write that fails (disk full, read-only, I/O error) drops that block, counts
//! its frames, reports the error, and the next segment is tried after a backoff.

use super::Block;
use super::segments::{self, Budget};
use crate::health::Health;
use aer_host::clock::now_us;
use aer_host::formats::raw_format::{Joiner, MAGIC};
use aer_host::reports::counters::{Counters, worth_logging};
use std::fs::File;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tracing::{error, info};

/// Blocks (up to 32 KiB each) that may wait for the writer.
const QUEUE_BLOCKS: usize = 256;
/// Joined blocks are compressed and written once they hold this much (or are a second old).
const JOIN_BYTES: usize = 256 * 1024;
/// Backoff after a failed write: 1 s doubling to 30 s.
const RETRY_START: Duration = Duration::from_secs(1);
const RETRY_MAX: Duration = Duration::from_secs(30);
/// How often the budget is checked.
const PRUNE_EVERY: Duration = Duration::from_secs(60);

/// Where and how the raw log is written.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub dir: PathBuf,
    /// A new segment starts once the current one holds this much.
    pub segment_bytes: u64,
    /// ... or is this old.
    pub segment_age: Duration,
    /// Frames are written within this time of arriving and reach the disk within this time of
    /// being written: a power cut loses at most twice this.
    pub sync_every: Duration,
    pub budget: Budget,
}

/// The writer thread.
pub struct RawWriter {
    thread: Option<JoinHandle<()>>,
}

impl RawWriter {
    /// Starts the writer; returns it and where ingest sends blocks. Fails if the folder cannot
    /// be created.
    pub fn start(
        settings: Settings,
        counters: Arc<Counters>,
        health: Arc<Health>,
    ) -> std::io::Result<(Self, SyncSender<Block>)> {
        std::fs::create_dir_all(&settings.dir)?;
        let (blocks_tx, blocks) = sync_channel(QUEUE_BLOCKS);
        let state = Writer {
            settings,
            counters,
            health,
            segment: None,
            pending: None,
            retry_at: None,
            backoff: RETRY_START,
            pruned_at: None,
            started_us: now_us(),
        };
        let thread = std::thread::Builder::new()
            .name("raw-log".into())
            .spawn(move || state.run(&blocks))?;
        Ok((
            Self {
                thread: Some(thread),
            },
            blocks_tx,
        ))
    }

    /// Waits until every sender is gone and what they sent is on disk.
    pub fn finish(mut self) {
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

struct Segment {
    path: PathBuf,
    file: File,
    started: Instant,
    bytes: u64,
    unsynced: bool,
    synced_at: Instant,
}

/// Blocks joined, waiting to be compressed and written.
struct Pending {
    joined: Joiner,
    since: Instant,
}

struct Writer {
    settings: Settings,
    pending: Option<Pending>,
    /// When this run began: its segments are never removed for the free-space floor.
    started_us: u64,
    counters: Arc<Counters>,
    health: Arc<Health>,
    segment: Option<Segment>,
    /// After a failure, no segment is opened before this.
    retry_at: Option<Instant>,
    backoff: Duration,
    pruned_at: Option<Instant>,
}

impl Writer {
    fn run(mut self, blocks: &Receiver<Block>) {
        loop {
            match blocks.recv_timeout(self.settings.sync_every) {
                Ok(block) => self.take(block),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            self.maintain();
        }
        self.write_pending();
        self.close();
    }

    /// Joins `block` to what waits; writes it all once there is enough.
    fn take(&mut self, block: Block) {
        let pending = self.pending.get_or_insert_with(|| Pending {
            joined: Joiner::default(),
            since: Instant::now(),
        });
        pending.joined.push(&block.encoder);
        if pending.joined.len() >= JOIN_BYTES {
            self.write_pending();
        }
    }

    /// Compresses what waits into one block and appends it.
    fn write_pending(&mut self) {
        let Some(pending) = self.pending.take() else {
            return;
        };
        let frames = pending.joined.frames();
        let block = pending.joined.finish();
        let result = match self.segment_for(block.len() as u64) {
            Some(segment) => segment.file.write_all(&block).map(|()| {
                segment.bytes += block.len() as u64;
                segment.unsynced = true;
            }),
            None => {
                // Still backing off after a failure.
                self.dropped(frames);
                return;
            }
        };
        match result {
            Ok(()) => {
                self.counters
                    .raw_frames
                    .fetch_add(frames, Ordering::Relaxed);
                if self.health.raw_log.recovered() {
                    info!("raw log writes again");
                }
                self.backoff = RETRY_START;
            }
            Err(error) => {
                self.dropped(frames);
                self.failed(&error);
            }
        }
    }

    /// The segment to append `len` bytes to: the current one, or a new one when it is full or
    /// old. `None` while backing off after a failure.
    fn segment_for(&mut self, len: u64) -> Option<&mut Segment> {
        let rotate = self.segment.as_ref().is_some_and(|segment| {
            segment.bytes + len > self.settings.segment_bytes
                || segment.started.elapsed() >= self.settings.segment_age
        });
        if rotate {
            self.close();
        }
        if self.segment.is_none() {
            if self.retry_at.is_some_and(|at| Instant::now() < at) {
                return None;
            }
            match self.open() {
                Ok(segment) => self.segment = Some(segment),
                Err(error) => {
                    self.failed(&error);
                    return None;
                }
            }
        }
        self.segment.as_mut()
    }

    fn open(&self) -> std::io::Result<Segment> {
        let path = self.settings.dir.join(segments::file_name(now_us()));
        let mut file = std::fs::OpenOptions::new()
            .create_new(true)
            .append(true)
            .open(&path)?;
        file.write_all(&MAGIC)?;
        Ok(Segment {
            path,
            file,
            started: Instant::now(),
            bytes: MAGIC.len() as u64,
            unsynced: true,
            synced_at: Instant::now(),
        })
    }

    /// Writes, syncs and prunes what is due.
    fn maintain(&mut self) {
        let sync_every = self.settings.sync_every;
        if self
            .pending
            .as_ref()
            .is_some_and(|pending| pending.since.elapsed() >= sync_every)
        {
            self.write_pending();
        }
        let sync = self
            .segment
            .as_mut()
            .filter(|segment| segment.unsynced && segment.synced_at.elapsed() >= sync_every)
            .map(|segment| {
                segment.synced_at = Instant::now();
                segment.unsynced = false;
                segment.file.sync_data()
            });
        if let Some(Err(error)) = sync {
            self.failed(&error);
        }
        if self.pruned_at.is_none_or(|at| at.elapsed() >= PRUNE_EVERY) {
            self.pruned_at = Some(Instant::now());
            self.prune();
        }
    }

    fn prune(&self) {
        let current = self.segment.as_ref().map(|segment| segment.path.as_path());
        let removed = segments::prune(
            &self.settings.dir,
            &self.settings.budget,
            current,
            Some(self.started_us),
            now_us(),
            crate::disk::free_bytes,
        );
        if removed > 0 {
            self.counters
                .pruned_segments
                .fetch_add(removed, Ordering::Relaxed);
            info!(segments = removed, "raw log pruned to its budget");
        }
    }

    fn close(&mut self) {
        if let Some(segment) = self.segment.take()
            && segment.unsynced
            && let Err(error) = segment.file.sync_data()
        {
            self.failed(&error);
        }
    }

    fn dropped(&self, frames: u64) {
        self.counters
            .raw_dropped
            .fetch_add(frames, Ordering::Relaxed);
    }

    /// A write, sync or open failed: report it, give up the segment, back off.
    fn failed(&mut self, error: &std::io::Error) {
        let count = Counters::bump(&self.counters.raw_errors);
        self.health.raw_log.failed(&error.to_string());
        if worth_logging(count) {
            error!(%error, dir = %self.settings.dir.display(), retry_s = self.backoff.as_secs(), count,
                "raw log write failed; its frames are dropped (and counted) until it works again");
        }
        self.segment = None;
        self.retry_at = Some(Instant::now() + self.backoff);
        self.backoff = (self.backoff * 2).min(RETRY_MAX);
    }
}
