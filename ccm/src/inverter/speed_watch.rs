//! The motor speed the inverter reports, checked against the front wheels. Under drive torque
//! the driven wheels turn at least as fast as the free-rolling front ones (slip is not
//! negative); a motor that reads far slower while torque is commanded and the car rolls is a
//! reading the CCM cannot trust: a DTI whose status froze (its packets carry no counter, so
//! they look fresh) would otherwise keep the power bound at the speed it froze at. A reading
//! that stays bit for bit the same while the front wheels speed up under torque is frozen too,
//! whatever its value.

use crate::constants::{
    GEAR_RATIO, SPEED_FROZEN_CHANGE, SPEED_FROZEN_FROM_RAD_S, SPEED_FROZEN_MS, SPEED_IMPLAUSIBLE,
    SPEED_IMPLAUSIBLE_MS, SPEED_WATCH_MIN_TORQUE_NM,
};
use aer_control::Persist;

/// Whether the reported motor speed has contradicted the wheels for too long.
#[derive(Debug, Clone, Default)]
pub struct SpeedWatch {
    contradicting: Persist,
    /// The reading's bits, since when it has not changed, and the slower front wheel then.
    unchanged: Option<(u32, u32, f32)>,
}

impl SpeedWatch {
    /// True once, with at least [`SPEED_WATCH_MIN_TORQUE_NM`] commanded, the driven wheels'
    /// speed from the reported motor speed stays below a tier of [`SPEED_IMPLAUSIBLE`] (a
    /// share of the slower front wheel, above that tier's speed) for [`SPEED_IMPLAUSIBLE_MS`].
    /// Braking (no torque) and a car at rest never trip it; an unknown motor speed is the
    /// inverter timeout's to judge.
    pub fn implausible(
        &mut self,
        motor_rad_s: Option<f32>,
        front_rad_s: (f32, f32),
        torque_commanded_nm: f32,
        now_ms: u32,
    ) -> bool {
        let free = front_rad_s.0.min(front_rad_s.1);
        let contradicting = motor_rad_s.is_some_and(|motor| {
            let driven = motor.abs() / GEAR_RATIO;
            torque_commanded_nm >= SPEED_WATCH_MIN_TORQUE_NM
                && SPEED_IMPLAUSIBLE
                    .iter()
                    .any(|&(from_rad_s, share)| free >= from_rad_s && driven < share * free)
        });
        let contradicted = self
            .contradicting
            .update(contradicting, now_ms)
            .is_some_and(|held| held >= SPEED_IMPLAUSIBLE_MS);
        contradicted || self.frozen(motor_rad_s, free, torque_commanded_nm, now_ms)
    }

    /// The reading has not changed for [`SPEED_FROZEN_MS`] while the slower front wheel
    /// changed by more than [`SPEED_FROZEN_CHANGE`] under torque.
    fn frozen(&mut self, motor_rad_s: Option<f32>, free: f32, torque_nm: f32, now_ms: u32) -> bool {
        let Some(motor) = motor_rad_s else {
            self.unchanged = None;
            return false;
        };
        match self.unchanged {
            Some((bits, since_ms, free_then)) if bits == motor.to_bits() => {
                // Slow wheels are timed over few pulses: their noise is no evidence.
                torque_nm >= SPEED_WATCH_MIN_TORQUE_NM
                    && free_then >= SPEED_FROZEN_FROM_RAD_S
                    && now_ms.wrapping_sub(since_ms) >= SPEED_FROZEN_MS
                    && (free - free_then).abs() > SPEED_FROZEN_CHANGE * free_then
            }
            _ => {
                self.unchanged = Some((motor.to_bits(), now_ms, free));
                false
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frozen_motor_speed_under_torque_trips_after_the_limit() {
        let mut watch = SpeedWatch::default();
        let front = (20.0, 20.0);
        assert!(!watch.implausible(Some(0.0), front, 200.0, 0));
        assert!(!watch.implausible(Some(0.0), front, 200.0, SPEED_IMPLAUSIBLE_MS - 10));
        assert!(watch.implausible(Some(0.0), front, 200.0, SPEED_IMPLAUSIBLE_MS));
    }

    #[test]
    fn a_reading_frozen_at_speed_trips_once_the_car_is_10_percent_faster() {
        let mut watch = SpeedWatch::default();
        // A reading that still moves a little (not frozen) but stays low.
        let low = |now: u32| Some(40.0 * GEAR_RATIO + now as f32 * 1e-3);
        assert!(!watch.implausible(low(0), (42.0, 42.0), 200.0, 0));
        assert!(!watch.implausible(low(100), (45.0, 45.0), 200.0, 100));
        let limit = 100 + SPEED_IMPLAUSIBLE_MS;
        assert!(!watch.implausible(low(limit - 10), (45.0, 45.0), 200.0, limit - 10));
        assert!(watch.implausible(low(limit), (45.0, 45.0), 200.0, limit));
    }

    #[test]
    fn a_reading_that_stops_changing_while_the_car_speeds_up_is_frozen() {
        let mut watch = SpeedWatch::default();
        let frozen = Some(40.0 * GEAR_RATIO * 1.1);
        assert!(!watch.implausible(frozen, (40.0, 40.0), 200.0, 0));
        assert!(!watch.implausible(frozen, (40.5, 40.5), 200.0, SPEED_FROZEN_MS));
        assert!(watch.implausible(frozen, (42.0, 42.0), 200.0, SPEED_FROZEN_MS + 10));
        // A steady speed with a steady reading (the skidpad) is not frozen.
        let mut steady = SpeedWatch::default();
        for now in (0..2_000).step_by(10) {
            assert!(!steady.implausible(frozen, (40.0, 40.0), 50.0, now));
        }
    }

    #[test]
    fn slip_braking_rest_slow_wheels_and_an_unknown_speed_never_trip_it() {
        let front = (20.0, 20.0);
        let cases: [(Option<f32>, (f32, f32), f32); 4] = [
            // Driving with slip: the motor turns faster than the front wheels.
            (Some(20.0 * GEAR_RATIO * 1.2), front, 200.0),
            // Braking: rear wheels locked, no torque.
            (Some(0.0), front, 0.0),
            // At rest.
            (Some(0.0), (0.0, 0.0), 200.0),
            // Unknown.
            (None, front, 200.0),
        ];
        for (motor, front, torque) in cases {
            let mut watch = SpeedWatch::default();
            for now in (0..2_000).step_by(10) {
                assert!(
                    !watch.implausible(motor, front, torque, now),
                    "{motor:?} {front:?}"
                );
            }
        }
        // Slow, noisy wheels under an unchanged reading.
        let mut watch = SpeedWatch::default();
        for now in (0..2_000).step_by(10) {
            let noisy = 4.0 + (now % 30) as f32 * 0.05;
            assert!(!watch.implausible(Some(4.5 * GEAR_RATIO), (noisy, noisy), 100.0, now));
        }
    }
}
