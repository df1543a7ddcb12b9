//! The numbers of the XCP protocol layer (ASAM MCD-1 XCP 1.x) that this slave speaks: packet
//! identifiers, command codes, error codes and the bits of the fields it answers. Kept apart
//! from the logic so the tests and the CCM binding name the same constants as the slave.

/// Largest command and response packet (CTO), in bytes: one classic CAN frame. XCP-on-TCP uses
/// the same size so both transports behave alike.
pub const MAX_CTO: usize = 8;

/// Largest data acquisition packet (DTO), in bytes: one classic CAN frame, on TCP too.
pub const MAX_DTO: usize = 8;

/// Packet identifiers of the slave's answers (first byte of a response or error packet).
pub mod pid {
    /// Positive response.
    pub const RES: u8 = 0xFF;
    /// Error packet.
    pub const ERR: u8 = 0xFE;
    /// Event packet (EV_DAQ_OVERLOAD, EV_SESSION_TERMINATED).
    pub const EV: u8 = 0xFD;
    /// Service request packet (never sent by this slave).
    pub const SERV: u8 = 0xFC;
    /// Number of PIDs a DTO may use: absolute ODT numbers 0..=0xFB.
    pub const DTO_LIMIT: usize = 0xFC;
}

/// Command codes (first byte of a command packet) the slave dispatches on.
pub mod cmd {
    /// Opens a session.
    pub const CONNECT: u8 = 0xFF;
    /// Closes the session.
    pub const DISCONNECT: u8 = 0xFE;
    /// Session and protection status.
    pub const GET_STATUS: u8 = 0xFD;
    /// Resynchronises after a master timeout (answered with ERR_CMD_SYNCH).
    pub const SYNCH: u8 = 0xFC;
    /// Optional communication modes (block mode, MAX_BS, MIN_ST).
    pub const GET_COMM_MODE_INFO: u8 = 0xFB;
    /// Identification (ASCII text, A2L name, EPK).
    pub const GET_ID: u8 = 0xFA;
    /// Requests to store calibration data in non-volatile memory.
    pub const SET_REQUEST: u8 = 0xF9;
    /// Seed for unlocking a protected resource.
    pub const GET_SEED: u8 = 0xF8;
    /// Key for the seed.
    pub const UNLOCK: u8 = 0xF7;
    /// Sets the memory transfer address.
    pub const SET_MTA: u8 = 0xF6;
    /// Reads at the MTA.
    pub const UPLOAD: u8 = 0xF5;
    /// Reads at an address given in the command.
    pub const SHORT_UPLOAD: u8 = 0xF4;
    /// Checksum over a block at the MTA.
    pub const BUILD_CHECKSUM: u8 = 0xF3;
    /// Transport-layer specific command (not supported).
    pub const TRANSPORT_LAYER_CMD: u8 = 0xF2;
    /// User command (not supported).
    pub const USER_CMD: u8 = 0xF1;
    /// Writes at the MTA (first packet of a block in master block mode).
    pub const DOWNLOAD: u8 = 0xF0;
    /// Further packets of a master-block-mode download.
    pub const DOWNLOAD_NEXT: u8 = 0xEF;
    /// Writes MAX_CTO-1 bytes at the MTA (not supported).
    pub const DOWNLOAD_MAX: u8 = 0xEE;
    /// Writes at an address given in the command.
    pub const SHORT_DOWNLOAD: u8 = 0xED;
    /// Bit-wise modification (not supported).
    pub const MODIFY_BITS: u8 = 0xEC;
    /// Selects the ECU's and/or the XCP access page.
    pub const SET_CAL_PAGE: u8 = 0xEB;
    /// Reads the ECU's or the XCP access page.
    pub const GET_CAL_PAGE: u8 = 0xEA;
    /// Number of segments.
    pub const GET_PAG_PROCESSOR_INFO: u8 = 0xE9;
    /// Address, length and pages of a segment.
    pub const GET_SEGMENT_INFO: u8 = 0xE8;
    /// Access rights of a page.
    pub const GET_PAGE_INFO: u8 = 0xE7;
    /// Copies one page onto another.
    pub const COPY_CAL_PAGE: u8 = 0xE4;
    /// Clears a DAQ list's entries.
    pub const CLEAR_DAQ_LIST: u8 = 0xE3;
    /// Points at an ODT entry for WRITE_DAQ.
    pub const SET_DAQ_PTR: u8 = 0xE2;
    /// Writes the ODT entry at the DAQ pointer.
    pub const WRITE_DAQ: u8 = 0xE1;
    /// Event channel, prescaler, timestamp of a DAQ list.
    pub const SET_DAQ_LIST_MODE: u8 = 0xE0;
    /// Reads a DAQ list's mode.
    pub const GET_DAQ_LIST_MODE: u8 = 0xDF;
    /// Starts, stops or selects one DAQ list.
    pub const START_STOP_DAQ_LIST: u8 = 0xDE;
    /// Starts or stops the selected (or all) DAQ lists together.
    pub const START_STOP_SYNCH: u8 = 0xDD;
    /// The slave's DAQ clock.
    pub const GET_DAQ_CLOCK: u8 = 0xDC;
    /// DAQ capabilities.
    pub const GET_DAQ_PROCESSOR_INFO: u8 = 0xDA;
    /// ODT entry sizes and the timestamp format.
    pub const GET_DAQ_RESOLUTION_INFO: u8 = 0xD9;
    /// An event channel's cycle, properties and name.
    pub const GET_DAQ_EVENT_INFO: u8 = 0xD7;
    /// Frees every dynamic DAQ list.
    pub const FREE_DAQ: u8 = 0xD6;
    /// Allocates DAQ lists.
    pub const ALLOC_DAQ: u8 = 0xD5;
    /// Allocates ODTs in a DAQ list.
    pub const ALLOC_ODT: u8 = 0xD4;
    /// Allocates entries in an ODT.
    pub const ALLOC_ODT_ENTRY: u8 = 0xD3;
    /// Prefix of the two-byte commands (GET_VERSION, packed DAQ; not supported).
    pub const LEVEL_1_COMMAND: u8 = 0xC0;

