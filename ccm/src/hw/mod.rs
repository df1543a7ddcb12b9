//! The CCM's hardware, set up one way for both images (race and bring-up): the Teensy 4.1's
//! pins as the board wires them ([`board`]), the PWM outputs ([`pwm`]), the pedal front-end
//! ([`pedals`]), the watchdog, and [`start`], which brings up everything the images share.
//!
//! Firmware only (feature `firmware`, thumbv7em): the logic stays in the portable modules;
//! this is the thin layer at the edge that touches registers.

pub mod board;
pub mod flash;
pub mod panic;
pub mod pedals;
pub mod pwm;

use aer_console::board_check::{BoardCheck, Teensy};
use aer_console::bringup::ResetCause;
use aer_console::usb::{UsbConsole, UsbMemory};
use aer_flexcan::{Flexcan, InitError};
use pedals::PedalFrontEnd;
use pwm::PwmBlock;
use teensy4_bsp::{
    board as bsp,
    hal::{
        self, adc, flexpwm, gpio,
        iomuxc::{self, Config, PullKeeper},
    },
    ral,
};

/// Everything both images drive and read, set up.
pub struct Ccm {
    /// Brake light driver (high = on).
    pub brake_light: gpio::Output,
    /// The on-board LED.
    pub led: gpio::Output,
    /// Ready-to-move button (pulled down: an open wire reads off).
    pub ready_to_move: gpio::Input,
    /// Launch-control button (pulled down).
    pub launch: gpio::Input,
    /// Front wheel-speed sensors 1 and 2 (pulled up), interrupting on rising edges
    /// (GPIO4_COMBINED_0_15).
    pub wheels: [gpio::Input; 2],
    /// Pumps 1 and 2: FlexPWM3 SM1, A and B.
    pub pumps: PwmBlock,
    /// Fan: FlexPWM1 SM3, B.
    pub fan: PwmBlock,
    /// Ready-to-drive buzzer: FlexPWM2 SM0, A.
    pub buzzer: PwmBlock,
    /// The on-chip ADC, 12 bits.
    pub adc: adc::Adc,
    /// BSE1 (A3), BSE2 (A2).
    pub brakes: [adc::AnalogInput; 2],
    /// Shock potentiometers 1-4 (A6-A9).
    pub shocks: [adc::AnalogInput; 4],
    /// Thermistor 1's pad (A0), left as it is: only the bring-up image reads it.
    pub thermistor: board::ThermistorPin,
    /// APPS1 and APPS2: on the on-chip ADC, or the ADS1115.
    pub pedals: PedalFrontEnd,
    /// CAN3, the vehicle bus (its start can fail: the race image halts, bring-up reports).
    pub vehicle_can: Result<Flexcan<3>, InitError>,
    /// CAN2, the inverter bus.
    pub inverter_can: Result<Flexcan<2>, InitError>,
    /// WDOG1, running with a 1 s timeout: feed it with [`feed_watchdog`].
    pub wdog: ral::wdog::WDOG1,
    /// Why the chip started (SRC_SRSR, cleared for the next start).
    pub reset_cause: ResetCause,
    /// The board check: the board this image was built for, found (or the image would have
    /// stopped in `wrong_board`).
    pub board: BoardCheck,
    /// The USB serial console, if the device started (the images run without it).
    pub console: Option<UsbConsole>,
    /// 256 bits from the TRNG, to start the XCP seed generator; `None` if the TRNG gave
    /// nothing within its bound (calibration then stays locked: seeds would be predictable).
    pub entropy: Option<[u8; 32]>,
}

/// Start-up failed (a pin on the wrong port, a PWM period that does not fit): the image
/// halts with no output configured, so no torque is ever commanded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SetupFailed;

