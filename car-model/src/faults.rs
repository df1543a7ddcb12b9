//! Fault injection: what can break on the car, and when it breaks in a run.

/// A node whose frames can be garbled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Node {
    /// The precharge controller.
    Pcc,
    /// The Orion BMS.
    Bms,
    /// The inverter.
    Inverter,
    /// The isolation monitor.
    Imd,
}

/// One thing that breaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// The pedal converter (ADS1115) stops answering: no more conversions.
    PedalConverterLost,
    /// A pedal sensor's signal wire is open: it reads 0 V (sensor 0 = APPS1, 1 = APPS2).
    PedalSensorOpen(usize),
    /// A pedal sensor's signal is shorted to its supply.
    PedalSensorShorted(usize),
    /// A pedal sensor's signal stays where it was when the fault began.
    PedalSensorStuck(usize),
    /// The brake sensor voltages are not numbers (a broken conversion).
    BrakeSensorNan,
    /// The CCM's 1 kHz sampling stops (the task hangs).
    SamplingStopped,
    /// The BMS stops sending.
    BmsSilent,
    /// The inverter stops sending (it still obeys commands).
    InverterSilent,
    /// The inverter faults (the IFL100's over-heat bit, the DTI's fault code): it stops
    /// driving and reports it.
    InverterFaulted,
    /// The inverter's status is stuck: it repeats the frames of the moment it stuck (the
    /// IFL100's counters stop moving; the DTI's packets carry none), and still obeys commands.
    InverterStuck,
    /// The shutdown circuit opens: the PCC opens its relays and reports ERROR.
    ShutdownOpen,
    /// A bus is off for the CCM (0 = CAN1, 1 = CAN2): nothing in or out.
    BusOff(usize),
    /// A node's frames carry random bytes: values out of range, unknown enum values.
    GarbledFrames(Node),
    /// A PCC V/F converter's output wire breaks: no pulses, whatever the voltage (0 = the
    /// accumulator's, 1 = the tractive system's).
    ConverterSilent(usize),
    /// AIR+'s contacts weld shut: closed whatever the PCC and the shutdown circuit do.
    AirPlusWelded,
    /// AIR+ never closes, whatever the PCC commands (its coil unpowered, its driver dead).
    AirPlusStuckOpen,
    /// The discharge circuit is open: with the AIRs open the tractive system discharges only
    /// through the inverter's own bleeder, in tens of seconds.
    DischargeFailed,
    /// A load across the tractive system (1.9 kOhm, as the precharge resistor): a precharge
    /// stalls at half the pack and heats the resistor.
    TractiveLoad,
    /// A precharge-resistor thermistor is open (0 = pin 21, 1 = pin 22).
    ThermistorOpen(usize),
    /// The inverter's own command timeout is off (the DTI's CAN timeout left disabled in its
    /// tool): it holds its last command for as long as none follows.
    InverterTimeoutOff,
    /// The CCM panics when the fault begins: its panic handler sends the inverter's stop
    /// frames and resets at once; the image starts again after the reset.
    CcmPanic,
    /// The CCM's control hangs when the fault begins (no panic): nothing is sent until the
    /// 1 s watchdog resets it.
    CcmHang,
}

impl Fault {
    /// Every kind, with its first variant where it has several (for reports).
    pub const KINDS: [Self; 22] = [
        Self::PedalConverterLost,
        Self::PedalSensorOpen(0),
        Self::PedalSensorShorted(1),
        Self::PedalSensorStuck(0),
        Self::BrakeSensorNan,
        Self::SamplingStopped,
        Self::BmsSilent,
        Self::InverterSilent,
        Self::InverterFaulted,
        Self::InverterStuck,
        Self::ShutdownOpen,
        Self::BusOff(0),
        Self::GarbledFrames(Node::Pcc),
        Self::ConverterSilent(1),
        Self::AirPlusWelded,
        Self::AirPlusStuckOpen,
        Self::DischargeFailed,
        Self::TractiveLoad,
        Self::ThermistorOpen(0),
        Self::InverterTimeoutOff,
        Self::CcmPanic,
        Self::CcmHang,
    ];
}

/// A fault active over a time window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Injection {
    /// What breaks.
    pub fault: Fault,
    /// From this time (ms) on...
    pub from_ms: u32,
    /// ...until this time (exclusive; `u32::MAX` for the rest of the run).
    pub until_ms: u32,
}

impl Injection {
    /// Whether it is active at `now_ms`.
    pub const fn active(&self, now_ms: u32) -> bool {
        now_ms >= self.from_ms && now_ms < self.until_ms
    }
}

/// Up to four faults in one run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FaultPlan {
    injections: [Option<Injection>; 4],
}

impl FaultPlan {
    /// No fault.
    pub const NONE: Self = Self {
        injections: [None; 4],
    };

    /// The plan with `injection` added (ignored once four are planned).
    #[must_use]
    pub fn with(mut self, injection: Injection) -> Self {
        if let Some(slot) = self.injections.iter_mut().find(|slot| slot.is_none()) {
            *slot = Some(injection);
        }
        self
    }

    /// Every planned injection.
    pub fn injections(&self) -> impl Iterator<Item = &Injection> {
        self.injections.iter().flatten()
    }

    /// Whether a fault matching `wanted` is active at `now_ms`.
    pub fn active(&self, now_ms: u32, wanted: impl Fn(Fault) -> bool) -> bool {
        self.injections()
            .any(|injection| injection.active(now_ms) && wanted(injection.fault))
    }

    /// Whether `fault` itself is active at `now_ms`.
    pub fn is_active(&self, now_ms: u32, fault: Fault) -> bool {
        self.active(now_ms, |active| active == fault)
    }
}
