//! The receiving end: reassembles a message and says when to send flow control.

use crate::Config;
use crate::frame::{FlowStatus, Frame, FrameError, Pci, flow_control, parse};

/// Why a frame did not lead to a message. After any of these the receiver is idle again and
/// the next first or single frame starts afresh.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RxError {
    /// Not a valid ISO-TP frame.
    Frame(FrameError),
    /// A consecutive frame arrived while no message was in progress.
    UnexpectedConsecutive,
    /// A consecutive frame with the wrong sequence number: one was lost or repeated.
    Sequence {
        /// The number that should have come.
        expected: u8,
        /// The number that came.
        got: u8,
    },
    /// No consecutive frame within N_Cr; the partial message is dropped.
    Timeout,
    /// A message longer than this receiver holds. For a first frame, `reply` is the
    /// OVERFLOW flow control to send back.
    TooLong {
        /// Announced length.
        length: u16,
        /// The flow control to send back, if any.
        reply: Option<Frame>,
    },
}

/// What a received frame produced.
#[derive(Debug, PartialEq, Eq)]
pub enum Received<'a> {
    /// Nothing to do yet.
    Nothing,
    /// Send this flow control now.
    FlowControl(Frame),
    /// A complete message.
    Message(&'a [u8]),
}

/// Reassembles messages up to `N` bytes.
#[derive(Debug, Clone)]
pub struct Receiver<const N: usize> {
    config: Config,
    buffer: [u8; N],
    len: usize,
    filled: usize,
    expected_sequence: u8,
    block_count: u8,
    last_us: u32,
    receiving: bool,
    /// A message interrupted by a new first frame (or timed out before it), reported after the
    /// new one is taken.
    interrupted: bool,
}

impl<const N: usize> Receiver<N> {
    /// An idle receiver.
    pub const fn new(config: Config) -> Self {
        Self {
            config,
            buffer: [0; N],
            len: 0,
            filled: 0,
            expected_sequence: 0,
            block_count: 0,
            last_us: 0,
            receiving: false,
            interrupted: false,
        }
    }

    /// True while a segmented message is being reassembled.
    pub fn is_receiving(&self) -> bool {
        self.receiving
    }

    /// Drops a partial message older than N_Cr. Call it periodically when frames may stop
    /// coming; `on_frame` checks the same on every frame.
    pub fn poll(&mut self, now_us: u32) -> Result<(), RxError> {
        if self.receiving && now_us.wrapping_sub(self.last_us) > self.config.timeout_us {
            self.receiving = false;
            return Err(RxError::Timeout);
        }
        Ok(())
    }

    /// Feeds one frame received on the data identifier.
    ///
    /// A single or first frame that arrives mid-message starts the new message at once (its
    /// flow control must not wait); the dropped partial message is reported by
    /// [`take_interrupted`](Self::take_interrupted) so the caller can count it.
    pub fn on_frame(&mut self, data: &[u8], now_us: u32) -> Result<Received<'_>, RxError> {
        let timed_out = self.poll(now_us);
        let pci = parse(data).map_err(RxError::Frame)?;
        if timed_out.is_err() && matches!(pci, Pci::Single(_) | Pci::First { .. }) {
            // The partial message timed out and a new one starts: the new one is taken, the
            // lost one reported like an interrupted one.
            self.interrupted = true;
        }
        match pci {
            Pci::Single(payload) => {
                self.note_interruption();
                let stored = self
                    .buffer
                    .get_mut(..payload.len())
                    .ok_or(RxError::TooLong {
                        length: payload.len() as u16,
                        reply: None,
                    })?;
                stored.copy_from_slice(payload);
                Ok(Received::Message(
                    self.buffer.get(..payload.len()).unwrap_or_default(),
                ))
            }
            Pci::First { length, data } => {
                self.note_interruption();
                let len = usize::from(length);
                if len > N {
                    return Err(RxError::TooLong {
                        length,
                        reply: Some(flow_control(
                            FlowStatus::Overflow,
                            0,
                            self.config.st_min,
                            self.config.padding,
                        )),
                    });
                }
                let take = data.len().min(6).min(len);
                if let (Some(slot), Some(src)) = (self.buffer.get_mut(..take), data.get(..take)) {
                    slot.copy_from_slice(src);
                }
                self.len = len;
                self.filled = take;
                self.expected_sequence = 1;
                self.block_count = 0;
                self.last_us = now_us;
                self.receiving = true;
                Ok(Received::FlowControl(self.continue_to_send()))
            }
            Pci::Consecutive { sequence, data } => {
                timed_out?;
                if !self.receiving {
                    return Err(RxError::UnexpectedConsecutive);
                }
                if sequence != self.expected_sequence {
                    self.receiving = false;
                    return Err(RxError::Sequence {
                        expected: self.expected_sequence,
                        got: sequence,
                    });
                }
                let take = data.len().min(self.len - self.filled);
                if let (Some(slot), Some(src)) = (
                    self.buffer.get_mut(self.filled..self.filled + take),
                    data.get(..take),
                ) {
                    slot.copy_from_slice(src);
                }
                self.filled += take;
                self.expected_sequence = (self.expected_sequence + 1) & 0x0F;
                self.last_us = now_us;
                if self.filled >= self.len {
                    self.receiving = false;
                    return Ok(Received::Message(
                        self.buffer.get(..self.len).unwrap_or_default(),
                    ));
                }
                self.block_count = self.block_count.wrapping_add(1);
                if self.config.block_size != 0 && self.block_count >= self.config.block_size {
                    self.block_count = 0;
                    return Ok(Received::FlowControl(self.continue_to_send()));
                }
                Ok(Received::Nothing)
            }
            // Our own flow control echoed, or another pair's: not for a receiver.
            Pci::FlowControl { .. } => Ok(Received::Nothing),
        }
    }

    /// True (once) if a partial message was dropped because a new one started (mid-message,
    /// or after the partial one timed out with no frame to report it).
    pub fn take_interrupted(&mut self) -> bool {
        core::mem::take(&mut self.interrupted)
    }

    fn note_interruption(&mut self) {
        if self.receiving {
            self.interrupted = true;
            self.receiving = false;
        }
    }

    fn continue_to_send(&self) -> Frame {
        flow_control(
            FlowStatus::ContinueToSend,
            self.config.block_size,
            self.config.st_min,
            self.config.padding,
        )
    }
}
