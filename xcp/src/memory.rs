//! Memory transfer: the MTA, reads (UPLOAD, SHORT_UPLOAD, BUILD_CHECKSUM, GET_ID's text),
//! and writes (DOWNLOAD with master block mode, DOWNLOAD_NEXT). Reads and writes go through
//! the [`Target`]; a block download reaches it as one write. SHORT_DOWNLOAD is not offered:
//! its eight-byte header leaves no room for data at MAX_CTO 8 (ERR_CMD_UNKNOWN).

use crate::checksum::Crc16Ccitt;
use crate::config::{BLOCK_MAX, DOWNLOAD_CHUNK};
use crate::protocol::{checksum_type, err, id_type};
use crate::refusal::{Detail, reason};
use crate::slave::Slave;
use crate::target::Target;
use crate::transfer::{Block, Mta, Text, after_packet, expected};
use crate::wire::{Answer, Args, Fail, Outcome, Packet};

impl<const LISTS: usize, const ODTS: usize, const ENTRIES: usize> Slave<LISTS, ODTS, ENTRIES> {
    /// The bytes of a text the MTA can point at.
    fn text<'t>(&self, target: &'t impl Target, text: Text) -> &'t [u8] {
        match text {
            Text::Ascii => self.config.id_text.as_bytes(),
            Text::A2lName => self.config.a2l_name.as_bytes(),
            Text::Epk => target.epk(),
            Text::EventName(channel) => self
                .config
                .events
                .get(usize::from(channel))
                .map_or(&[][..], |event| event.name.as_bytes()),
            Text::Empty => &[],
        }
    }

    /// Reads `out.len()` bytes at `mta`, on the XCP page.
    fn read_at(&self, target: &impl Target, mta: Mta, out: &mut [u8]) -> Result<(), Fail> {
        match mta {
            Mta::Memory { ext, address } => target
                .read(self.xcp_page, ext, address, out)
                .map_err(|refusal| Fail::refused(refusal, target)),
            Mta::Text { text, offset } => {
                let start = usize::try_from(offset).map_err(|_| Fail::new(err::OUT_OF_RANGE))?;
                let end = start
                    .checked_add(out.len())
                    .ok_or(Fail::new(err::OUT_OF_RANGE))?;
                let bytes = self
                    .text(target, text)
                    .get(start..end)
                    .ok_or(Fail::new(err::OUT_OF_RANGE))?;
                for (slot, byte) in out.iter_mut().zip(bytes) {
                    *slot = *byte;
                }
                Ok(())
            }
        }
    }

    /// Reads `count` bytes at `mta` into a positive response.
    fn upload_at(&self, target: &impl Target, mta: Mta, count: u8) -> Result<Packet, Fail> {
        let count = usize::from(count);
        let mut packet = Packet::ok(&[]);
        if count == 0 || count > packet.room() {
            return Err(Fail::new(err::OUT_OF_RANGE));
        }
        let tail = packet.tail_mut(count).ok_or(Fail::new(err::OUT_OF_RANGE))?;
        self.read_at(target, mta, tail)?;
        packet.commit(count);
        Ok(packet)
    }

    /// GET_ID: answers the length and points the MTA at the text (UPLOAD reads it; a CAN
    /// response has no room for it inline). Types without a text answer length 0.
    pub(crate) fn get_id(&mut self, target: &impl Target, args: Args<'_>) -> Outcome {
        let text = match args.u8(1)? {
            id_type::ASCII => Text::Ascii,
            id_type::A2L_NAME => Text::A2lName,
            id_type::EPK => Text::Epk,
            _ => Text::Empty,
        };
        let length = u32::try_from(self.text(target, text).len()).unwrap_or(u32::MAX);
        self.mta = Mta::Text { text, offset: 0 };
        let mut packet = Packet::ok(&[0, 0, 0]); // mode 0: upload from the MTA
        packet.push_u32(length);
        Ok(Answer::Reply(packet))
    }

    /// SET_MTA: any address; the target judges it at the next access.
    pub(crate) fn set_mta(&mut self, args: Args<'_>) -> Outcome {
        let ext = args.u8(3)?;
        let address = args.u32(4)?;
        self.mta = Mta::Memory { ext, address };
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// UPLOAD: up to MAX_CTO-1 bytes at the MTA, which then advances.
    pub(crate) fn upload(&mut self, target: &impl Target, args: Args<'_>) -> Outcome {
        let count = args.u8(1)?;
        let next = self
            .mta
            .advanced(usize::from(count))
            .ok_or(Fail::new(err::OUT_OF_RANGE))?;
        let packet = self.upload_at(target, self.mta, count)?;
        self.mta = next;
        Ok(Answer::Reply(packet))
    }

    /// SHORT_UPLOAD: up to MAX_CTO-1 bytes at the given address; the MTA ends after them.
    pub(crate) fn short_upload(&mut self, target: &impl Target, args: Args<'_>) -> Outcome {
        let count = args.u8(1)?;
        let mta = Mta::Memory {
            ext: args.u8(3)?,
            address: args.u32(4)?,
        };
        let next = mta
            .advanced(usize::from(count))
            .ok_or(Fail::new(err::OUT_OF_RANGE))?;
        let packet = self.upload_at(target, mta, count)?;
        self.mta = next;
        Ok(Answer::Reply(packet))
    }

    /// BUILD_CHECKSUM: XCP_CRC_16_CITT over a block at the MTA (read through the target); a
    /// block larger than the configured limit answers ERR_OUT_OF_RANGE with that limit.
    pub(crate) fn build_checksum(&mut self, target: &impl Target, args: Args<'_>) -> Outcome {
        let size = args.u32(4)?;
        let limit = self.config.max_checksum_block;
        if size == 0 || size > limit {
            return Err(Fail::with_u32(err::OUT_OF_RANGE, limit));
        }
        let size = usize::try_from(size).map_err(|_| Fail::new(err::OUT_OF_RANGE))?;
        let next = self
            .mta
            .advanced(size)
            .ok_or(Fail::new(err::OUT_OF_RANGE))?;
        let mut crc = Crc16Ccitt::new();
        let mut done = 0usize;
        let mut chunk = [0u8; 32];
        while done < size {
            let len = (size - done).min(chunk.len());
            let at = self
                .mta
                .advanced(done)
                .ok_or(Fail::new(err::OUT_OF_RANGE))?;
            let part = chunk.get_mut(..len).ok_or(Fail::new(err::OUT_OF_RANGE))?;
            self.read_at(target, at, part)?;
            crc.update(part);
            done += len;
        }
        self.mta = next;
        let mut packet = Packet::ok(&[checksum_type::CRC_16_CITT, 0, 0]);
        packet.push_u32(u32::from(crc.value()));
        Ok(Answer::Reply(packet))
    }

    /// Where a write may go: calibration unlocked, the XCP page is the working page, and the
    /// MTA is a memory address.
    fn write_destination(&self) -> Result<(u8, u32), Fail> {
        self.require_unlocked()?;
        if self.xcp_page != 0 {
            // The reference page is the schema's defaults: never written.
            return Err(Fail::because(
                err::WRITE_PROTECTED,
                Detail::of(reason::READ_ONLY, 0.0, 0.0),
            ));
        }
        match self.mta {
            Mta::Memory { ext, address } => Ok((ext, address)),
            Mta::Text { .. } => Err(Fail::new(err::ACCESS_DENIED)),
        }
    }

    /// Writes bytes at the MTA as one target transaction; the MTA advances only on success.
    fn commit(&mut self, target: &mut impl Target, ext: u8, address: u32, data: &[u8]) -> Outcome {
        let mta = Mta::Memory { ext, address };
        let next = mta
            .advanced(data.len())
            .ok_or(Fail::new(err::OUT_OF_RANGE))?;
        target
            .write(ext, address, data)
            .map_err(|refusal| Fail::refused(refusal, target))?;
        self.mta = next;
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// DOWNLOAD: up to six bytes written at once, or the first packet of a master-block-mode
    /// block of up to MAX_BS packets, collected and written as one transaction.
    ///
    /// A DOWNLOAD arriving while a block is open and carrying exactly its missing bytes
    /// completes the block: pyxcp's block downloader sends the tail of a 7..11-byte block as
    /// a DOWNLOAD instead of a DOWNLOAD_NEXT, and a slave that writes as it receives would
    /// place those bytes right there. Any other DOWNLOAD into an open block is a sequence
    /// error and nothing of the block is written (after a failed block, whose error was
    /// answered, it simply starts a new transfer).
    pub(crate) fn download(&mut self, target: &mut impl Target, args: Args<'_>) -> Outcome {
        let count = usize::from(args.u8(1)?);
        if self.block.is_open() {
            if count == self.block.remaining() && count <= DOWNLOAD_CHUNK {
                return self.download_next(target, args);
            }
            if !self.block.failed {
                let fail = Fail::with_byte(err::SEQUENCE, expected(&self.block));
                self.block = after_packet(count);
                return Err(fail);
            }
            // The failed block's error is answered; this DOWNLOAD starts a new transfer.
            self.block = Block::IDLE;
        }
        let started = self.start_block(target, args, count);
        if started.is_err() {
            self.block = after_packet(count);
        }
        started
    }

    /// A DOWNLOAD with no block open: writes it, or opens a block.
    fn start_block(&mut self, target: &mut impl Target, args: Args<'_>, count: usize) -> Outcome {
        let (ext, address) = self.write_destination()?;
        let most = usize::from(self.config.block_packets())
            .saturating_mul(DOWNLOAD_CHUNK)
            .min(BLOCK_MAX);
        if count == 0 || count > most {
            return Err(Fail::new(err::OUT_OF_RANGE));
        }
        let end = u32::try_from(count)
            .ok()
            .and_then(|count| address.checked_add(count));
        if end.is_none() {
            return Err(Fail::new(err::OUT_OF_RANGE));
        }
        let data = args.slice(2, count.min(DOWNLOAD_CHUNK))?;
        if count <= DOWNLOAD_CHUNK {
            return self.commit(target, ext, address, data);
        }
        self.block = Block::open(count, ext, address);
        self.block.append(data);
        Ok(Answer::Silent)
    }

    /// DOWNLOAD_NEXT: the next packet of the open block; its count must be the bytes still to
    /// come (else ERR_SEQUENCE with the expected count, and the block is dropped). The last one
    /// writes the whole block and answers; the others are not answered. Packets of a block
    /// whose error was already answered are dropped without answer.
    pub(crate) fn download_next(&mut self, target: &mut impl Target, args: Args<'_>) -> Outcome {
        let count = match args.u8(1) {
            Ok(count) => usize::from(count),
            Err(fail) => {
                self.block = Block::IDLE;
                return Err(fail);
            }
        };
        if !self.block.is_open() || count != self.block.remaining() {
            let fail = Fail::with_byte(err::SEQUENCE, expected(&self.block));
            self.block = after_packet(count);
            return Err(fail);
        }
        if self.block.failed {
            self.block = after_packet(count);
            return Ok(Answer::Silent);
        }
        let data = match args.slice(2, count.min(DOWNLOAD_CHUNK)) {
            Ok(data) => data,
            Err(fail) => {
                self.block = after_packet(count);
                return Err(fail);
            }
        };
        self.block.append(data);
        if self.block.remaining() > 0 {
            return Ok(Answer::Silent);
        }
        let block = self.block;
        self.block = Block::IDLE;
        self.commit(target, block.ext, block.address, block.bytes())
    }
}
