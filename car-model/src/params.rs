//! What a run of the model can vary: the physical uncertainties the CCM must cope with
//! (drivetrain efficiency, measurement lag) and the car's fixed physical values.

use aer_ccm::InverterKind;
use aer_ccm::power::PowerLimits;

/// Parameters of one run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelParams {
    /// Drivetrain efficiency (battery DC to shaft) at standstill...
    pub efficiency: f32,
    /// ...falling by this much at 6,500 rpm (linear in speed), clamped to 0.85-0.97.
    pub efficiency_droop: f32,
    /// Time constant (ms) of a first-order lag on the inverter's DC voltage and current
    /// (MCU3) and on the BMS's current and voltage: the measurement's own filtering.
    pub measurement_lag_ms: f32,
    /// BMS pack-status frames report the values of this many 10 ms periods ago.
    pub bms_delay_periods: usize,
    /// Random delay (ms, 0..this) added to each node's frames on the bus.
    pub frame_jitter_ms: u32,
    /// Seed of the model's own randomness (jitter, autocross course).
    pub seed: u32,
    /// The inverter the car carries, and the CCM drives (fixed for a run: a retune keeps
    /// the one the run started with).
    pub inverter: InverterKind,
    /// The CCM's power limits (fixed for a run, as the inverter): the rules hold the car to
    /// their `power_limit_w`.
    pub limits: PowerLimits,
}

impl ModelParams {
    /// A nominal comp car (DTI HV-550): 91 % efficient, a 10 ms measurement lag, the BMS one
    /// period late, no jitter.
    pub const NOMINAL: Self = Self {
        efficiency: 0.91,
        efficiency_droop: 0.0,
        measurement_lag_ms: 10.0,
        bms_delay_periods: 1,
        frame_jitter_ms: 0,
        seed: 1,
        inverter: InverterKind::Dti,
        limits: PowerLimits::CAR,
    };

    /// The nominal car on the HIMaC bench's IFL100.
    pub const BENCH: Self = Self {
        inverter: InverterKind::Ifl100,
        ..Self::NOMINAL
    };
}

/// Chassis and tyres.
pub mod chassis {
    /// Standard gravity (m/s^2).
    pub const GRAVITY: f32 = 9.81;
    /// Drag area Cd x A (m^2) and air density (kg/m^3).
    pub const DRAG_AREA_M2: f32 = 1.1;
    /// Air density (kg/m^3).
    pub const AIR_DENSITY: f32 = 1.2;
    /// Rolling resistance coefficient.
    pub const ROLLING_RESISTANCE: f32 = 0.015;
    /// Share of the weight on the rear (driven) axle at rest.
    pub const REAR_WEIGHT_SHARE: f32 = 0.55;
    /// Centre of gravity height and wheelbase (m): longitudinal load transfer.
    pub const CG_HEIGHT_M: f32 = 0.30;
    /// Wheelbase (m).
    pub const WHEELBASE_M: f32 = 1.55;
    /// Rotating inertia at the rear axle (kg m^2): both rear wheels plus the motor through
    /// the gear (0.03 kg m^2 x 3.5^2).
    pub const REAR_INERTIA_KG_M2: f32 = 1.17;
    /// Tyre: peak friction coefficient, the slip where it peaks, and the sliding coefficient
    /// far beyond it.
    pub const TYRE_PEAK_MU: f32 = 1.25;
    /// Slip ratio at the peak.
    pub const TYRE_PEAK_SLIP: f32 = 0.10;
    /// Friction coefficient when spinning.
    pub const TYRE_SLIDE_MU: f32 = 0.95;
    /// Brake force per psi of line pressure (N/psi): 1,000 psi brakes at about 1.5 g.
    pub const BRAKE_N_PER_PSI: f32 = 4.4;
    /// Rear circuit pressure as a share of the front's.
    pub const REAR_BRAKE_SHARE: f32 = 0.85;
}

/// Motor and inverter.
pub mod powertrain {
    /// Time constant (ms) of the inverter's torque response to a new command.
    pub const TORQUE_RESPONSE_MS: f32 = 5.0;
    /// The IFL100 drops to zero torque when no VCU1 arrived for this long (ms, assumed).
    pub const VCU1_TIMEOUT_MS: u32 = 100;
    /// The DTI drops its current, and its drive enable, when no current command or no drive
    /// enable arrived for this long (ms, assumed: the DTI tool's CAN timeout, to be set and
    /// measured on the bench with the bring-up image's `dti enable`).
    pub const DTI_COMMAND_TIMEOUT_MS: u32 = aer_ccm::constants::DTI_ASSUMED_COMMAND_TIMEOUT_MS;
    /// The DTI's available AC current (A, peak) as the model reports it: the motor's maximum
    /// torque over its torque constant.
    pub const DTI_AVAILABLE_AC_A: f32 = 346.6;
    /// Motor speed (rpm) where the efficiency droop is reached, and the fastest the motor
    /// turns.
    pub const MAX_RPM: f32 = 6_500.0;
    /// Inverter losses while the DC link is live (W).
    pub const IDLE_LOSS_W: f32 = 150.0;
    /// Heat: motor and inverter warm with their losses and cool towards the coolant
    /// (degC per kJ of loss, and the fraction of the excess shed per second).
    pub const HEATING_DEGC_PER_KJ: f32 = 0.02;
    /// Fraction of the temperature above the coolant shed per second.
    pub const COOLING_PER_S: f32 = 0.01;
    /// Coolant temperature (degC).
    pub const COOLANT_DEGC: f32 = 30.0;
}

/// The CCM itself.
pub mod ccm {
    /// From a reset to the image's first control step (ms, assumed): the boot ROM, the copy
    /// into RAM and the image's start-up.
    pub const RESET_TO_RUNNING_MS: u32 = 300;
    /// The hardware watchdog's timeout (WDOG1, as the image sets it).
    pub const WATCHDOG_MS: u32 = 1_000;
}

/// Accumulator.
pub mod accumulator {
    /// Cells in series.
    pub const CELLS_IN_SERIES: f32 = 96.0;
    /// Pack internal resistance (ohm).
    pub const RESISTANCE_OHM: f32 = 0.12;
    /// Capacity (ampere-hours).
    pub const CAPACITY_AH: f32 = 18.0;
    /// Open-circuit voltage of one cell over SOC: (soc, volts), SOC rising.
    pub const CELL_OCV: [(f32, f32); 6] = [
        (0.0, 3.0),
        (0.1, 3.45),
        (0.2, 3.55),
        (0.5, 3.7),
        (0.8, 3.95),
        (1.0, 4.15),
    ];
    /// Spread of the cells around the average (V): low and high cell.
    pub const CELL_SPREAD_V: f32 = 0.015;
    /// Pack temperature rise per kJ of resistive loss (degC).
    pub const HEATING_DEGC_PER_KJ: f32 = 0.004;
}
