//! The CCM's constants, in one place (vehicle-facts.md and the team's documentation; values
//! marked "assumed" are this firmware's choices and should be checked on the car). The car's
//! physical parameters and rule limits, which the dashboard and the car model need too, come
//! from `aer-params` and are re-exported here. The numbers the team tunes (launch and traction
//! control, the power trim's gain, the cooling ramps, the sensors' calibration) are not here:
//! they are `schema/calibration.yaml`'s, read from the active
//! [`Calibration`](crate::calibration::Calibration) every step.

use aer::can::{
    DtiAcLimits, DtiCurrents, DtiFlags, DtiSetCurrent, DtiSpeed, DtiTemperatures, Mcu1, Mcu2, Mcu3,
    OrionCellVoltages, OrionLimits, OrionPackStatus, PccStatus, Vcu1,
};

pub use aer_params::{
    DRIVETRAIN_EFFICIENCY, GEAR_RATIO, MOTOR_MAX_TORQUE_NM, MOTOR_POLE_PAIRS,
    MOTOR_TORQUE_PER_PEAK_A, POWER_LIMIT_W, SOC_DERATE_END, SOC_DERATE_START, WHEEL_RADIUS_M,
};

// --- The car's configuration -------------------------------------------------------------

/// Which inverter the CCM drives (its frames and status: `inverter`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InverterKind {
    /// The comp car's DTI HV-550: extended ids, current commands, drive enable.
    Dti,
    /// The HIMaC bench's IFL100: VCU1 torque commands, MCU1-3 status, BMS1/BMS2 emulated.
    Ifl100,
}

/// The inverter the firmware drives: the comp car's DTI HV-550, or the HIMaC bench's IFL100
/// with the `inverter-ifl100` feature (`cargo xtask firmware` builds it as `ccm-ifl100.hex`).
/// The library and the car model take it as a value, so the tests drive both.
pub const INVERTER: InverterKind = if cfg!(feature = "inverter-ifl100") {
    InverterKind::Ifl100
} else {
    InverterKind::Dti
};

// --- Task rates --------------------------------------------------------------------------

/// Sensor sampling (on-chip ADC, pedals): 1 kHz.
pub const ADC_PERIOD_MS: u32 = 1;
/// Vehicle control (state machine, launch/traction control): 100 Hz.
pub const CONTROL_PERIOD_MS: u32 = 10;
/// The IFL100's VCU1 and BMS1/BMS2 (every 20 ms).
pub const IFL100_COMMAND_PERIOD_MS: u32 = Vcu1::CYCLE_TIME_MS;
/// The DTI's current, drive enable and DC current limits (every 10 ms).
pub const DTI_COMMAND_PERIOD_MS: u32 = DtiSetCurrent::CYCLE_TIME_MS;
/// Telemetry packet to the Pi.
pub const TELEMETRY_PERIOD_MS: u32 = 10;
/// CCM_Status on both buses.
pub const STATUS_PERIOD_MS: u32 = 100;
/// Watchdog supervisor check.
pub const WATCHDOG_CHECK_MS: u32 = 100;
/// Hardware watchdog timeout.
pub const HARDWARE_WATCHDOG_TIMEOUT_MS: u32 = 1_000;

// --- Freshness: how old an input may be before it counts as lost -------------------------
//
// A lost input means no torque and a named fault (see `faults`). A node that has never been
// heard is lost once the CCM has run for `START_UP_GRACE_MS`, so the other nodes may boot a
// little later than the CCM without a fault at every power-up.

/// The 1 kHz sensor sample (brakes, shocks, the pedal converter's poll): the sampling task
/// has stopped.
pub const SAMPLE_TIMEOUT_MS: u32 = 10;
/// A pedal sensor channel without a new ADS1115 conversion for this long: the converter
/// or its I2C bus is lost (each channel converts about every 2.3 ms). With the control step
/// after it, torque is zero well within T.4.2.10's 100 ms.
pub const PEDAL_CONVERSION_TIMEOUT_MS: u32 = 20;