    /// Every command above with its name in the standard: what a tool shows for the last
    /// refused command (the ECU's A2L `xcp.command` table).
    pub const NAMES: [(u8, &str); 43] = [
        (CONNECT, "CONNECT"),
        (DISCONNECT, "DISCONNECT"),
        (GET_STATUS, "GET_STATUS"),
        (SYNCH, "SYNCH"),
        (GET_COMM_MODE_INFO, "GET_COMM_MODE_INFO"),
        (GET_ID, "GET_ID"),
        (SET_REQUEST, "SET_REQUEST"),
        (GET_SEED, "GET_SEED"),
        (UNLOCK, "UNLOCK"),
        (SET_MTA, "SET_MTA"),
        (UPLOAD, "UPLOAD"),
        (SHORT_UPLOAD, "SHORT_UPLOAD"),
        (BUILD_CHECKSUM, "BUILD_CHECKSUM"),
        (TRANSPORT_LAYER_CMD, "TRANSPORT_LAYER_CMD"),
        (USER_CMD, "USER_CMD"),
        (DOWNLOAD, "DOWNLOAD"),
        (DOWNLOAD_NEXT, "DOWNLOAD_NEXT"),
        (DOWNLOAD_MAX, "DOWNLOAD_MAX"),
        (SHORT_DOWNLOAD, "SHORT_DOWNLOAD"),
        (MODIFY_BITS, "MODIFY_BITS"),
        (SET_CAL_PAGE, "SET_CAL_PAGE"),
        (GET_CAL_PAGE, "GET_CAL_PAGE"),
        (GET_PAG_PROCESSOR_INFO, "GET_PAG_PROCESSOR_INFO"),
        (GET_SEGMENT_INFO, "GET_SEGMENT_INFO"),
        (GET_PAGE_INFO, "GET_PAGE_INFO"),
        (COPY_CAL_PAGE, "COPY_CAL_PAGE"),
        (CLEAR_DAQ_LIST, "CLEAR_DAQ_LIST"),
        (SET_DAQ_PTR, "SET_DAQ_PTR"),
        (WRITE_DAQ, "WRITE_DAQ"),
        (SET_DAQ_LIST_MODE, "SET_DAQ_LIST_MODE"),
        (GET_DAQ_LIST_MODE, "GET_DAQ_LIST_MODE"),
        (START_STOP_DAQ_LIST, "START_STOP_DAQ_LIST"),
        (START_STOP_SYNCH, "START_STOP_SYNCH"),
        (GET_DAQ_CLOCK, "GET_DAQ_CLOCK"),
        (GET_DAQ_PROCESSOR_INFO, "GET_DAQ_PROCESSOR_INFO"),
        (GET_DAQ_RESOLUTION_INFO, "GET_DAQ_RESOLUTION_INFO"),
        (GET_DAQ_EVENT_INFO, "GET_DAQ_EVENT_INFO"),
        (FREE_DAQ, "FREE_DAQ"),
        (ALLOC_DAQ, "ALLOC_DAQ"),
        (ALLOC_ODT, "ALLOC_ODT"),
        (ALLOC_ODT_ENTRY, "ALLOC_ODT_ENTRY"),
        (LEVEL_1_COMMAND, "LEVEL_1_COMMAND"),
        (0, "none"),
    ];
}

