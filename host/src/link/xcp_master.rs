//! An XCP master on TCP for the CCM's calibration page, as the dashboard's Tune page uses it
//! through the Pi's gateway: connect, read the page, unlock with the team's seed and key,
//! write a value, copy the reference page over the working page, switch the ECU page, save
//! to flash. One command at a time, each answered (or timed out) before the next; events and
//! DAQ packets in between are skipped. Every refusal comes back as the slave's XCP error code,
//! for [`crate::calibration::refusal_text`].

use aer::calibration::PAGE_LEN;
use aer::calibration::xcp::CALIBRATION_ADDRESS;
use aer_xcp::protocol::{cmd, page_mode, pid, resource, session};
use aer_xcp::seed_key::{SECRET_LEN, key_for};
use aer_xcp::transport::{TCP_FRAME_MAX, TcpDecoder, TcpEncoder};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::Duration;
use thiserror::Error;

/// Bytes one SHORT_UPLOAD or DOWNLOAD_NEXT carries at MAX_CTO 8.
const UPLOAD_CHUNK: usize = 7;
const DOWNLOAD_CHUNK: usize = 6;

/// Why a command did not succeed.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum MasterError {
    /// The slave answered with an error (its XCP code).
    #[error("the CCM refused it (XCP error 0x{0:02X})")]
    Refused(u8),
    /// No answer in time.
    #[error("no answer within {0:?}")]
    Timeout(Duration),
    /// The connection failed or closed.
    #[error("connection: {0}")]
    Io(String),
    /// Something that is not XCP on TCP, or an answer that does not fit the command.
    #[error("protocol: {0}")]
    Protocol(&'static str),
    /// Unlocking needs the team's secret, and none is configured.
    #[error("no XCP secret configured: calibration stays locked")]
    NoSecret,
}

impl From<std::io::Error> for MasterError {
    fn from(error: std::io::Error) -> Self {
        match error.kind() {
            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut => {
                Self::Timeout(Duration::ZERO)
            }
            _ => Self::Io(error.to_string()),
        }
    }
}

/// A connected master.
pub struct Master {
    stream: TcpStream,
    encoder: TcpEncoder,
    decoder: TcpDecoder,
    /// Bytes read but not decoded yet.
    unread: Vec<u8>,
    timeout: Duration,
}

impl Master {
    /// Connects to `address` and opens an XCP session (CONNECT); `timeout` bounds the TCP
    /// connection and every answer.
    pub fn connect(address: SocketAddr, timeout: Duration) -> Result<Self, MasterError> {
        let stream = TcpStream::connect_timeout(&address, timeout)?;
        stream.set_nodelay(true)?;
        stream.set_read_timeout(Some(timeout))?;
        stream.set_write_timeout(Some(timeout))?;
        let mut master = Self {
            stream,
            encoder: TcpEncoder::new(),
            decoder: TcpDecoder::new(),
            unread: Vec::new(),
            timeout,
        };
        master.command(&[cmd::CONNECT, 0])?;
        Ok(master)
    }

    /// Sends `packet` and returns the positive response (an error response is
    /// [`MasterError::Refused`]).
    pub fn command(&mut self, packet: &[u8]) -> Result<Vec<u8>, MasterError> {
        self.send_unanswered(packet)?;
        loop {
            let answer = self.next_packet()?;
            match answer.first() {
                Some(&pid::RES) => return Ok(answer),
                Some(&pid::ERR) => {
                    return Err(MasterError::Refused(answer.get(1).copied().unwrap_or(0)));
                }
                // Events, service requests, DAQ: not the answer.
                _ => {}
            }
        }
    }

    /// The next whole packet: from what was read already, else from the stream.
    fn next_packet(&mut self) -> Result<Vec<u8>, MasterError> {
        loop {
            let (used, packet) = self.decoder.decode(&self.unread);
            let packet = packet.map(|p| {
                p.map(|p| p.data.to_vec())
                    .map_err(|_| MasterError::Protocol("not XCP on TCP"))
            });
            self.unread.drain(..used.min(self.unread.len()));
            if let Some(packet) = packet {
                return packet;
            }
            let mut buffer = [0u8; 256];
            let read = match self.stream.read(&mut buffer) {
                Ok(0) => return Err(MasterError::Io("the gateway closed the connection".into())),
                Ok(read) => read,
                Err(error) => {
                    return Err(match MasterError::from(error) {
                        MasterError::Timeout(_) => MasterError::Timeout(self.timeout),
                        other => other,
                    });
                }
            };
            self.unread
                .extend_from_slice(buffer.get(..read).unwrap_or_default());
        }
    }

    /// Bytes `address..address + len` of the XCP page (SHORT_UPLOAD).
    pub fn read(&mut self, address: u32, len: usize) -> Result<Vec<u8>, MasterError> {
        let mut bytes = Vec::with_capacity(len);
        while bytes.len() < len {
            let count = UPLOAD_CHUNK.min(len - bytes.len());
            let at = u32::try_from(bytes.len())
                .ok()
                .and_then(|offset| address.checked_add(offset))
                .ok_or(MasterError::Protocol("an address past 4 GiB"))?;
            let mut upload = vec![cmd::SHORT_UPLOAD, count as u8, 0, 0];
            upload.extend_from_slice(&at.to_le_bytes());
            let answer = self.command(&upload)?;
            let data = answer
                .get(1..=count)
                .ok_or(MasterError::Protocol("a short SHORT_UPLOAD answer"))?;
            bytes.extend_from_slice(data);
        }
        Ok(bytes)
    }