// The CAN inputs' limits are the schema's (`TIMEOUT_MS`: the DBC's `AerTimeoutMs`, else five
// cycle times), the same numbers every tier uses.

/// PCC status (0x222, every 10 ms): 100 ms.
pub const PCC_STATUS_TIMEOUT_MS: u32 = PccStatus::TIMEOUT_MS;
/// Orion pack status (0x6B0, every 10 ms): current, voltage, SOC; 100 ms.
pub const BMS_PACK_TIMEOUT_MS: u32 = OrionPackStatus::TIMEOUT_MS;
/// Orion limits (0x6B1, every 100 ms): 500 ms.
pub const BMS_LIMITS_TIMEOUT_MS: u32 = OrionLimits::TIMEOUT_MS;
/// Orion cell voltages (0x6B2, every 100 ms): 500 ms.
pub const BMS_CELLS_TIMEOUT_MS: u32 = OrionCellVoltages::TIMEOUT_MS;
/// MCU1 (motor speed, torque; every 10 ms): the power ceiling needs the speed; 50 ms.
pub const MCU1_TIMEOUT_MS: u32 = Mcu1::TIMEOUT_MS;
/// MCU3 (DC voltage and current; every 10 ms): the power trim needs them; 50 ms.
pub const MCU3_TIMEOUT_MS: u32 = Mcu3::TIMEOUT_MS;
/// MCU2 (temperatures, fault bits; every 100 ms): 500 ms.
pub const MCU2_TIMEOUT_MS: u32 = Mcu2::TIMEOUT_MS;
/// DTI speed and DC voltage (packet 0x20, every 10 ms): the power ceiling needs the speed.
pub const DTI_SPEED_TIMEOUT_MS: u32 = DtiSpeed::TIMEOUT_MS;
/// DTI AC and DC current (0x21, every 10 ms): the power trim needs the DC current.
pub const DTI_CURRENTS_TIMEOUT_MS: u32 = DtiCurrents::TIMEOUT_MS;
/// DTI drive enabled, limits and map version (0x24, every 10 ms).
pub const DTI_FLAGS_TIMEOUT_MS: u32 = DtiFlags::TIMEOUT_MS;
/// DTI temperatures and fault code (0x22, every 100 ms).
pub const DTI_TEMPERATURES_TIMEOUT_MS: u32 = DtiTemperatures::TIMEOUT_MS;
/// DTI available AC current (0x25, every 100 ms): the inverter's available torque.
pub const DTI_AC_LIMITS_TIMEOUT_MS: u32 = DtiAcLimits::TIMEOUT_MS;
/// Missing nodes are not reported as lost during this long after start-up.
pub const START_UP_GRACE_MS: u32 = 1_000;

// --- DTI HV-550 ---------------------------------------------------------------------------

