//! Duty-cycle outputs on a FlexPWM submodule (imxrt-hal 0.6 offers only the registers).

use teensy4_bsp::board;
use teensy4_bsp::hal::flexpwm::{
    self, Channel, ClockSelect, LoadMode, PairOperation, Prescaler, Pwm, SM,
};

/// One submodule counting from 0 to `period - 1` on the IPG clock.
pub struct PwmBlock {
    pwm: Pwm,
    sm: SM,
    period: i16,
}

impl PwmBlock {
    /// Configures and starts `sm` at about `hz`, outputs off, with the smallest prescaler
    /// whose period fits the 16-bit counter. Returns `None` when `hz` needs more than 32,767
    /// counts even at a prescaler of 128.
    pub fn new(mut pwm: Pwm, sm: SM, hz: u32) -> Option<Self> {
        const PRESCALERS: [(Prescaler, u32); 8] = [
            (Prescaler::Prescaler1, 1),
            (Prescaler::Prescaler2, 2),
            (Prescaler::Prescaler4, 4),
            (Prescaler::Prescaler8, 8),
            (Prescaler::Prescaler16, 16),
            (Prescaler::Prescaler32, 32),
            (Prescaler::Prescaler64, 64),
            (Prescaler::Prescaler128, 128),
        ];
        let counts = board::IPG_FREQUENCY.checked_div(hz)?;
        let (prescaler, period) = PRESCALERS.iter().find_map(|&(prescaler, divider)| {
            i16::try_from(counts / divider)
                .ok()
                .map(|period| (prescaler, period))
        })?;
        pwm.set_debug_enable(sm, true);
        pwm.set_wait_enable(sm, true);
        pwm.set_clock_select(sm, ClockSelect::Ipg);
        pwm.set_prescaler(sm, prescaler);
        pwm.set_pair_operation(sm, PairOperation::Independent);
        pwm.set_load_mode(sm, LoadMode::reload_full());
        pwm.set_load_frequency(sm, 1);
        pwm.set_initial_count(sm, 0);
        pwm.set_value(sm, flexpwm::FULL_RELOAD_VALUE_REGISTER, period - 1);
        let mut block = Self { pwm, sm, period };
        for channel in [Channel::A, Channel::B] {
            block.set_duty(channel, 0.0);
        }
        block.pwm.set_output_enable(sm.mask(), Channel::A);
        block.pwm.set_output_enable(sm.mask(), Channel::B);
        block.pwm.set_load_ok(sm.mask());
        block.pwm.set_run(sm.mask());
        Some(block)
    }

    /// Sets `channel`'s duty (0..1, clamped; NaN = off) from the next period on.
    pub fn set_duty(&mut self, channel: Channel, duty: f32) {
        let duty = if duty.is_finite() {
            duty.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let off = (f32::from(self.period) * duty) as i16;
        self.pwm.set_turn_on(self.sm, channel, 0);
        self.pwm.set_turn_off(self.sm, channel, off);
        self.pwm.set_load_ok(self.sm.mask());
    }
}
