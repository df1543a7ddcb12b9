//! What the last refusal was, in numbers a calibration tool can show: the command, the error
//! code, and why (a [`reason`], the item and element it concerns, the value and the limit).
//! The ECU publishes [`LastRefusal`] as measurements (its A2L names the reasons and items in
//! value tables), so CANape and pyxcp users read the reason a tuner reads on the Pi.

/// Why a command was refused, beyond its error code. The numbers are part of the ECU's
/// description (its A2L's `xcp.reason` table): never renumber one.
pub mod reason {
    /// No detail.
    pub const NONE: u8 = 0;
    /// A value below its limit (`value`, `limit` = the minimum).
    pub const BELOW_MIN: u8 = 1;
    /// A value above its limit (`value`, `limit` = the maximum).
    pub const ABOVE_MAX: u8 = 2;
    /// Not a normal number: NaN, infinite, or subnormal (`value`).
    pub const NOT_A_NUMBER: u8 = 3;
    /// An element not above the one before it, in a list that must increase (`value`,
    /// `limit` = the element before).
    pub const NOT_INCREASING: u8 = 4;
    /// A cross-check between values failed (a sensor's ends too close, say: `value` the span,
    /// `limit` the least allowed).
    pub const CROSS_CHECK: u8 = 5;
    /// The item may change only with the car at standstill.
    pub const NEEDS_STANDSTILL: u8 = 6;
    /// The item may change only with the car stopped and the tractive system off.
    pub const NEEDS_TRACTIVE_OFF: u8 = 7;
    /// The memory is read-only (a measurement, the reference page, the EPK).
    pub const READ_ONLY: u8 = 8;
    /// The address lies outside every table the ECU exposes.
    pub const NOT_MAPPED: u8 = 9;
    /// Calibration is locked: seed and key first.
    pub const LOCKED: u8 = 10;
    /// A wrong key: the session ended.
    pub const WRONG_KEY: u8 = 11;
    /// Too soon after a wrong key (`value` = seconds still to wait).
    pub const TOO_SOON: u8 = 12;
    /// The DAQ lists would need more DTO frames per second than the bus budget leaves
    /// (`value` = frames/s they need, `limit` = frames/s DAQ may use).
    pub const DAQ_BUDGET: u8 = 16;
    /// An ODT entry does not fit what is left of its ODT (`value` = bytes asked, `limit` =
    /// bytes left; a timestamp takes 4 bytes of the first ODT).
    pub const ODT_FULL: u8 = 17;
    /// No more DAQ lists, ODTs or entries (`value` = asked, `limit` = available).
    pub const DAQ_STORAGE: u8 = 18;
    /// A DAQ list without an event channel, or on a sporadic one, cannot start.
    pub const NO_EVENT: u8 = 19;
    /// Saving is refused now (`limit` carries nothing): standstill with the tractive system
    /// off only.
    pub const SAVE_NOT_NOW: u8 = 20;

    /// Every reason with its text, as the ECU's A2L value table has them.
    pub const ALL: [(u8, &str); 18] = [
        (NONE, "none"),
        (BELOW_MIN, "below its minimum"),
        (ABOVE_MAX, "above its maximum"),
        (NOT_A_NUMBER, "not a normal number"),
        (NOT_INCREASING, "not above the element before"),
        (CROSS_CHECK, "a cross-check failed"),
        (NEEDS_STANDSTILL, "only at standstill"),
        (NEEDS_TRACTIVE_OFF, "only with the tractive system off"),
        (READ_ONLY, "read-only"),
        (NOT_MAPPED, "not mapped"),
        (LOCKED, "calibration locked (seed and key)"),
        (WRONG_KEY, "wrong key"),
        (TOO_SOON, "too soon after a wrong key"),
        (DAQ_BUDGET, "DAQ frame budget"),
        (ODT_FULL, "ODT full"),
        (DAQ_STORAGE, "no DAQ storage left"),
        (NO_EVENT, "no periodic event channel"),
        (SAVE_NOT_NOW, "save only at standstill, tractive system off"),
    ];
}

/// The detail of a refusal (see [`reason`]); the default names no reason and no item.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detail {
    /// Why ([`reason`]).
    pub reason: u8,
    /// What it concerns: the ECU's parameter index (its A2L's `xcp.item` table), or 0xFFFF.
    pub item: u16,
    /// Which element of the item.
    pub element: u8,
    /// The value refused (or what the reason says).
    pub value: f32,
    /// The limit it met (or what the reason says).
    pub limit: f32,
}

impl Default for Detail {
    fn default() -> Self {
        Self::of(reason::NONE, 0.0, 0.0)
    }
}

impl Detail {
    /// No item.
    pub const NO_ITEM: u16 = 0xFFFF;

    /// A detail that concerns no item.
    pub const fn of(reason: u8, value: f32, limit: f32) -> Self {
        Self {
            reason,
            item: Self::NO_ITEM,
            element: 0,
            value,
            limit,
        }
    }
}

/// The last refused command: what the ECU publishes (see the module's description).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LastRefusal {
    /// Refusals since start-up (wraps); a tool sees a new refusal by this changing.
    pub count: u32,
    /// The refused command's code (0 before the first).
    pub command: u8,
    /// The XCP error code answered.
    pub error: u8,
    /// Why.
    pub detail: Detail,
}

/// Bytes of [`LastRefusal::to_bytes`].
pub const LAST_REFUSAL_LEN: usize = 20;

impl LastRefusal {
    /// Little-endian, 20 bytes: count (u32), command, error, reason, element (u8 each), item
    /// (u16), 2 bytes of padding, value (f32), limit (f32).
    pub fn to_bytes(&self) -> [u8; LAST_REFUSAL_LEN] {
        let [c0, c1, c2, c3] = self.count.to_le_bytes();
        let [i0, i1] = self.detail.item.to_le_bytes();
        let [v0, v1, v2, v3] = self.detail.value.to_le_bytes();
        let [l0, l1, l2, l3] = self.detail.limit.to_le_bytes();
        [
            c0,
            c1,
            c2,
            c3,
            self.command,
            self.error,
            self.detail.reason,
            self.detail.element,
            i0,
            i1,
            0,
            0,
            v0,
            v1,
            v2,
            v3,
            l0,
            l1,
            l2,
            l3,
        ]
    }
}
