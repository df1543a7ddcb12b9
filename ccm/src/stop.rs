//! The frames that stop the inverter, kept ready for the panic handler.
//!
//! A panic can come from any task, in the middle of anything, with any lock held, so the
//! handler must not build frames (the code that builds them may be what panicked) nor take a
//! lock. The control task builds the stop frames every period ([`Control::stop_frames`]: no
//! torque, drive disabled, no current allowed, the IFL100's next rolling counter) and
//! publishes them here; the handler takes the newest complete copy and sends it on the
//! inverter bus before it resets.
//!
//! Two slots and an index: a publish writes the slot not in use, then flips the index, so a
//! panic that interrupts a publish still reads a whole copy. Only atomics: no unsafe, nothing
//! to tear.
//!
//! [`Control::stop_frames`]: crate::control::Control::stop_frames

use crate::inverter::{OutFrame, OutFrames};
use aer_flexcan::CanFrame;
use core::sync::atomic::{AtomicU8, AtomicU32, Ordering};
use embedded_can::{ExtendedId, Frame, Id, StandardId};

/// Words per frame: flags and length, identifier, two words of payload.
const FRAME_WORDS: usize = 4;
/// Frames per copy (what one command period sends at most).
const FRAMES: usize = 4;
const WORDS: usize = FRAME_WORDS * FRAMES;
const PRESENT: u32 = 1 << 31;
const EXTENDED: u32 = 1 << 30;

/// The newest stop frames.
#[derive(Debug)]
pub struct StopFrames {
    slots: [[AtomicU32; WORDS]; 2],
    current: AtomicU8,
}

/// The one the firmware's control task publishes to and its panic handler reads.
pub static STOP: StopFrames = StopFrames::new();

/// A copy holds the newest frames (for simulations that clone a running car).
impl Clone for StopFrames {
    fn clone(&self) -> Self {
        let copy = Self::new();
        copy.publish(&self.latest());
        copy
    }
}

impl Default for StopFrames {
    fn default() -> Self {
        Self::new()
    }
}

impl StopFrames {
    /// Nothing published yet: [`Self::latest`] is empty.
    pub const fn new() -> Self {
        Self {
            slots: [
                [const { AtomicU32::new(0) }; WORDS],
                [const { AtomicU32::new(0) }; WORDS],
            ],
            current: AtomicU8::new(0),
        }
    }

    /// Makes `frames` the newest copy.
    pub fn publish(&self, frames: &OutFrames) {
        let next = usize::from(self.current.load(Ordering::Relaxed) ^ 1) & 1;
        let Some(slot) = self.slots.get(next) else {
            return;
        };
        let mut frames = frames.iter();
        for words in slot.chunks_exact(FRAME_WORDS) {
            let encoded = frames.next().map_or([0; FRAME_WORDS], encode);
            for (word, value) in words.iter().zip(encoded) {
                word.store(value, Ordering::Relaxed);
            }
        }
        self.current.store(next as u8, Ordering::Release);
    }

    /// The newest complete copy.
    pub fn latest(&self) -> OutFrames {
        let current = usize::from(self.current.load(Ordering::Acquire)) & 1;
        let mut out = [None; FRAMES];
        if let Some(slot) = self.slots.get(current) {
            for (frame, words) in out.iter_mut().zip(slot.chunks_exact(FRAME_WORDS)) {
                let mut value = [0u32; FRAME_WORDS];
                for (value, word) in value.iter_mut().zip(words) {
                    *value = word.load(Ordering::Relaxed);
                }
                *frame = decode(value);
            }
        }
        OutFrames::new(out)
    }

    /// [`Self::latest`] as the CAN frames the panic handler queues, in order.
    pub fn latest_frames(&self) -> impl Iterator<Item = CanFrame> {
        let frames = self.latest();
        let mut out = [None; FRAMES];
        for (slot, frame) in out.iter_mut().zip(frames.iter()) {
            let id = if frame.extended {
                ExtendedId::new(frame.id).map(Id::Extended)
            } else {
                u16::try_from(frame.id)
                    .ok()
                    .and_then(StandardId::new)
                    .map(Id::Standard)
            };
            *slot = id.and_then(|id| CanFrame::new(id, frame.data()));
        }
        out.into_iter().flatten()
    }
}

fn encode(frame: &OutFrame) -> [u32; FRAME_WORDS] {
    let data = frame.data();
    let mut bytes = [0u8; 8];
    for (byte, value) in bytes.iter_mut().zip(data) {
        *byte = *value;
    }
    let len = data.len().min(8) as u32;
    let [a, b, c, d, e, f, g, h] = bytes;
    [
        PRESENT | if frame.extended { EXTENDED } else { 0 } | len,
        frame.id,
        u32::from_le_bytes([a, b, c, d]),
        u32::from_le_bytes([e, f, g, h]),
    ]
}

fn decode([flags, id, low, high]: [u32; FRAME_WORDS]) -> Option<OutFrame> {
    if flags & PRESENT == 0 {
        return None;
    }
    let [a, b, c, d] = low.to_le_bytes();
    let [e, f, g, h] = high.to_le_bytes();
    let len = (flags & 0xF).min(8) as usize;
    OutFrame::encoded(id, flags & EXTENDED != 0, |out| {
        *out = [a, b, c, d, e, f, g, h];
        Ok(len)
    })
    .ok()
}
