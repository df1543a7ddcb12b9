//! The precharge controller's state and latched error causes, as sent in PCC_Status.

/// Precharge controller state, as sent in PCC_Status.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum State {
    /// Waiting for the shutdown circuit, the pack voltage and the BMS.
    Standby,
    /// Charging the tractive system through the precharge resistor.
    Precharge,
    /// Relays open, tractive system discharging after the pack went away.
    Discharge,
    /// Precharge complete, AIR+ closed: ready to drive.
    Online,
    /// Precharge complete with the BMS's charger safety on: connected for charging.
    Charging,
    /// A fault: AIR+ open.
    Error,
}

impl State {
    /// The schema's value for this state.
    pub const fn to_wire(self) -> aer::can::PrechargeState {
        use aer::can::PrechargeState as Wire;
        match self {
            Self::Standby => Wire::Standby,
            Self::Precharge => Wire::Precharge,
            Self::Discharge => Wire::Discharge,
            Self::Online => Wire::Online,
            Self::Charging => Wire::Charging,
            Self::Error => Wire::Error,
        }
    }

    /// True in the states where the accumulator may be connected to the tractive system.
    pub const fn is_energised(self) -> bool {
        matches!(self, Self::Precharge | Self::Online | Self::Charging)
    }
}

/// Latched error causes, as sent in PCC_Status.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Errors {
    /// 0x01: the target was reached before the minimum time.
    pub too_fast: bool,
    /// 0x02: the target was not reached within the maximum time.
    pub too_slow: bool,
    /// 0x04: no BMS frame for the timeout while energised.
    pub bms_timeout: bool,
    /// 0x08: the tractive system fell away from the pack while energised: the shutdown
    /// circuit opened (it drops AIR- and the precharge relay) or the tractive system is
    /// loaded down.
    pub shutdown: bool,
    /// 0x10: the accumulator's converter (pin 14) fell silent after reading 60 V or more, or
    /// while the PCC was energised or discharging: its voltage is unknown.
    pub accumulator_silent: bool,
    /// 0x20: the tractive system's converter (pin 15) fell silent the same way: the tractive
    /// system may be live while the PCC cannot see it.
    pub tractive_silent: bool,
    /// 0x40: the tractive system did not fall below 60 V within the discharge time after it
    /// began to fall: an AIR welded or the discharge circuit failed.
    pub no_discharge: bool,
    /// 0x80: the PCC restarted after its watchdog expired (a hang or a panic), so the state
    /// it was in is not known.
    pub undefined_state: bool,
    /// The precharge reached the target faster than the resistor allows: AIR+ welded or the
    /// precharge resistor bypassed (set with `too_fast`).
    pub bypassed: bool,
    /// A precharge-resistor thermistor read the resistor's limit or more.
    pub resistor_hot: bool,
    /// AIR+ was commanded closed but the tractive system did not reach the online minimum of
    /// the pack within the close time: AIR+, its coil, its driver or its supply.
    pub air_plus_open: bool,
    /// While energised the tractive system read above the accumulator by more than the
    /// converters can disagree: a scaling or divider changed, neither reading is trusted.
    pub converters_disagree: bool,
}

impl Errors {
    /// True when a cause other than the shutdown input is latched (those need a power
    /// cycle, after the cause is found).
    pub const fn needs_reset(&self) -> bool {
        self.too_fast
            || self.too_slow
            || self.bms_timeout
            || self.accumulator_silent
            || self.tractive_silent
            || self.no_discharge
            || self.undefined_state
            || self.bypassed
            || self.resistor_hot
            || self.air_plus_open
            || self.converters_disagree
    }

    /// True when any cause is latched.
    pub const fn any(&self) -> bool {
        self.needs_reset() || self.shutdown
    }

    /// True when a converter's silence is latched.
    pub const fn converter_silent(&self) -> bool {
        self.accumulator_silent || self.tractive_silent
    }
}

impl core::fmt::Display for Errors {
    /// The latched causes by name (`none` when clear), as the console logs them.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let causes = [
            (self.too_fast, "too-fast"),
            (
                self.bypassed,
                "bypassed (AIR+ welded or the precharge resistor bypassed)",
            ),
            (self.too_slow, "too-slow"),
            (self.bms_timeout, "bms-timeout"),
            (self.shutdown, "shutdown"),
            (self.air_plus_open, "air-plus-open (AIR+ did not close)"),
            (
                self.converters_disagree,
                "converters-disagree (the tractive system read above the pack)",
            ),
            (self.accumulator_silent, "accumulator-converter-silent"),
            (self.tractive_silent, "tractive-converter-silent"),
            (self.no_discharge, "no-discharge"),
            (self.resistor_hot, "resistor-hot"),
            (self.undefined_state, "undefined-state (watchdog reset)"),
        ];
        let mut first = true;
        for (_, name) in causes.iter().filter(|(latched, _)| *latched) {
            f.write_str(if first { "" } else { ", " })?;
            f.write_str(name)?;
            first = false;
        }
        if first {
            f.write_str("none")?;
        }
        Ok(())
    }
}
