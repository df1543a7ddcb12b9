//! Torque limits: motor maximum, accumulator power (80 kW, EV.3.3.1) and SOC derating
//! (linear from 20 % to 0 at 5 %), as in the team's `PowerLimit_Update`.

use crate::config::{MOTOR_MAX_TORQUE_NM, POWER_LIMIT_W, SOC_DERATE_END, SOC_DERATE_START};

/// The limits `limit_torque` applies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PowerLimits {
    /// Largest torque ever commanded (Nm).
    pub max_torque_nm: f32,
    /// Electrical power limit (W, pack voltage x current).
    pub power_limit_w: f32,
    /// SOC (0..1) where derating starts, and where torque reaches zero.
    pub soc_derate: (f32, f32),
}

impl PowerLimits {
    /// The car: 260 Nm, 80 kW, derating 20 % -> 5 %.
    pub const CAR: Self = Self {
        max_torque_nm: MOTOR_MAX_TORQUE_NM,
        power_limit_w: POWER_LIMIT_W,
        soc_derate: (SOC_DERATE_START, SOC_DERATE_END),
    };

    /// The torque allowed for a `demand_nm` at `soc` (0..1) while the pack delivers
    /// `voltage_v` x `current_a`. Never negative, never above the motor maximum.
    ///
    /// Power is limited by scaling the demand by limit / power once the measured power
    /// exceeds the limit (torque is taken as proportional to power at a given speed).
    pub fn limit_torque(&self, soc: f32, voltage_v: f32, current_a: f32, demand_nm: f32) -> f32 {
        let demand = if demand_nm.is_finite() {
            demand_nm
        } else {
            0.0
        };
        let mut torque = demand.max(0.0).min(self.max_torque_nm);
        let (start, end) = self.soc_derate;
        // A SOC that is not a number cannot vouch for the pack: no torque.
        let soc = if soc.is_finite() { soc } else { end };
        if soc < start {
            torque *= ((soc - end) / (start - end)).clamp(0.0, 1.0);
        }
        let power = voltage_v * current_a;
        if power.is_finite() && power > self.power_limit_w {
            torque *= self.power_limit_w / power;
        }
        torque.max(0.0).min(self.max_torque_nm)
    }
}