    /// The working page (or the page the XCP side is switched to).
    pub fn read_page(&mut self) -> Result<[u8; PAGE_LEN], MasterError> {
        let bytes = self.read(CALIBRATION_ADDRESS, PAGE_LEN)?;
        bytes
            .try_into()
            .map_err(|_| MasterError::Protocol("a page of the wrong length"))
    }

    /// The page the control step runs on (0 working, 1 reference).
    pub fn ecu_page(&mut self) -> Result<u8, MasterError> {
        let answer = self.command(&[cmd::GET_CAL_PAGE, page_mode::ECU, 0])?;
        answer
            .get(3)
            .copied()
            .ok_or(MasterError::Protocol("a short GET_CAL_PAGE answer"))
    }

    /// Whether calibration is locked (GET_STATUS's protection bits).
    pub fn calibration_locked(&mut self) -> Result<bool, MasterError> {
        let answer = self.command(&[cmd::GET_STATUS])?;
        let protection = answer
            .get(2)
            .copied()
            .ok_or(MasterError::Protocol("a short GET_STATUS answer"))?;
        Ok(protection & resource::CAL_PAG != 0)
    }

    /// Unlocks calibration with the team's secret (GET_SEED, UNLOCK).
    pub fn unlock(&mut self, secret: Option<&[u8; SECRET_LEN]>) -> Result<(), MasterError> {
        let secret = secret.ok_or(MasterError::NoSecret)?;
        let answer = self.command(&[cmd::GET_SEED, 0, resource::CAL_PAG])?;
        let len = usize::from(*answer.get(1).ok_or(MasterError::Protocol("no seed"))?);
        if len == 0 {
            return Ok(()); // Already unlocked.
        }
        let seed = answer
            .get(2..2 + len)
            .ok_or(MasterError::Protocol("a seed longer than its answer"))?;
        let key = key_for(secret, seed);
        let mut remaining = key.len();
        for chunk in key.chunks(DOWNLOAD_CHUNK) {
            let mut unlock = vec![cmd::UNLOCK, remaining as u8];
            unlock.extend_from_slice(chunk);
            self.command(&unlock)?;
            remaining -= chunk.len();
        }
        Ok(())
    }

    /// Writes `data` at `address` as one transaction (SET_MTA, then one DOWNLOAD or a master
    /// block of DOWNLOAD and DOWNLOAD_NEXT, which the slave answers once, at its end).
    pub fn write(&mut self, address: u32, data: &[u8]) -> Result<(), MasterError> {
        let total = u8::try_from(data.len())
            .map_err(|_| MasterError::Protocol("a write over 255 bytes"))?;
        let mut set_mta = vec![cmd::SET_MTA, 0, 0, 0];
        set_mta.extend_from_slice(&address.to_le_bytes());
        self.command(&set_mta)?;
        let mut remaining = usize::from(total);
        let chunks: Vec<&[u8]> = data.chunks(DOWNLOAD_CHUNK).collect();
        for (i, chunk) in chunks.iter().enumerate() {
            let code = if i == 0 {
                cmd::DOWNLOAD
            } else {
                cmd::DOWNLOAD_NEXT
            };
            let mut packet = vec![code, remaining as u8];
            packet.extend_from_slice(chunk);
            remaining -= chunk.len();
            if remaining == 0 {
                self.command(&packet)?;
            } else {
                // The slave answers a block packet only with an error.
                self.send_unanswered(&packet)?;
            }
        }
        Ok(())
    }

    /// Sends `packet` without waiting for an answer.
    fn send_unanswered(&mut self, packet: &[u8]) -> Result<(), MasterError> {
        let mut frame = [0u8; TCP_FRAME_MAX];
        let len = self
            .encoder
            .encode(packet, &mut frame)
            .map_err(|_| MasterError::Protocol("a command too long for XCP on TCP"))?;
        self.stream
            .write_all(frame.get(..len).unwrap_or_default())?;
        Ok(())
    }

    /// Copies the reference page (the schema's defaults) over the working page.
    pub fn revert_to_reference(&mut self) -> Result<(), MasterError> {
        self.command(&[cmd::COPY_CAL_PAGE, 0, 1, 0, 0]).map(drop)
    }

    /// Makes the control step run on `page` (0 working, 1 reference).
    pub fn set_ecu_page(&mut self, page: u8) -> Result<(), MasterError> {
        self.command(&[cmd::SET_CAL_PAGE, page_mode::ECU, 0, page])
            .map(drop)
    }

    /// Saves the working page to flash, for the next start.
    pub fn save(&mut self) -> Result<(), MasterError> {
        self.command(&[cmd::SET_REQUEST, session::STORE_CAL_REQ, 0, 0])
            .map(drop)
    }

    /// Ends the session (DISCONNECT); the connection closes when the master is dropped.
    pub fn disconnect(mut self) -> Result<(), MasterError> {
        self.command(&[cmd::DISCONNECT]).map(drop)
    }
}
