//! Page switching: one calibration segment (0) with a working page (0, read-write) and a
//! reference page (1, read-only). The ECU's page belongs to the target, which may refuse a
//! switch; the XCP access page (what UPLOAD and DOWNLOAD see) belongs to the session.

use crate::protocol::{err, page_mode};
use crate::refusal::{Detail, reason};
use crate::slave::Slave;
use crate::target::Target;
use crate::wire::{Answer, Args, Fail, Outcome, Packet};

/// GET_PAGE_INFO properties of the working page: ECU access, XCP read and XCP write
/// allowed with or without the other side (both bits of each two-bit field set).
const WORKING_PAGE_PROPERTIES: u8 = 0x3F;

/// GET_PAGE_INFO properties of the reference page: ECU access and XCP read, no XCP write.
const REFERENCE_PAGE_PROPERTIES: u8 = 0x0F;

/// ERR_SEGMENT_NOT_VALID unless the segment is 0.
fn require_segment(segment: u8) -> Result<(), Fail> {
    if segment == 0 {
        Ok(())
    } else {
        Err(Fail::new(err::SEGMENT_NOT_VALID))
    }
}

/// ERR_PAGE_NOT_VALID unless the page exists (0 working, 1 reference).
fn require_page(page: u8) -> Result<(), Fail> {
    if page <= 1 {
        Ok(())
    } else {
        Err(Fail::new(err::PAGE_NOT_VALID))
    }
}

/// The modes SET_CAL_PAGE accepts: ECU and/or XCP, optionally for all segments.
fn page_mode_valid(mode: u8) -> bool {
    mode & (page_mode::ECU | page_mode::XCP) != 0
        && mode & !(page_mode::ECU | page_mode::XCP | page_mode::ALL) == 0
}

impl<const LISTS: usize, const ODTS: usize, const ENTRIES: usize> Slave<LISTS, ODTS, ENTRIES> {
    /// SET_CAL_PAGE: ECU and/or XCP page, atomically (if the target refuses the ECU's switch,
    /// the XCP page stays too).
    pub(crate) fn set_cal_page(&mut self, target: &mut impl Target, args: Args<'_>) -> Outcome {
        let mode = args.u8(1)?;
        let segment = args.u8(2)?;
        let page = args.u8(3)?;
        self.require_unlocked()?;
        if !page_mode_valid(mode) {
            return Err(Fail::new(err::MODE_NOT_VALID));
        }
        if mode & page_mode::ALL == 0 {
            require_segment(segment)?;
        }
        require_page(page)?;
        if mode & page_mode::ECU != 0 {
            target
                .set_ecu_page(page)
                .map_err(|refusal| Fail::refused(refusal, target))?;
        }
        if mode & page_mode::XCP != 0 {
            self.xcp_page = page;
        }
        Ok(Answer::Reply(Packet::ok(&[])))
    }

    /// GET_CAL_PAGE: the ECU's or the XCP page of segment 0.
    pub(crate) fn get_cal_page(&self, target: &impl Target, args: Args<'_>) -> Outcome {
        let mode = args.u8(1)?;
        let segment = args.u8(2)?;
        let page = match mode {
            page_mode::ECU => target.ecu_page(),
            page_mode::XCP => self.xcp_page,
            _ => return Err(Fail::new(err::MODE_NOT_VALID)),
        };
        require_segment(segment)?;
        Ok(Answer::Reply(Packet::ok(&[0, 0, page])))
    }

    /// GET_SEGMENT_INFO: mode 0 the address (info 0) or length (info 1), mode 1 the standard
    /// info (2 pages, extension, no address mappings, no compression or encryption).
    pub(crate) fn get_segment_info(&self, args: Args<'_>) -> Outcome {
        let mode = args.u8(1)?;
        let segment = args.u8(2)?;
        let info = args.u8(3)?;
        require_segment(segment)?;
        let layout = self.config.segment;
        match (mode, info) {
            (0, 0 | 1) => {
                let mut packet = Packet::ok(&[0, 0, 0]);
                packet.push_u32(if info == 0 {
                    layout.address
                } else {
                    layout.length
                });
                Ok(Answer::Reply(packet))
            }
            (1, _) => Ok(Answer::Reply(Packet::ok(&[2, layout.ext, 0, 0, 0]))),
            _ => Err(Fail::new(err::OUT_OF_RANGE)),
        }
    }

    /// GET_PAGE_INFO: the access rights of a page, init segment 0.
    pub(crate) fn get_page_info(&self, args: Args<'_>) -> Outcome {
        let segment = args.u8(2)?;
        let page = args.u8(3)?;
        require_segment(segment)?;
        require_page(page)?;
        let properties = if page == 0 {
            WORKING_PAGE_PROPERTIES
        } else {
            REFERENCE_PAGE_PROPERTIES
        };
        Ok(Answer::Reply(Packet::ok(&[properties, 0])))
    }

    /// COPY_CAL_PAGE: one page onto the other through the target (reference onto working
    /// restores the defaults); the reference page is never a destination.
    pub(crate) fn copy_cal_page(&mut self, target: &mut impl Target, args: Args<'_>) -> Outcome {
        let from_segment = args.u8(1)?;
        let from = args.u8(2)?;
        let to_segment = args.u8(3)?;
        let to = args.u8(4)?;
        self.require_unlocked()?;
        require_segment(from_segment)?;
        require_segment(to_segment)?;
        require_page(from)?;
        require_page(to)?;
        if to != 0 {
            return Err(Fail::because(
                err::WRITE_PROTECTED,
                Detail::of(reason::READ_ONLY, 0.0, 0.0),
            ));
        }
        target
            .copy_page(from, to)
            .map_err(|refusal| Fail::refused(refusal, target))?;
        Ok(Answer::Reply(Packet::ok(&[])))
    }
}
