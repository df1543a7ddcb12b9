//! Longitudinal vehicle dynamics: motor torque through the gear to the rear wheels, a tyre
//! slip curve with load transfer, drag, rolling resistance and brakes. The front wheels roll
//! freely at the car's speed; the rear wheels spin up when the torque exceeds the grip.
//!
//! A dynamometer mode holds the motor at a fixed speed instead, for power-limit cases that
//! must hold a speed whatever the torque.

use crate::params::chassis::{
    AIR_DENSITY, BRAKE_N_PER_PSI, CG_HEIGHT_M, DRAG_AREA_M2, GRAVITY, REAR_BRAKE_SHARE,
    REAR_INERTIA_KG_M2, REAR_WEIGHT_SHARE, ROLLING_RESISTANCE, TYRE_PEAK_MU, TYRE_PEAK_SLIP,
    TYRE_SLIDE_MU, WHEELBASE_M,
};
use aer_params::{GEAR_RATIO, VEHICLE_MASS_KG, WHEEL_RADIUS_M};

/// Below this speed (m/s) slip is computed against this speed, so it stays finite at rest.
const SLIP_REFERENCE_MIN_M_S: f32 = 0.5;

/// How the car moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mode {
    /// On the road.
    Road,
    /// On a dynamometer holding the motor at this speed (rpm).
    Dyno {
        /// Motor speed held (rpm).
        rpm: f32,
    },
}

/// The chassis' state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chassis {
    /// How it moves.
    pub mode: Mode,
    /// Car speed (m/s).
    pub speed_m_s: f32,
    /// Rear wheel speed (rad/s).
    pub rear_rad_s: f32,
    /// Distance travelled (m).
    pub distance_m: f32,
    /// Longitudinal acceleration (m/s^2).
    pub accel_m_s2: f32,
    /// Rear tyre slip ratio.
    pub slip: f32,
}

impl Chassis {
    /// A car at rest in `mode`.
    pub fn new(mode: Mode) -> Self {
        let mut chassis = Self {
            mode,
            speed_m_s: 0.0,
            rear_rad_s: 0.0,
            distance_m: 0.0,
            accel_m_s2: 0.0,
            slip: 0.0,
        };
        if let Mode::Dyno { rpm } = mode {
            chassis.rear_rad_s = aer_params::motor_rad_s(rpm) / GEAR_RATIO;
            chassis.speed_m_s = chassis.rear_rad_s * WHEEL_RADIUS_M;
        }
        chassis
    }

    /// Motor speed (rpm).
    pub fn motor_rpm(&self) -> f32 {
        self.rear_rad_s * GEAR_RATIO * 60.0 / core::f32::consts::TAU
    }

    /// Motor speed (rad/s).
    pub fn motor_rad_s(&self) -> f32 {
        self.rear_rad_s * GEAR_RATIO
    }

    /// Front wheel speed (rad/s): free rolling.
    pub fn front_rad_s(&self) -> f32 {
        self.speed_m_s / WHEEL_RADIUS_M
    }