/// Error codes (second byte of an error packet).
pub mod err {
    /// Answer to SYNCH.
    pub const CMD_SYNCH: u8 = 0x00;
    /// Command not executed, try again (never sent: pyxcp retries it for ever).
    pub const CMD_BUSY: u8 = 0x10;
    /// Rejected because the DAQ list is running.
    pub const DAQ_ACTIVE: u8 = 0x11;
    /// Unknown or unsupported command.
    pub const CMD_UNKNOWN: u8 = 0x20;
    /// Command packet too short, too long or malformed.
    pub const CMD_SYNTAX: u8 = 0x21;
    /// A parameter is out of range.
    pub const OUT_OF_RANGE: u8 = 0x22;
    /// The memory may not be written (now).
    pub const WRITE_PROTECTED: u8 = 0x23;
    /// The address is not accessible.
    pub const ACCESS_DENIED: u8 = 0x24;
    /// Seed and key required.
    pub const ACCESS_LOCKED: u8 = 0x25;
    /// No such page.
    pub const PAGE_NOT_VALID: u8 = 0x26;
    /// No such page mode.
    pub const MODE_NOT_VALID: u8 = 0x27;
    /// No such segment.
    pub const SEGMENT_NOT_VALID: u8 = 0x28;
    /// Command out of the required order.
    pub const SEQUENCE: u8 = 0x29;
    /// The DAQ configuration is not valid (also: it would exceed the bus budget).
    pub const DAQ_CONFIG: u8 = 0x2A;
    /// Not enough DAQ storage.
    pub const MEMORY_OVERFLOW: u8 = 0x30;
    /// The target failed for another reason.
    pub const GENERIC: u8 = 0x31;
    /// The resource is not accessible now, try later (GET_SEED after a wrong key, until the
    /// delay has passed).
    pub const RESOURCE_TEMPORARY_NOT_ACCESSIBLE: u8 = 0x33;

    /// Every error code above with its name in the standard (the ECU's A2L `xcp.error`
    /// table).
    pub const NAMES: [(u8, &str); 17] = [
        (CMD_SYNCH, "ERR_CMD_SYNCH"),
        (CMD_BUSY, "ERR_CMD_BUSY"),
        (DAQ_ACTIVE, "ERR_DAQ_ACTIVE"),
        (CMD_UNKNOWN, "ERR_CMD_UNKNOWN"),
        (CMD_SYNTAX, "ERR_CMD_SYNTAX"),
        (OUT_OF_RANGE, "ERR_OUT_OF_RANGE"),
        (WRITE_PROTECTED, "ERR_WRITE_PROTECTED"),
        (ACCESS_DENIED, "ERR_ACCESS_DENIED"),
        (ACCESS_LOCKED, "ERR_ACCESS_LOCKED"),
        (PAGE_NOT_VALID, "ERR_PAGE_NOT_VALID"),
        (MODE_NOT_VALID, "ERR_MODE_NOT_VALID"),
        (SEGMENT_NOT_VALID, "ERR_SEGMENT_NOT_VALID"),
        (SEQUENCE, "ERR_SEQUENCE"),
        (DAQ_CONFIG, "ERR_DAQ_CONFIG"),
        (MEMORY_OVERFLOW, "ERR_MEMORY_OVERFLOW"),
        (GENERIC, "ERR_GENERIC"),
        (
            RESOURCE_TEMPORARY_NOT_ACCESSIBLE,
            "ERR_RESOURCE_TEMPORARY_NOT_ACCESSIBLE",
        ),
    ];
}