/// Brings the board up: the board check first (on a Teensy 4.0, or one the check cannot
/// identify, the image stops here in `wrong_board`, every pin as reset left it), then pins,
/// PWM (outputs off), ADC, pedal front-end, GPT1 on the 1 MHz
/// peripheral clock (the image starts its monotonic on it next), both CAN controllers, WDOG1
/// at 1 s, the reset cause and the USB console named `product`.
pub fn start(
    device: teensy4_bsp::Peripherals,
    usb_memory: UsbMemory,
    product: &'static str,
) -> Result<Ccm, SetupFailed> {
    let bsp::Resources {
        pins,
        mut gpio2,
        mut gpio4,
        mut gpt1,
        ccm,
        adc1,
        lpi2c1,
        flexpwm1,
        flexpwm2,
        flexpwm3,
        usb,
        mut trng,
        ..
    } = bsp::t41(device);
    // Which board this is, before any pin is touched: on another one, nothing is driven and
    // the flash is never written.
    let check = BoardCheck {
        image: product,
        built_for: Teensy::T41,
        found: aer_console::chip::identify(),
    };
    if !check.right() {
        aer_console::usb::wrong_board(usb, usb_memory, check);
    }
    let mut pins = board::pins(pins);

    let brake_light = gpio2.output(pins.brake_light).map_err(|_| SetupFailed)?;
    let led = gpio2.output(pins.led).map_err(|_| SetupFailed)?;
    // The buttons read low (off) when a wire is open; the wheel-speed sensors' open collectors
    // need the pull-up.
    let pull_down = Config::modify().set_pull_keeper(Some(PullKeeper::Pulldown100k));
    let pull_up = Config::modify().set_pull_keeper(Some(PullKeeper::Pullup22k));
    iomuxc::configure(&mut pins.ready_to_move, pull_down);
    iomuxc::configure(&mut pins.launch, pull_down);
    iomuxc::configure(&mut pins.wheels.0, pull_up);
    iomuxc::configure(&mut pins.wheels.1, pull_up);
    let ready_to_move = gpio2.input(pins.ready_to_move).map_err(|_| SetupFailed)?;
    let launch = gpio4.input(pins.launch).map_err(|_| SetupFailed)?;
    let wheels = [
        gpio4.input(pins.wheels.0).map_err(|_| SetupFailed)?,
        gpio4.input(pins.wheels.1).map_err(|_| SetupFailed)?,
    ];
    for wheel in &wheels {
        gpio4
            .set_interrupt(wheel, Some(gpio::Trigger::RisingEdge))
            .map_err(|_| SetupFailed)?;
    }

    let (mut pump1, mut pump2) = pins.pumps;
    let (mut fan_pin, mut buzzer_pin) = (pins.fan, pins.buzzer);
    hal::iomuxc::flexpwm::prepare(&mut pump1);
    hal::iomuxc::flexpwm::prepare(&mut pump2);
    hal::iomuxc::flexpwm::prepare(&mut fan_pin);
    hal::iomuxc::flexpwm::prepare(&mut buzzer_pin);
    let pumps = PwmBlock::new(flexpwm3, flexpwm::SM::SM1, board::PUMP_PWM_HZ).ok_or(SetupFailed)?;
    let fan = PwmBlock::new(flexpwm1, flexpwm::SM::SM3, board::FAN_PWM_HZ).ok_or(SetupFailed)?;
    let buzzer = PwmBlock::new(flexpwm2, flexpwm::SM::SM0, board::BUZZER_HZ).ok_or(SetupFailed)?;

    let mut adc = adc1;
    adc.set_resolution(adc::ResolutionBits::Res12);
    let (bse1, bse2) = pins.brakes;
    let (s1, s2, s3, s4) = pins.shocks;
    let brakes = [
        adc.input::<_, 1>(bse1).map_err(|_| SetupFailed)?,
        adc.input::<_, 1>(bse2).map_err(|_| SetupFailed)?,
    ];
    let shocks = [
        adc.input::<_, 1>(s1).map_err(|_| SetupFailed)?,
        adc.input::<_, 1>(s2).map_err(|_| SetupFailed)?,
        adc.input::<_, 1>(s3).map_err(|_| SetupFailed)?,
        adc.input::<_, 1>(s4).map_err(|_| SetupFailed)?,
    ];
    let pedals = pedals::front_end(&mut adc, pins.pedals, lpi2c1)?;

    gpt1.set_clock_source(hal::gpt::ClockSource::PeripheralClock);
    gpt1.set_divider(bsp::PERCLK_FREQUENCY / 1_000_000);

    // SAFETY: the BSP does not hand out FlexCAN, SRC or WDOG1; nothing else uses them.
    let (can3_regs, can2_regs, wdog, src) = unsafe {
        (
            ral::can3::CAN3::instance(),
            ral::can::CAN2::instance(),
            ral::wdog::WDOG1::instance(),
            ral::src::SRC::instance(),
        )
    };
    // Why this start (SRC_SRSR, sticky: cleared so the next start is judged on its own).
    let srsr = ral::read_reg!(ral::src, src, SRSR);
    ral::write_reg!(ral::src, src, SRSR, srsr);
    let (tx3, rx3) = pins.vehicle_can;
    let (tx2, rx2) = pins.inverter_can;
    let vehicle_can = Flexcan::new_can3(can3_regs, tx3, rx3, &ccm, board::CAN_BITRATE);
    let inverter_can = Flexcan::new(can2_regs, tx2, rx2, &ccm, board::CAN_BITRATE);
    if inverter_can.is_ok() {
        panic::inverter_bus_started();
    }
    start_watchdog(&wdog);

    let console = UsbConsole::new(usb, usb_memory, product).ok();
    let entropy = random_bytes(&mut trng);
    Ok(Ccm {
        brake_light,
        led,
        ready_to_move,
        launch,
        wheels,
        pumps,
        fan,
        buzzer,
        adc,
        brakes,
        shocks,
        thermistor: pins.thermistor,
        pedals,
        vehicle_can,
        inverter_can,
        wdog,
        reset_cause: ResetCause(srsr),
        board: check,
        console,
        entropy,
    })
}

/// Eight words from the TRNG, each polled a bounded number of times (its first entropy takes
/// a few milliseconds after reset); `None` if any word did not come or came with an error.
fn random_bytes(trng: &mut hal::trng::Trng) -> Option<[u8; 32]> {
    let mut word = || {
        for _ in 0..2_000_000u32 {
            if let core::task::Poll::Ready(result) = trng.next_u32() {
                return result.ok();
            }
        }
        None
    };
    let mut bytes = [0u8; 32];
    for chunk in bytes.chunks_exact_mut(4) {
        chunk.copy_from_slice(&word()?.to_le_bytes());
    }
    Some(bytes)
}

/// WDOG1 with a 1 s timeout: WT = 1 (0.5 s steps, plus one), enabled. The power-down counter
/// is switched off so only a missed service resets the CCM.
fn start_watchdog(wdog: &ral::wdog::WDOG1) {
    ral::write_reg!(ral::wdog, wdog, WMCR, 0);
    ral::modify_reg!(ral::wdog, wdog, WCR, WT: 1, WDE: 1);
}

/// Services WDOG1.
pub fn feed_watchdog(wdog: &ral::wdog::WDOG1) {
    ral::write_reg!(ral::wdog, wdog, WSR, 0x5555);
    ral::write_reg!(ral::wdog, wdog, WSR, 0xAAAA);
}

/// Parks the core: start-up failed, with outputs unconfigured (no torque is ever commanded)
/// and, if it failed before [`start`] reached it, the watchdog not started.
pub fn halt() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}
