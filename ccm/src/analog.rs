//! The i.MX RT1062's on-chip ADC as the CCM board uses it: 12-bit conversions of a 3.3 V
//! reference, behind the board's divider (`aer_boards::ccm::Revision::adc_divider`), turned
//! into volts at the sensor.

use crate::apps::PedalVolts;

/// The ADC's reference (V).
pub const REFERENCE_V: f32 = 3.3;
/// Full scale of a 12-bit conversion.
pub const FULL_SCALE_COUNTS: f32 = 4_095.0;

/// Volts at the ADC pin for 12-bit `counts`.
pub fn pin_volts(counts: u16) -> f32 {
    f32::from(counts.min(4_095)) * REFERENCE_V / FULL_SCALE_COUNTS
}

/// Volts at the sensor for 12-bit `counts` behind `divider` (sensor volts per pin volt).
pub fn sensor_volts(counts: u16, divider: f32) -> f32 {
    pin_volts(counts) * divider
}

/// Both pedal sensors read on the on-chip ADC: a new reading every sample.
pub fn pedal_volts(counts: [u16; 2], divider: f32) -> PedalVolts {
    counts.map(|counts| Some(sensor_volts(counts, divider)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_scale_is_the_reference_times_the_divider_and_counts_saturate() {
        assert_eq!(pin_volts(0), 0.0);
        assert_eq!(pin_volts(4_095), REFERENCE_V);
        assert_eq!(pin_volts(u16::MAX), REFERENCE_V);
        assert!((sensor_volts(4_095, 1.515_151) - 5.0).abs() < 1e-3);
    }
}
