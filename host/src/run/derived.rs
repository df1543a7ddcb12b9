//! Channels derived from the telemetry by the car's own parameters (`aer-params`: gear ratio,
//! wheel radius), declared once for the driver's display, the run report and the exports:
//! road speed and battery power, and their integrals over a session, distance and energy.

use aer::telemetry::Telemetry;

/// Gaps between packets longer than this are not integrated (the car was not seen).
pub const MAX_STEP_S: f64 = 0.5;

/// A derived channel as the exports describe it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channel {
    pub name: &'static str,
    pub label: &'static str,
    pub unit: &'static str,
    pub description: &'static str,
}

/// The derived channels, in the order [`Sample::values`] gives them.
pub const CHANNELS: [Channel; 4] = [
    Channel {
        name: "speed",
        label: "Speed",
        unit: "km/h",
        description: "Road speed from the motor speed through the gear ratio and the wheel radius (aer-params; no wheel-speed sensor, so wheel slip reads as speed).",
    },
    Channel {
        name: "battery_power",
        label: "Battery power",
        unit: "kW",
        description: "Pack voltage times pack current (the BMS's): positive while discharging, negative while regenerating.",
    },
    Channel {
        name: "distance",
        label: "Distance",
        unit: "m",
        description: "Road speed integrated over the session's packets (gaps over 0.5 s not counted).",
    },
    Channel {
        name: "battery_energy",
        label: "Battery energy",
        unit: "Wh",
        description: "Battery power integrated over the session's packets (gaps over 0.5 s not counted): energy drawn less energy regenerated.",
    },
];

/// The telemetry fields the derived channels are computed from, for a reader of the stored
/// columns: the motor speed (rpm), the pack voltage (V) and current (A).
pub const INPUTS: [&str; 3] = ["motor_speed", "pack_voltage", "pack_current"];

/// Road speed (m/s) for a motor speed (rpm).
pub fn road_speed_m_s(motor_rpm: f64) -> f64 {
    // The car's formula, in f64: the gear ratio and wheel radius of aer-params.
    motor_rpm / f64::from(aer_params::GEAR_RATIO) * std::f64::consts::TAU / 60.0
        * f64::from(aer_params::WHEEL_RADIUS_M)
}

/// Road speed (m/s) of a packet.
pub fn speed_m_s(telemetry: &Telemetry) -> f64 {
    road_speed_m_s(f64::from(telemetry.motor_speed))
}

/// Battery power (W) of a packet, positive while discharging.
pub fn battery_power_w(telemetry: &Telemetry) -> f64 {
    f64::from(telemetry.pack_voltage) * f64::from(telemetry.pack_current)
}

/// The derived channels of one packet.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    pub speed_m_s: f64,
    pub power_w: f64,
    /// Since the start of the session.
    pub distance_m: f64,
    /// Since the start of the session (J).
    pub energy_j: f64,
}

impl Sample {
    /// The values in [`CHANNELS`]' order and units.
    pub fn values(&self) -> [f64; 4] {
        [
            self.speed_m_s * 3.6,
            self.power_w / 1_000.0,
            self.distance_m,
            self.energy_j / 3_600.0,
        ]
    }
}

/// Integrates speed and power packet by packet.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Integrator {
    distance_m: f64,
    energy_j: f64,
    /// The packet before: its time, speed and power.
    last: Option<(f64, f64, f64)>,
}

impl Integrator {
    /// Takes the packet received at `ts` (s) with its road speed (m/s) and battery power (W).
    /// Each packet's values hold until the next (a sample stands for the time after it), so
    /// the packet before counts for the time since it, unless that gap is longer than
    /// [`MAX_STEP_S`] or time went back.
    pub fn step(&mut self, ts: f64, speed_m_s: f64, power_w: f64) -> Sample {
        if let Some((last_ts, speed, power)) = self.last {
            let step = ts - last_ts;
            if (0.0..=MAX_STEP_S).contains(&step) {
                if speed.is_finite() {
                    self.distance_m += speed.max(0.0) * step;
                }
                if power.is_finite() {
                    self.energy_j += power * step;
                }
            }
        }
        self.last = Some((ts, speed_m_s, power_w));
        Sample {
            speed_m_s,
            power_w,
            distance_m: self.distance_m,
            energy_j: self.energy_j,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packet(motor_rpm: f32, volts: f32, amps: f32) -> Telemetry {
        let mut telemetry = Telemetry::zeroed();
        telemetry.motor_speed = motor_rpm;
        telemetry.pack_voltage = volts;
        telemetry.pack_current = amps;
        telemetry
    }

    #[test]
    fn the_road_speed_is_the_car_formula() {
        for rpm in [0.0_f32, 1_234.5, 6_000.0] {
            let theirs = f64::from(aer_params::road_speed_m_s(rpm));
            assert!((road_speed_m_s(f64::from(rpm)) - theirs).abs() < 1e-4 * theirs.max(1.0));
        }
    }

    #[test]
    fn distance_and_energy_integrate_speed_and_power_over_the_packets() {
        // 3,500 rpm at the motor: 1,000 rpm at the wheel (gear 3.5), 2 pi 0.35 m a turn.
        let wheel_m_s = std::f64::consts::TAU * 0.35 * 1_000.0 / 60.0;
        let mut integrator = Integrator::default();
        let mut last = Sample::default();
        // 101 packets, 10 ms apart: 1 s at that speed and power.
        for i in 0..=100 {
            let telemetry = packet(3_500.0, 400.0, 50.0);
            last = integrator.step(
                f64::from(i) * 0.01,
                speed_m_s(&telemetry),
                battery_power_w(&telemetry),
            );
        }
        assert!((last.speed_m_s - wheel_m_s).abs() < 1e-3, "{last:?}");
        assert!((last.distance_m - wheel_m_s).abs() < 1e-3, "1 s: {last:?}");
        assert!(
            (last.energy_j - 20_000.0).abs() < 1e-6,
            "20 kW for 1 s: {last:?}"
        );
        let [kmh, kw, m, wh] = last.values();
        assert!((kmh - wheel_m_s * 3.6).abs() < 1e-3 && (kw - 20.0).abs() < 1e-9);
        assert!((m - last.distance_m).abs() < 1e-12 && (wh - 20_000.0 / 3_600.0).abs() < 1e-9);
    }

    #[test]
    fn a_gap_or_a_step_back_in_time_is_not_integrated() {
        let mut integrator = Integrator::default();
        integrator.step(0.0, 10.0, 20_000.0);
        let after_gap = integrator.step(60.0, 10.0, 20_000.0);
        assert_eq!((after_gap.distance_m, after_gap.energy_j), (0.0, 0.0));
        let back = integrator.step(59.0, 10.0, 20_000.0);
        assert_eq!((back.distance_m, back.energy_j), (0.0, 0.0));
        // The value of the packet before counts, not the one that just came.
        let next = integrator.step(59.5, 0.0, 0.0);
        assert_eq!((next.distance_m, next.energy_j), (5.0, 10_000.0));
    }
}