/// The CAN map version the schema describes (2.5, reported as major x 10 + minor). Any other
/// version is an inverter fault: its frames may not mean what the schema says.
pub const DTI_CAN_MAP_VERSION: u8 = 25;
/// What the DTI does when commands stop, as the car model and the torque-off figures assume
/// it until the bench measures it (ms): current and drive enable dropped after this long
/// (the DTI tool's CAN timeout; the bring-up image's `dti enable` measures it).
pub const DTI_ASSUMED_COMMAND_TIMEOUT_MS: u32 = 100;
/// The DTI reports "drive enabled" against the CCM's "disabled" (or the reverse) for longer
/// than this (ms): it is not obeying, an inverter fault. Two command periods and a status
/// period of slack.
pub const DTI_ENABLE_MISMATCH_MS: u32 = 50;
/// How far the motor speed the inverter reports (at the wheel) may read below the slower front
/// wheel under torque, for [`SPEED_IMPLAUSIBLE_MS`], before it counts as an inverter fault:
/// (from this front wheel speed in rad/s, this share of it). Slip is never negative under
/// drive, so a slower motor is a frozen or wrong reading; the loose first tier covers the
/// launch, where the readings' lag is a large share of the speed, the tight second one speed,
/// where a reading 10 % low would let the power bounds allow about that much too much.
pub const SPEED_IMPLAUSIBLE: [(f32, f32); 2] = [(MIN_SLIP_SPEED_RAD_S, 0.5), (30.0, 0.9)];
/// See [`SPEED_IMPLAUSIBLE`].
pub const SPEED_IMPLAUSIBLE_MS: u32 = 200;
/// A motor speed reading unchanged bit for bit this long (five DTI status periods) ...
pub const SPEED_FROZEN_MS: u32 = 50;
/// ... while the slower front wheel changed by more than this share under torque is frozen ...
pub const SPEED_FROZEN_CHANGE: f32 = 0.02;
/// ... from this front wheel speed on (rad/s, about 2.3 m/s): slower wheels are timed over few
/// pulses, and their noise is no evidence.
pub const SPEED_FROZEN_FROM_RAD_S: f32 = 10.0;
/// Below this commanded torque (Nm) the speed check rests: coasting and braking may lock the
/// driven wheels.
pub const SPEED_WATCH_MIN_TORQUE_NM: f32 = 20.0;

// --- Power limiting ----------------------------------------------------------------------

/// How far below the rule's power limit the limiter aims (a share of the limit): the
/// measurement's resolution and the ripple of the trim, so that every 100 ms average stays
/// below the limit. 2.5 % of 80 kW: the limiter aims at 78 kW. The target follows the limit
/// (`PowerLimits::for_rule`), and the torque monitor bounds the limit itself.
pub const POWER_LIMIT_MARGIN: f32 = 0.025;
/// How far below the rule's power limit the torque monitor bounds the accumulator's power (a
/// share of the limit): its readings' resolution (1 V in 400 V, 0.1 A) and their lag, so it
/// holds the rule on its own. Smaller than [`POWER_LIMIT_MARGIN`], so the monitor never
/// meets the limiter in normal driving.
pub const MONITOR_MARGIN: f32 = 0.01;
/// Below this share of the power limit, the measured DC power is too small to tell the
/// drivetrain's efficiency from (the monitor then returns to the lowest).
pub const EFFICIENCY_MEASURABLE_SHARE: f32 = 0.1;
/// The monitor's efficiency rises only while the DC power reading moved by less than this
/// share of the limit since the last step (it has caught up with the torque)...
pub const EFFICIENCY_SETTLED_SHARE: f32 = 0.002;
/// ...and by at most this much per control step (the drivetrain's whole range in 0.24 s).
pub const EFFICIENCY_RISE_PER_STEP: f32 = 0.005;
/// Time constant (s) with which the monitor's efficiency returns to the lowest while the
/// power is too small to measure it.
pub const EFFICIENCY_RELAX_S: f32 = 0.5;
/// The trim raises the efficiency estimate only while the measured power moved by less than
/// this fraction of the target since the last step...
pub const POWER_SETTLED_FRACTION: f32 = 0.01;
/// ...and reads at least this share (allowing for the measurement's resolution) of the least
/// the ceiling can give: lowest / highest efficiency times the target.
pub const POWER_TRIM_FLOOR: f32 = 0.98;
/// Time constant (s) with which the efficiency estimate returns to the lowest efficiency
/// while the power ceiling does not bind, so the next full-power phase starts safe.
pub const POWER_TRIM_RELAX_S: f32 = 0.5;
/// Below this motor speed (rad/s) the power ceiling is computed at this speed (the ceiling
/// is far above the motor maximum there anyway).
pub const POWER_CEILING_MIN_RAD_S: f32 = 10.0;

// --- Pedals ------------------------------------------------------------------------------

