//! Torque limits: motor maximum, SOC derating (linear from 20 % to 0 at 5 %) and the
//! accumulator power limit (80 kW, EV.3.3.1).
//!
//! Power is limited by a torque ceiling from the motor speed, T <= k x P_target / omega,
//! where k is an estimate of the drivetrain's efficiency (battery DC power to shaft power).
//! k starts at the lowest efficiency the drivetrain can have, so the ceiling alone already
//! keeps the power at or below the target whatever the true efficiency is, without waiting
//! for a measurement. An integrating trim on the measured DC power then raises k towards
//! the true efficiency (so no lap time is thrown away) and lowers it again if the power
//! goes above the target; while the ceiling does not bind, k returns to the safe lowest
//! value.
//!
//! The trim only raises k once the measurement has caught up with the ceiling: it reads at
//! least what the ceiling gives at the highest efficiency, and moved by less than 1 % of the
//! target since the last step. Right after the pedal goes down the measurement still lags
//! the torque, and integrating that gap would wind k up past the true efficiency and
//! overshoot the limit once the measurement catches up. Lowering k is never held back.
//!
//! The team's `PowerLimit_Update` scaled the demand by limit / measured power instead. The
//! measured power is produced by the previous, already limited command, so in closed loop
//! that settles near sqrt(demand x limit), above the limit (87-115 kW at 3,300-5,000 rpm).

use crate::constants::{
    DRIVETRAIN_EFFICIENCY, MOTOR_MAX_TORQUE_NM, POWER_CEILING_MIN_RAD_S, POWER_LIMIT_MARGIN,
    POWER_LIMIT_W, POWER_SETTLED_FRACTION, POWER_TRIM_FLOOR, POWER_TRIM_RELAX_S, SOC_DERATE_END,
    SOC_DERATE_START,
};

/// The fixed limits, one set for the limiter and the torque monitor alike: motor maximum,
/// the rule's power limit and the limiter's target below it, SOC derating. Built from
/// `aer-params` ([`PowerLimits::CAR`]); a lower limit (an endurance power cap) is
/// [`PowerLimits::for_rule`] with that limit, and everything that depends on it follows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PowerLimits {
    /// Largest torque ever commanded (Nm).
    pub max_torque_nm: f32,
    /// Tractive power the accumulator may deliver (W): the rule (EV.3.3.1), which the torque
    /// monitor bounds on its own.
    pub power_limit_w: f32,
    /// DC power the limiter holds the car at (W, pack voltage x current): the limit less
    /// [`POWER_LIMIT_MARGIN`].
    pub power_target_w: f32,
    /// SOC (0..1) where derating starts, and where torque reaches zero.
    pub soc_derate: (f32, f32),
}

impl PowerLimits {
    /// The car: 260 Nm, the rule's 80 kW with the limiter 2.5 % below it, derating
    /// 20 % -> 5 %.
    pub const CAR: Self = Self::for_rule(POWER_LIMIT_W);

    /// The car's limits with the accumulator's power limited to `power_limit_w`.
    pub const fn for_rule(power_limit_w: f32) -> Self {
        Self {
            max_torque_nm: MOTOR_MAX_TORQUE_NM,
            power_limit_w,
            power_target_w: power_limit_w * (1.0 - POWER_LIMIT_MARGIN),
            soc_derate: (SOC_DERATE_START, SOC_DERATE_END),
        }
    }

    /// The fraction of the motor maximum allowed at `soc` (0..1): 1 above the start of the
    /// derating, 0 at and below its end, linear between. A SOC that is not a number cannot
    /// vouch for the pack: 0.
    pub fn soc_factor(&self, soc: f32) -> f32 {
        let (start, end) = self.soc_derate;
        if !soc.is_finite() {
            return 0.0;
        }
        ((soc - end) / (start - end)).clamp(0.0, 1.0)
    }

    /// `demand_nm` within 0..motor maximum, scaled by the SOC factor (the team's
    /// `PowerLimit_Update` derating). Never negative.
    pub fn soc_limited(&self, soc: f32, demand_nm: f32) -> f32 {
        let demand = if demand_nm.is_finite() {
            demand_nm
        } else {
            0.0
        };
        demand.max(0.0).min(self.max_torque_nm) * self.soc_factor(soc)
    }
}

// The limiter aims below the rule by a small, positive margin.
const _: () = assert!(
    PowerLimits::CAR.power_target_w < PowerLimits::CAR.power_limit_w
        && PowerLimits::CAR.power_target_w > 0.9 * PowerLimits::CAR.power_limit_w
);

/// The power ceiling and its trim.
#[derive(Debug, Clone, PartialEq)]
pub struct PowerLimiter {
    period_s: f32,
    /// The DC power it holds the car at (W).
    target_w: f32,
    /// Efficiency estimate k, within `DRIVETRAIN_EFFICIENCY`.
    efficiency: f32,
    /// The measured power of the last step (W).
    last_measured_w: f32,
}

impl PowerLimiter {
    /// A limiter stepped every `period_ms` that holds the DC power at `target_w`, starting at
    /// the lowest efficiency.
    pub fn new(period_ms: u32, target_w: f32) -> Self {
        Self {
            period_s: period_ms as f32 / 1_000.0,
            target_w,
            efficiency: DRIVETRAIN_EFFICIENCY.0,
            last_measured_w: f32::NAN,
        }
    }

    /// The current efficiency estimate.
    pub fn efficiency(&self) -> f32 {
        self.efficiency
    }

    /// One control step: the torque ceiling (Nm) for motor speed `motor_rad_s`, after
    /// trimming with the DC power measured now (`measured_w`, battery to inverter) while the
    /// driver asks for `demand_nm`; the trim moves at `trim_gain` (per second, on the relative
    /// power error: the calibration's `power_trim_gain`).
    pub fn step(
        &mut self,
        trim_gain: f32,
        motor_rad_s: f32,
        measured_w: f32,
        demand_nm: f32,
    ) -> f32 {
        let target = self.target_w;
        let ceiling_before = ceiling(self.efficiency, target, motor_rad_s);
        let binds = demand_nm >= ceiling_before;
        let (low, high) = DRIVETRAIN_EFFICIENCY;
        // At steady state under the ceiling the measurement reads at least low / high of the
        // target (k >= low, true efficiency <= high); below that it has not caught up yet.
        let caught_up = measured_w >= POWER_TRIM_FLOOR * low / high * target
            && (measured_w - self.last_measured_w).abs() <= POWER_SETTLED_FRACTION * target;
        self.last_measured_w = measured_w;
        let error = (target - measured_w) / target;
        if measured_w > target || (binds && caught_up && error.is_finite()) {
            self.efficiency += trim_gain * error * self.period_s;
        } else if !binds || !measured_w.is_finite() {
            let relax = (self.period_s / POWER_TRIM_RELAX_S).min(1.0);
            self.efficiency += (low - self.efficiency) * relax;
        }
        self.efficiency = self.efficiency.clamp(low, high);
        ceiling(self.efficiency, target, motor_rad_s)
    }
}

/// The shaft torque (Nm) that draws `power_w` from the battery at `efficiency` and motor
/// speed `motor_rad_s` (taken as at least [`POWER_CEILING_MIN_RAD_S`]).
pub fn ceiling(efficiency: f32, power_w: f32, motor_rad_s: f32) -> f32 {
    let speed = if motor_rad_s.is_finite() {
        motor_rad_s.abs().max(POWER_CEILING_MIN_RAD_S)
    } else {
        // A speed that is not a number: as if the motor were at its fastest, no torque.
        f32::INFINITY
    };
    efficiency * power_w / speed
}
