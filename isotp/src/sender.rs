//! The sending end: single frame, or first frame then consecutive frames paced by the
//! receiver's flow control.

use crate::frame::{FlowStatus, Frame, Pci, StMin, parse};
use crate::{Config, MAX_PAYLOAD};

/// Why a message could not be (completely) sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SendError {
    /// Empty, or longer than 4095 bytes or this sender's buffer.
    Length(usize),
    /// The previous message is still being sent.
    Busy,
    /// No flow control within N_Bs.
    Timeout,
    /// The receiver answered OVERFLOW: it cannot take a message this long.
    Overflow,
    /// More WAIT flow controls in a row than the configuration tolerates.
    TooManyWaits,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Idle,
    /// A single or first frame is ready; the message starts once it is sent.
    Starting,
    /// Waiting for flow control since `since_us`.
    AwaitingFlowControl {
        since_us: u32,
        waits: u8,
    },
    /// Sending consecutive frames.
    Sending {
        /// Frames left in this block (`None` = no block limit).
        block_left: Option<u8>,
        /// Earliest time of the next consecutive frame.
        next_us: u32,
        st_min: StMin,
    },
}

/// Sends one message at a time; `N` is the largest message it can hold.
///
/// Use: [`start`](Self::start) a message, then call [`poll`](Self::poll) with the clock; when it
/// yields a frame, transmit it and call [`sent`](Self::sent). Feed every frame received on the
/// flow-control identifier to [`on_flow_control`](Self::on_flow_control). A frame that the CAN
/// controller could not take is simply offered again by the next `poll`.
#[derive(Debug, Clone)]
pub struct Sender<const N: usize> {
    config: Config,
    buffer: [u8; N],
    len: usize,
    offset: usize,
    sequence: u8,
    state: State,
}

impl<const N: usize> Sender<N> {
    /// An idle sender.
    pub const fn new(config: Config) -> Self {
        Self {
            config,
            buffer: [0; N],
            len: 0,
            offset: 0,
            sequence: 0,
            state: State::Idle,
        }
    }

    /// True when no message is in progress.
    pub fn is_idle(&self) -> bool {
        self.state == State::Idle
    }

    /// Starts sending `payload`.
    pub fn start(&mut self, payload: &[u8]) -> Result<(), SendError> {
        if self.state != State::Idle {
            return Err(SendError::Busy);
        }
        let len = payload.len();
        let stored = self.buffer.get_mut(..len);
        match stored {
            Some(stored) if len > 0 && len <= MAX_PAYLOAD => stored.copy_from_slice(payload),
            _ => return Err(SendError::Length(len)),
        }
        self.len = len;
        self.offset = 0;
        self.sequence = 1;
        self.state = State::Starting;
        Ok(())
    }

    /// Abandons the message in progress (for example when a newer one replaces it).
    pub fn abort(&mut self) {
        self.state = State::Idle;
    }

    /// The frame to transmit now, if any; errors end the message.
    pub fn poll(&mut self, now_us: u32) -> Result<Option<Frame>, SendError> {
        match self.state {
            State::Idle => Ok(None),
            State::Starting => Ok(Some(self.first_frame())),
            State::AwaitingFlowControl { since_us, .. } => {
                if now_us.wrapping_sub(since_us) > self.config.timeout_us {
                    self.state = State::Idle;
                    return Err(SendError::Timeout);
                }
                Ok(None)
            }
            State::Sending { next_us, .. } => {
                // Signed difference: "now is at or after next", wrap-safe.
                if (now_us.wrapping_sub(next_us) as i32) < 0 {
                    return Ok(None);
                }
                let end = (self.offset + 7).min(self.len);
                let data = self.buffer.get(self.offset..end).unwrap_or_default();
                Ok(Some(Frame::build(
                    &[0x20 | self.sequence],
                    data,
                    self.config.padding,
                )))
            }
        }
    }

    /// Records that the frame `poll` returned went out at `now_us`.
    pub fn sent(&mut self, now_us: u32) {
        match self.state {
            State::Starting => {
                if self.len <= 7 {
                    self.state = State::Idle;
                } else {
                    self.offset = 6;
                    self.state = State::AwaitingFlowControl {
                        since_us: now_us,
                        waits: 0,
                    };
                }
            }
            State::Sending {
                block_left, st_min, ..
            } => {
                self.offset = (self.offset + 7).min(self.len);
                self.sequence = (self.sequence + 1) & 0x0F;
                if self.offset >= self.len {
                    self.state = State::Idle;
                    return;
                }
                let block_left = block_left.map(|left| left.saturating_sub(1));
                self.state = if block_left == Some(0) {
                    State::AwaitingFlowControl {
                        since_us: now_us,
                        waits: 0,
                    }
                } else {
                    State::Sending {
                        block_left,
                        next_us: now_us.wrapping_add(st_min.micros()),
                        st_min,
                    }
                };
            }
            State::Idle | State::AwaitingFlowControl { .. } => {}
        }
    }

    /// Feeds a frame received on the flow-control identifier. Frames that are not flow
    /// control, or arrive when none is awaited, are ignored (another node's traffic).
    pub fn on_flow_control(&mut self, data: &[u8], now_us: u32) -> Result<(), SendError> {
        let State::AwaitingFlowControl { waits, .. } = self.state else {
            return Ok(());
        };
        let Ok(Pci::FlowControl {
            status,
            block_size,
            st_min,
        }) = parse(data)
        else {
            return Ok(());
        };
        match status {
            FlowStatus::ContinueToSend => {
                self.state = State::Sending {
                    block_left: (block_size != 0).then_some(block_size),
                    next_us: now_us,
                    st_min,
                };
                Ok(())
            }
            FlowStatus::Wait if waits < self.config.max_waits => {
                self.state = State::AwaitingFlowControl {
                    since_us: now_us,
                    waits: waits + 1,
                };
                Ok(())
            }
            FlowStatus::Wait => {
                self.state = State::Idle;
                Err(SendError::TooManyWaits)
            }
            FlowStatus::Overflow => {
                self.state = State::Idle;
                Err(SendError::Overflow)
            }
        }
    }

    fn first_frame(&self) -> Frame {
        let payload = self.buffer.get(..self.len).unwrap_or_default();
        if self.len <= 7 {
            // len <= 7 fits the low nibble.
            return Frame::build(&[self.len as u8], payload, self.config.padding);
        }
        let [high, low] = (self.len as u16).to_be_bytes();
        let head = [0x10 | (high & 0x0F), low];
        Frame::build(
            &head,
            payload.get(..6).unwrap_or_default(),
            self.config.padding,
        )
    }
}