/// Pedal filter cut-off (Hz), sampled at 1 kHz.
pub const PEDAL_FILTER_HZ: f32 = 100.0;
/// A sensor fault must persist longer than this (ms) before it counts (T.4.2.10, T.4.3.4).
pub const SENSOR_FAULT_PERSIST_MS: u32 = 100;
/// A pedal sensor fault still counts as continuous through a clean spell this short (ms).
pub const SENSOR_FAULT_GAP_MS: u32 = 10;
/// APPS sensors disagreeing by more than this fraction of travel is implausible (T.4.2.4).
pub const APPS_IMPLAUSIBLE: f32 = 0.10;
/// APPS/brake plausibility (EV.4.7): throttle above this with the brakes engaged latches...
pub const APPS_BRAKE_TRIP: f32 = 0.25;
/// ...until the throttle is back below this.
pub const APPS_BRAKE_RESET: f32 = 0.05;
/// Pedal travel below which the driver counts as off the throttle (ends a launch).
pub const PEDAL_RELEASED: f32 = 0.05;
/// Pedal travel that still asks for no torque: the sensors' noise at rest must not command
/// torque. The torque request rises linearly from here to full travel.
pub const PEDAL_DEADBAND: f32 = 0.02;
/// ADS1115 full-scale range at PGA 2/3 (V): APPS2 runs on 5 V, above the 4.096 V range.
pub const ADS1115_FULL_SCALE_V: f32 = 6.144;
/// APPS1 supply (V); valid signal 10-90 % of it.
pub const APPS1_SUPPLY_V: f32 = 3.3;
/// APPS2 supply (V); valid signal 10-90 % of it.
pub const APPS2_SUPPLY_V: f32 = 5.0;
/// Brake pressure sensors: valid signal range (V).
pub const BSE_VALID_V: (f32, f32) = (0.5, 4.5);
/// A pedal sensor must move at least this much over the pedal's travel (V) for its
/// calibration to be taken: below it, noise is a large share of the torque request.
pub const MIN_PEDAL_TRAVEL_V: f32 = 0.5;
/// A brake pressure sensor's reading with the brakes released (its calibrated zero) must lie
/// here (V): below 0.5 V is outside the valid range (a BSE fault at rest); above 0.7 V
/// (100 psi on the nominal sensor) is pressure left in the circuit or a wrong sensor
/// (assumed band).
pub const BSE_ZERO_V: (f32, f32) = (0.5, 0.7);
/// Brake pressure sensors' span from zero to full scale (V): 0.5 V to 4.5 V nominally.
pub const BSE_SPAN_V: f32 = 4.0;
/// Brake pressure at the sensor's zero plus [`BSE_SPAN_V`] (psi); the zero is the bench's
/// calibration, 0.5 V nominally (assumed: 2,000 psi sensors).
pub const BSE_FULL_SCALE_PSI: f32 = 2_000.0;
/// The one "brakes engaged" threshold (psi, assumed): engaged above the first pressure,
/// released below the second (hysteresis against flicker). The brake light, the APPS/brake
/// plausibility check and launch control all use it, so the light is on exactly when the
/// CCM treats the brakes as engaged.
pub const BRAKES_ENGAGED_PSI: (f32, f32) = (30.0, 20.0);
/// Front and rear circuits disagreeing (one above the first pressure while the other stays
/// below the second) for longer than this is a brake-pressure plausibility fault (assumed).
pub const BRAKE_CIRCUITS_IMPLAUSIBLE: (f32, f32, u32) = (400.0, 20.0, 500);

// --- Chassis sensors ---------------------------------------------------------------------