    /// Advances by `dt_s` with `motor_torque_nm` at the motor and `brake_psi` in the front
    /// brake circuit.
    pub fn step(&mut self, motor_torque_nm: f32, brake_psi: f32, dt_s: f32) {
        if let Mode::Dyno { .. } = self.mode {
            self.accel_m_s2 = 0.0;
            self.distance_m += self.speed_m_s * dt_s;
            return;
        }
        let mass = VEHICLE_MASS_KG;
        let radius = WHEEL_RADIUS_M;
        let v = self.speed_m_s;
        let resistance = if v > 0.01 {
            0.5 * AIR_DENSITY * DRAG_AREA_M2 * v * v + ROLLING_RESISTANCE * mass * GRAVITY
        } else {
            0.0
        };
        let brake = brake_psi.max(0.0) * BRAKE_N_PER_PSI;
        let rear_brake = brake * REAR_BRAKE_SHARE / (1.0 + REAR_BRAKE_SHARE);
        let front_brake = brake - rear_brake;
        let wheel_torque = motor_torque_nm * GEAR_RATIO;
        let normal_rear = (mass * GRAVITY * REAR_WEIGHT_SHARE
            + mass * self.accel_m_s2 * CG_HEIGHT_M / WHEELBASE_M)
            .max(0.0);
        let grip = TYRE_PEAK_MU * normal_rear;

        // Rolling with the car: the tyre force that keeps the rear wheel at the car's speed.
        let rolling_accel = (wheel_torque / radius - resistance - front_brake - rear_brake)
            / (mass + REAR_INERTIA_KG_M2 / (radius * radius));
        let rolling_force = mass * rolling_accel + resistance + front_brake;
        let spinning = self.slip > TYRE_PEAK_SLIP * 1.05;
        let (force, wheel_accel) = if !spinning && rolling_force.abs() <= grip {
            (rolling_force, None)
        } else {
            // Beyond the grip: the wheel turns on its own, the tyre gives its sliding force.
            let direction = if self.slip >= 0.0 { 1.0 } else { -1.0 };
            let force = direction * tyre_mu(self.slip.abs()) * normal_rear;
            let wheel = (wheel_torque - force * radius - rear_brake * radius) / REAR_INERTIA_KG_M2;
            (force, Some(wheel))
        };
        let accel = (force - resistance - front_brake) / mass;
        self.speed_m_s = (v + accel * dt_s).max(0.0);
        self.accel_m_s2 = if self.speed_m_s > 0.0 { accel } else { 0.0 };
        let reference = self.speed_m_s.max(SLIP_REFERENCE_MIN_M_S);
        match wheel_accel {
            None => {
                // Linear part of the slip curve.
                let slip = force / grip.max(1.0) * TYRE_PEAK_SLIP;
                self.rear_rad_s = self.speed_m_s / radius * (1.0 + slip);
                self.slip = slip;
            }
            Some(wheel) => {
                self.rear_rad_s = (self.rear_rad_s + wheel * dt_s).max(0.0);
                self.slip = (self.rear_rad_s * radius - self.speed_m_s) / reference;
                if self.slip.abs() < TYRE_PEAK_SLIP {
                    // Grip regained: roll with the car again.
                    self.slip = self.slip.clamp(-TYRE_PEAK_SLIP, TYRE_PEAK_SLIP);
                }
            }
        }
        self.distance_m += self.speed_m_s * dt_s;
    }
}

/// Friction coefficient at `slip` (>= 0): rising to the peak, then falling towards the
/// sliding value.
pub fn tyre_mu(slip: f32) -> f32 {
    let x = slip / TYRE_PEAK_SLIP;
    if x <= 1.0 {
        TYRE_PEAK_MU * 2.0 * x / (1.0 + x * x)
    } else {
        TYRE_SLIDE_MU + (TYRE_PEAK_MU - TYRE_SLIDE_MU) * 2.0 * x / (1.0 + x * x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_torque_accelerates_the_car_at_under_one_g_and_drag_slows_it() {
        let mut chassis = Chassis::new(Mode::Road);
        for _ in 0..1_000 {
            chassis.step(200.0, 0.0, 0.001);
        }
        assert!((5.0..10.0).contains(&chassis.speed_m_s), "{chassis:?}");
        assert!(chassis.slip.abs() <= TYRE_PEAK_SLIP, "no spin at 200 Nm");
        let fast = chassis.speed_m_s;
        for _ in 0..1_000 {
            chassis.step(0.0, 0.0, 0.001);
        }
        assert!(chassis.speed_m_s < fast);
        for _ in 0..3_000 {
            chassis.step(0.0, 800.0, 0.001);
        }
        assert_eq!(chassis.speed_m_s, 0.0, "brakes stop the car");
    }

    #[test]
    fn too_much_torque_spins_the_rear_wheels() {
        let mut chassis = Chassis::new(Mode::Road);
        // On a low-grip moment: full torque from rest with the wheels already slipping.
        chassis.slip = 0.3;
        chassis.rear_rad_s = 5.0;
        for _ in 0..200 {
            chassis.step(260.0, 0.0, 0.001);
        }
        assert!(chassis.slip > TYRE_PEAK_SLIP, "{chassis:?}");
    }

    #[test]
    fn the_dyno_holds_the_motor_speed() {
        let mut chassis = Chassis::new(Mode::Dyno { rpm: 4_000.0 });
        chassis.step(260.0, 0.0, 0.01);
        assert!((chassis.motor_rpm() - 4_000.0).abs() < 0.5);
    }
}
