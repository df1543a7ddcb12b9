//! The car's constants, in one place (vehicle-facts.md and the team's documentation; values
//! marked "assumed" are this firmware's choices and should be checked on the car).

// --- Task rates --------------------------------------------------------------------------

/// Sensor sampling (on-chip ADC, pedals): 1 kHz.
pub const ADC_PERIOD_MS: u32 = 1;
/// Vehicle control (state machine, launch/traction control): 100 Hz.
pub const CONTROL_PERIOD_MS: u32 = 10;
/// VCU1 and BMS1/BMS2 to the inverter.
pub const INVERTER_PERIOD_MS: u32 = 20;
/// Telemetry packet to the Pi.
pub const TELEMETRY_PERIOD_MS: u32 = 10;
/// Watchdog supervisor check.
pub const WATCHDOG_CHECK_MS: u32 = 100;
/// Hardware watchdog timeout.
pub const HARDWARE_WATCHDOG_TIMEOUT_MS: u32 = 1_000;

// --- Powertrain --------------------------------------------------------------------------

/// Motor torque the car is built for (Nm).
pub const MOTOR_MAX_TORQUE_NM: f32 = 260.0;
/// Tractive power limit (EV.3.3.1), in W.
pub const POWER_LIMIT_W: f32 = 80_000.0;
/// SOC below which torque is derated linearly...
pub const SOC_DERATE_START: f32 = 0.20;
/// ...down to zero at this SOC.
pub const SOC_DERATE_END: f32 = 0.05;

// --- Pedals ------------------------------------------------------------------------------

/// Pedal filter cut-off (Hz), sampled at 1 kHz.
pub const PEDAL_FILTER_HZ: f32 = 100.0;
/// A sensor fault must persist longer than this (ms) before it counts (T.4.2.10, T.4.3.4).
pub const SENSOR_FAULT_PERSIST_MS: u32 = 100;
/// APPS sensors disagreeing by more than this fraction of travel is implausible (T.4.2.4).
pub const APPS_IMPLAUSIBLE: f32 = 0.10;
/// APPS/brake plausibility (EV.4.7): throttle above this with the brake pressed latches...
pub const APPS_BRAKE_TRIP: f32 = 0.25;
/// ...until the throttle is back below this.
pub const APPS_BRAKE_RESET: f32 = 0.05;
/// ADS1115 full-scale range at PGA 2/3 (V): APPS2 runs on 5 V, above the 4.096 V range.
pub const ADS1115_FULL_SCALE_V: f32 = 6.144;
/// APPS1 supply (V); valid signal 10-90 % of it.
pub const APPS1_SUPPLY_V: f32 = 3.3;
/// APPS2 supply (V); valid signal 10-90 % of it.
pub const APPS2_SUPPLY_V: f32 = 5.0;
/// Brake pressure sensors: valid signal range (V).
pub const BSE_VALID_V: (f32, f32) = (0.5, 4.5);
/// Brake pressure at 4.5 V (psi); 0.5 V is 0 psi (assumed: 2,000 psi sensors).
pub const BSE_FULL_SCALE_PSI: f32 = 2_000.0;
/// Front brake pressure counted as "brake pressed" (psi, assumed).
pub const BRAKE_PRESSED_PSI: f32 = 50.0;
/// Brake light on above / off below (psi, assumed): hysteresis against flicker.
pub const BRAKE_LIGHT_PSI: (f32, f32) = (30.0, 20.0);
/// Front and rear circuits disagreeing (one above the first pressure while the other stays
/// below the second) for longer than this is a brake-pressure plausibility fault (assumed).
pub const BRAKE_CIRCUITS_IMPLAUSIBLE: (f32, f32, u32) = (400.0, 20.0, 500);

// --- Chassis sensors ---------------------------------------------------------------------

/// Shock travel at full compression (mm).
pub const SHOCK_TRAVEL_MAX_MM: f32 = 76.2;
/// The potentiometer's signal drop over the full travel (V), below its 5 V rest.
pub const SHOCK_SPAN_V: f32 = 0.14;
/// On-chip ADC counts at full scale (12 bit) and the sensor voltage that gives it.
pub const SHOCK_ADC_FULL: (u16, f32) = (4095, 5.0);
/// Teeth on each wheel-speed encoder gear (assumed).
pub const WHEEL_TEETH: u32 = 24;
/// No pulse for this long means the wheel stands still (us).
pub const WHEEL_STOP_TIMEOUT_US: u32 = 500_000;
/// Wheel radius (m).
pub const WHEEL_RADIUS_M: f32 = 0.35;
/// Motor revolutions per wheel revolution (assumed).
pub const GEAR_RATIO: f32 = 3.5;

// --- Driver controls ---------------------------------------------------------------------

/// Ready-to-move button must be stable this long (100-500 ms).
pub const RTM_DEBOUNCE_MS: u32 = 200;
/// Ready-to-drive sound length before torque is enabled (EV.9.2: 1-3 s).
pub const RTD_SOUND_MS: u32 = 2_000;
/// A PCC status older than this (10 missed frames) cannot vouch for the precharge.
pub const PCC_STATUS_TIMEOUT_MS: u32 = 100;

// --- Launch and traction control ---------------------------------------------------------

/// Launch control slip target and band (team documentation: 0.07, 0.05-0.10).
pub const LAUNCH_SLIP: (f32, f32, f32) = (0.07, 0.05, 0.10);
/// Traction control intervenes above this slip (assumed).
pub const TRACTION_SLIP: f32 = 0.10;
/// Below this free-rolling wheel speed (rad/s) slip is not defined (about 1 m/s).
pub const MIN_SLIP_SPEED_RAD_S: f32 = 3.0;

// --- Cooling -----------------------------------------------------------------------------

/// Pump duty while the tractive system is live, and its ramp with inverter temperature.
pub const PUMP_DUTY: (f32, f32, f32) = (0.3, 40.0, 60.0);
/// Fan off below the first temperature, full at the second (hottest of motor/inverter, degC).
pub const FAN_RAMP_DEGC: (f32, f32) = (45.0, 70.0);

// --- Fault thresholds --------------------------------------------------------------------

/// Lowest cell voltage (V) below which UNDER_VOLTAGE is raised.
pub const MIN_CELL_V: f32 = 2.8;
/// Motor, inverter and pack temperature limits (degC) for OVER_TEMPERATURE.
pub const MAX_TEMP_DEGC: (f32, f32, f32) = (120.0, 85.0, 60.0);