/// Shock travel at full compression (mm).
pub const SHOCK_TRAVEL_MAX_MM: f32 = 76.2;
/// On-chip ADC counts at full scale (12 bit) and the sensor voltage that gives it (3.3 V at
/// the pin behind the board's 1.515 divider, assumed on every CCM analog input).
pub const SHOCK_ADC_FULL: (u16, f32) = (4095, 5.0);
/// A shock sensor's calibrated ends must lie here (V at the sensor): the ADC reads up to
/// 5.0 V; an open or unpowered input reads near 0 V.
pub const SHOCK_VALID_V: (f32, f32) = (0.2, 5.0);
/// A shock sensor's calibrated ends must lie at least this far apart (V): closer, the ADC's
/// steps (1.2 mV) and noise are a large share of the travel (the team's sensors span 0.14 V).
pub const MIN_SHOCK_SPAN_V: f32 = 0.05;
/// Teeth on each wheel-speed encoder gear (assumed).
pub const WHEEL_TEETH: u32 = 24;
/// No pulse for this long means the wheel stands still (us).
pub const WHEEL_STOP_TIMEOUT_US: u32 = 500_000;

// --- Driver controls ---------------------------------------------------------------------

/// Ready-to-move button must be stable this long (100-500 ms).
pub const RTM_DEBOUNCE_MS: u32 = 200;
/// Ready-to-drive sound length before torque is enabled (EV.9.2: 1-3 s).
pub const RTD_SOUND_MS: u32 = 2_000;

// --- Launch and traction control ---------------------------------------------------------

/// Below this free-rolling wheel speed (rad/s) slip is not defined (about 1 m/s).
pub const MIN_SLIP_SPEED_RAD_S: f32 = 3.0;

// --- Fault thresholds --------------------------------------------------------------------

/// Lowest cell voltage (V) below which UNDER_VOLTAGE is raised.
pub const MIN_CELL_V: f32 = 2.8;
/// Motor, inverter and pack temperature limits (degC) for OVER_TEMPERATURE.
pub const MAX_TEMP_DEGC: (f32, f32, f32) = (120.0, 85.0, 60.0);

// --- Calibration ---------------------------------------------------------------------------

/// The tractive system counts as off (for calibration changes and saving) only while the
/// PCC reports STANDBY with its tractive-system voltage below this (the 60 V DC low-voltage
/// limit of the rules, as the PCC's own handover uses).
pub const TRACTIVE_OFF_V: f32 = aer_params::TRACTIVE_LOW_VOLTAGE_V;

/// The precharge target (% of the pack) the PCC closes AIR+ at: a PCC that reports ONLINE or
/// CHARGING below it reports what it cannot be.
pub const PCC_TARGET_PERCENT: f32 = aer_params::PRECHARGE_TARGET_PERCENT;

/// The PCC's tractive-system reading and the inverter's DC link may differ by this fraction of
/// the higher (the converters are checked to 1 % on the bench day, the DTI's reading is not
/// specified better than a few percent: assumed) ...
pub const TRACTIVE_MISMATCH_FRACTION: f32 = 0.1;
/// ... plus this (V): the PCC's 10 Hz filter and the inverter's status period lag a tractive
/// system that rises or falls by up to 800 V/s (the discharge's 0.5 s time constant).
pub const TRACTIVE_MISMATCH_MARGIN_V: f32 = 30.0;
/// ... for this long before it is a fault (ms): longer than any precharge or discharge
/// transient, short against the seconds a wrong "dead" reading would matter for.
pub const TRACTIVE_MISMATCH_PERSIST_MS: u32 = 500;
/// One reading below 60 V and the other at this or more is a disagreement whatever the
/// margin: the tractive system read dead where it may be live (V; above 60 V by the two
/// filters' lag).
pub const TRACTIVE_MISMATCH_LIVE_V: f32 = 70.0;
/// The car counts as stopped (for calibration changes and saving) only while the motor, on a
/// fresh inverter status, and both front wheels turn slower than this (rad/s, about 0.1 m/s at
/// the wheel); an unknown speed counts as moving.
pub const STANDSTILL_RAD_S: f32 = 0.5;