/// Event codes (the byte after [`pid::EV`]).
pub mod ev {
    /// DAQ packets were lost: the bus queue refused them (the overload indication
    /// GET_DAQ_PROCESSOR_INFO announces).
    pub const DAQ_OVERLOAD: u8 = 0x06;
    /// The slave ended the session by itself (idle time-out).
    pub const SESSION_TERMINATED: u8 = 0x07;
}

/// Resource bits (CONNECT's RESOURCE, GET_STATUS's protection status, GET_SEED, UNLOCK).
pub mod resource {
    /// Calibration and page switching.
    pub const CAL_PAG: u8 = 0x01;
    /// Data acquisition.
    pub const DAQ: u8 = 0x04;
    /// Stimulation (not supported).
    pub const STIM: u8 = 0x08;
    /// Flash programming (not supported).
    pub const PGM: u8 = 0x10;
    /// Debugging (not supported).
    pub const DBG: u8 = 0x20;
}

/// Bits of GET_STATUS's session status.
pub mod session {
    /// A STORE_CAL request is pending.
    pub const STORE_CAL_REQ: u8 = 0x01;
    /// At least one DAQ list is running.
    pub const DAQ_RUNNING: u8 = 0x40;
}

/// Bits of CONNECT's COMM_MODE_BASIC.
pub mod comm_mode {
    /// Motorola byte order (clear: Intel, which this slave uses).
    pub const BYTE_ORDER_MOTOROLA: u8 = 0x01;
    /// Slave block mode (not used: one response per UPLOAD).
    pub const SLAVE_BLOCK_MODE: u8 = 0x40;
    /// GET_COMM_MODE_INFO has more to say.
    pub const OPTIONAL: u8 = 0x80;
    /// GET_COMM_MODE_INFO's COMM_MODE_OPTIONAL: master block mode supported.
    pub const MASTER_BLOCK_MODE: u8 = 0x01;
}

/// Page modes of SET_CAL_PAGE / GET_CAL_PAGE.
pub mod page_mode {
    /// The page the ECU's application uses.
    pub const ECU: u8 = 0x01;
    /// The page the XCP driver reads and writes.
    pub const XCP: u8 = 0x02;
    /// Every segment (the segment number is ignored).
    pub const ALL: u8 = 0x80;
}

/// GET_ID identification types the slave answers.
pub mod id_type {
    /// ASCII text describing the slave.
    pub const ASCII: u8 = 0;
    /// ASAM-MC2 (A2L) file name without path and extension.
    pub const A2L_NAME: u8 = 1;
    /// The EPK (software version of the calibration layout), XCP 1.3+.
    pub const EPK: u8 = 5;
}

/// Bits of a DAQ list's mode (SET_DAQ_LIST_MODE and GET_DAQ_LIST_MODE).
pub mod daq_mode {
    /// Alternating display (not supported).
    pub const ALTERNATING: u8 = 0x01;
    /// STIM direction (not supported).
    pub const DIRECTION_STIM: u8 = 0x02;
    /// DTO counter (not supported).
    pub const DTO_CTR: u8 = 0x08;
    /// The first ODT carries a timestamp.
    pub const TIMESTAMP: u8 = 0x10;
    /// DTOs without identification field (not supported).
    pub const PID_OFF: u8 = 0x20;
    /// GET_DAQ_LIST_MODE: the list is selected.
    pub const SELECTED: u8 = 0x01;
    /// GET_DAQ_LIST_MODE: the list is running.
    pub const RUNNING: u8 = 0x40;
}

/// Checksum types of BUILD_CHECKSUM.
pub mod checksum_type {
    /// CRC-16 CCITT: polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR.
    pub const CRC_16_CITT: u8 = 0x08;
}

/// Timestamp and event-cycle units (GET_DAQ_RESOLUTION_INFO and GET_DAQ_EVENT_INFO).
pub mod time_unit {
    /// One microsecond.
    pub const US_1: u8 = 3;
    /// One second (the largest unit an event cycle is expressed in).
    pub const S_1: u8 = 9;
}
