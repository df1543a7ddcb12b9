//! The PCC's frames through the generated codec: its status (0x222, every 10 ms) and the
//! precharge resistor's temperatures (0x223, every 100 ms).

use crate::machine::Precharge;
use aer::can::{PccStatus, PccThermal};
use embedded_can::{Frame, StandardId};

/// Largest value the status frame's 16-bit, 0.01-scaled fields hold.
const FIELD_MAX: f64 = 655.35;
/// Largest progress the frame's 14-bit, 0.01-scaled field holds (%).
const PROGRESS_MAX: f64 = 163.83;

impl Precharge {
    /// The status as the schema's message, values clamped to what the frame can carry.
    pub fn status(&self) -> PccStatus {
        let errors = self.errors();
        let [accumulator, tractive] = self.pulses();
        PccStatus {
            pcc_state: self.state().to_wire(),
            pcc_error_air_plus_open: errors.air_plus_open,
            pcc_error_converters_disagree: errors.converters_disagree,
            pcc_error_bypassed: errors.bypassed,
            pcc_error_resistor_hot: errors.resistor_hot,
            pcc_accumulator_no_pulses: accumulator.is_silent(),
            pcc_tractive_no_pulses: tractive.is_silent(),
            pcc_error_too_fast: errors.too_fast,
            pcc_error_too_slow: errors.too_slow,
            pcc_error_bms_timeout: errors.bms_timeout,
            pcc_error_shutdown: errors.shutdown,
            pcc_error_accumulator_silent: errors.accumulator_silent,
            pcc_error_tractive_silent: errors.tractive_silent,
            pcc_error_no_discharge: errors.no_discharge,
            pcc_error_undefined_state: errors.undefined_state,
            pcc_accumulator_voltage: clamp(self.accumulator_v()),
            pcc_tractive_voltage: clamp(self.tractive_v()),
            pcc_precharge_progress: f64::from(self.progress_percent()).clamp(0.0, PROGRESS_MAX),
        }
    }

    /// The status as a CAN frame ready to send, or `None` if it cannot be encoded (values
    /// are clamped first, so that would be a codec defect; the caller counts it).
    pub fn status_frame<F: Frame>(&self) -> Option<F> {
        let mut data = [0u8; PccStatus::LEN];
        let len = self.status().encode(&mut data).ok()?;
        let id = StandardId::new(u16::try_from(PccStatus::ID).ok()?)?;
        F::new(id, data.get(..len)?)
    }

    /// The precharge resistor's temperatures as the schema's message: a thermistor with no
    /// reading is sent as not valid (its value 0, which no reader takes for a temperature).
    pub fn thermal(&self) -> PccThermal {
        let [first, second] = self.resistor_c();
        let value = |reading: Option<f32>| {
            reading.map_or(0.0, |c| f64::from(c).clamp(THERMAL_MIN_C, THERMAL_MAX_C))
        };
        PccThermal {
            pcc_resistor_temp1: value(first),
            pcc_resistor_temp2: value(second),
            pcc_resistor_temp1_valid: first.is_some(),
            pcc_resistor_temp2_valid: second.is_some(),
        }
    }

    /// [`Self::thermal`] as a CAN frame, or `None` if it cannot be encoded (a codec defect:
    /// the caller counts it).
    pub fn thermal_frame<F: Frame>(&self) -> Option<F> {
        let mut data = [0u8; PccThermal::LEN];
        let len = self.thermal().encode(&mut data).ok()?;
        let id = StandardId::new(u16::try_from(PccThermal::ID).ok()?)?;
        F::new(id, data.get(..len)?)
    }
}

/// The temperature range PCC_Thermal declares (degC): a shorted thermistor's reading is sent
/// at the top.
const THERMAL_MIN_C: f64 = -40.0;
const THERMAL_MAX_C: f64 = 250.0;

fn clamp(value: f32) -> f64 {
    f64::from(value).clamp(0.0, FIELD_MAX)
}
