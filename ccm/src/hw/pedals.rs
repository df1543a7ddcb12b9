//! The pedal front-end, one of two by board option: APPS1 (A5) and APPS2 (A4) on the on-chip
//! ADC (the comp car), or an ADS1115 on LPI2C1 (feature `pedals-ads1115`).

use super::SetupFailed;
use super::board::PedalPins;
use crate::apps::PedalVolts;
use teensy4_bsp::hal::adc;
#[cfg(feature = "pedals-ads1115")]
use teensy4_bsp::{board as bsp, hal, ral};

/// The pedal front-end: the on-chip ADC's two inputs, or the ADS1115.
#[cfg(not(feature = "pedals-ads1115"))]
pub type PedalFrontEnd = [adc::AnalogInput; 2];
#[cfg(feature = "pedals-ads1115")]
pub type PedalFrontEnd = crate::ads1115::Ads1115<hal::lpi2c::Lpi2c>;

/// APPS1 (A5) and APPS2 (A4) on the on-chip ADC.
#[cfg(not(feature = "pedals-ads1115"))]
pub(super) fn front_end(
    adc: &mut adc::Adc,
    (apps1, apps2): PedalPins,
    _: teensy4_bsp::ral::lpi2c::LPI2C1,
) -> Result<PedalFrontEnd, SetupFailed> {
    Ok([
        adc.input::<_, 1>(apps1).map_err(|_| SetupFailed)?,
        adc.input::<_, 1>(apps2).map_err(|_| SetupFailed)?,
    ])
}

/// The ADS1115 on LPI2C1 (SCL 19, SDA 18), with the controller's pin-low timeout on: SCL or
/// SDA held low for about 1 ms ends the transaction with an error instead of a wait without
/// end (imxrt-hal's blocking I2C has no timeout of its own).
#[cfg(feature = "pedals-ads1115")]
pub(super) fn front_end(
    _: &mut adc::Adc,
    (scl, sda): PedalPins,
    lpi2c1: ral::lpi2c::LPI2C1,
) -> Result<PedalFrontEnd, SetupFailed> {
    let mut i2c = bsp::lpi2c(lpi2c1, scl, sda, bsp::Lpi2cClockSpeed::KHz400);
    i2c.disabled(|_| {
        // SAFETY: LPI2C1 is owned by `i2c` and disabled inside this closure; only its timeout
        // configuration changes.
        let regs = unsafe { ral::lpi2c::LPI2C1::instance() };
        // TIMECFG = 1: the timeout watches SDA as well as SCL.
        ral::modify_reg!(ral::lpi2c, regs, MCFGR1, TIMECFG: 1);
        ral::modify_reg!(ral::lpi2c, regs, MCFGR3, PINLOW: I2C_PIN_LOW_TIMEOUT);
    });
    Ok(crate::ads1115::Ads1115::new(i2c))
}

/// MCFGR3.PINLOW in units of 256 LPI2C clock cycles (8 MHz, prescaler 1 at 400 kHz):
/// 32 x 32 us = about 1 ms.
#[cfg(feature = "pedals-ads1115")]
const I2C_PIN_LOW_TIMEOUT: u32 = 32;

/// Both pedal sensors in volts at the sensor, and the converter's failed transactions so far
/// (0 on the on-chip ADC).
#[cfg(not(feature = "pedals-ads1115"))]
pub fn read(adc: &mut adc::Adc, [apps1, apps2]: &mut PedalFrontEnd) -> (PedalVolts, u32) {
    let counts = [adc.read_blocking(apps1), adc.read_blocking(apps2)];
    (
        crate::analog::pedal_volts(counts, super::board::REVISION.adc_divider),
        0,
    )
}

/// Both pedal sensors in volts at the sensor, and the converter's failed transactions so far
/// (a failing converter is backed off: see `Ads1115::poll`).
#[cfg(feature = "pedals-ads1115")]
pub fn read(_: &mut adc::Adc, ads: &mut PedalFrontEnd) -> (PedalVolts, u32) {
    let volts = crate::ads1115::pedal_volts(ads.poll());
    (volts, ads.bus_errors)
}
