//! The gate in front of everything a bring-up image can do that matters at high voltage (the
//! PCC's AIR+, the DTI's drive enable): a typed confirmation, and the board's own readings,
//! checked again at every step of the bench loop.
//!
//! A reading is evidence only while it is alive, fresh and plausible. A V/F converter gives
//! pulses at any voltage it can measure: no pulses is a converter that is unplugged,
//! unpowered or broken, not 0 V. A reading older than the gate's age limit, or outside what a
//! real pack can show, is not evidence either. Each of those is [`Unknown`], and unknown never
//! arms anything.

use core::fmt;

/// How long a typed confirmation arms the outputs behind the gate (ms).
pub const HV_CONFIRMATION_MS: u32 = 30_000;

/// The band a real reading lies in (V): the rules allow at most 600 V in the tractive system
/// (margin for the dividers' tolerance above it, and for an inverter reporting a few volts
/// below zero at rest). Outside it is a broken converter, a wrong scale or noise.
pub const HV_PLAUSIBLE_V: (f32, f32) = (-10.0, 650.0);

/// One high-voltage reading as a board has it now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HvReading {
    /// A measurement: `volts`, taken at `at_ms`.
    Volts {
        /// What it read (V).
        volts: f32,
        /// When (ms, the board's clock).
        at_ms: u32,
    },
    /// No sign of life from the sensor: no pulses from a V/F converter, no packet from an
    /// inverter.
    Silent,
}

/// A sensor the gate reads: its name, what it reads now, and what its silence means.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HvSensor<'a> {
    /// The sensor, as the refusal names it: `accumulator (pin 14)`, `DTI DC link`.
    pub name: &'a str,
    /// Its reading now.
    pub reading: HvReading,
    /// Why silence is not 0 V and what to do about it, for the refusal.
    pub silent: &'a str,
}

/// Why a reading is not evidence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Unknown<'a> {
    /// No sign of life; the text says what that means for this sensor.
    Silent(&'a str),
    /// Older than the gate's age limit.
    Stale {
        /// How old (ms).
        age_ms: u32,
        /// The limit (ms).
        limit_ms: u32,
    },
    /// Outside [`HV_PLAUSIBLE_V`], or not a number.
    Implausible {
        /// What it read (V).
        volts: f32,
    },
}

/// Why the gate is closed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HvRefusal<'a> {
    /// No confirmation typed, or it was revoked.
    NotConfirmed,
    /// The confirmation is older than [`HV_CONFIRMATION_MS`].
    Expired,
    /// A reading is not evidence of anything.
    Unknown {
        /// The sensor.
        name: &'a str,
        /// Why.
        why: Unknown<'a>,
    },
    /// A reading at or above the discharged limit.
    Live {
        /// The sensor.
        name: &'a str,
        /// What it read (V).
        volts: f32,
        /// The limit (V).
        limit_v: f32,
    },
}

impl fmt::Display for HvRefusal<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotConfirmed => f.write_str("type `confirm hv-disconnected` first"),
            Self::Expired => f.write_str("the HV confirmation expired (30 s): confirm again"),
            Self::Unknown { name, why } => match why {
                Unknown::Silent(meaning) => write!(f, "{name} gives no reading: {meaning}"),
                Unknown::Stale { age_ms, limit_ms } => write!(
                    f,
                    "{name}'s reading is {age_ms} ms old, older than {limit_ms} ms: unknown, so nothing is armed"
                ),
                Unknown::Implausible { volts } => write!(
                    f,
                    "{name} reads {volts:.1} V, outside what a pack can show ({:.0} to {:.0} V): a broken converter or a wrong scale, so nothing is armed",
                    HV_PLAUSIBLE_V.0, HV_PLAUSIBLE_V.1
                ),
            },
            Self::Live {
                name,
                volts,
                limit_v,
            } => write!(
                f,
                "{name} reads {volts:.1} V, not below {limit_v:.0} V: the high voltage is not disconnected and discharged"
            ),
        }
    }
}

/// Whether `sensor` is alive, fresh (at most `max_age_ms` old at `now_ms`) and plausible, and
/// then what it reads (V).
pub fn evidence<'a>(
    sensor: &HvSensor<'a>,
    now_ms: u32,
    max_age_ms: u32,
) -> Result<f32, HvRefusal<'a>> {
    let unknown = |why| HvRefusal::Unknown {
        name: sensor.name,
        why,
    };
    match sensor.reading {
        HvReading::Silent => Err(unknown(Unknown::Silent(sensor.silent))),
        HvReading::Volts { volts, at_ms } => {
            let age_ms = now_ms.wrapping_sub(at_ms);
            if age_ms > max_age_ms {
                Err(unknown(Unknown::Stale {
                    age_ms,
                    limit_ms: max_age_ms,
                }))
            } else if !(HV_PLAUSIBLE_V.0..=HV_PLAUSIBLE_V.1).contains(&volts) {
                Err(unknown(Unknown::Implausible { volts }))
            } else {
                Ok(volts)
            }
        }
    }
}

/// The gate: open only within [`HV_CONFIRMATION_MS`] of a typed confirmation that the high
/// voltage is disconnected, and only while every reading is evidence (alive, fresh,
/// plausible) of a voltage below the discharged limit. A typed word alone never arms it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HvGate {
    confirmed_ms: Option<u32>,
    /// Volts below which a reading counts as discharged (the rules' 60 V DC).
    discharged_v: f32,
    /// How old a reading may be (ms).
    max_age_ms: u32,
}

impl HvGate {
    /// A closed gate for readings that count as discharged below `discharged_v` and as
    /// unknown once older than `max_age_ms`.
    pub const fn new(discharged_v: f32, max_age_ms: u32) -> Self {
        Self {
            confirmed_ms: None,
            discharged_v,
            max_age_ms,
        }
    }

    /// The user confirmed at `now_ms` that the high voltage is disconnected; taken only if
    /// every reading agrees.
    pub fn confirm<'a>(
        &mut self,
        now_ms: u32,
        sensors: &[HvSensor<'a>],
    ) -> Result<(), HvRefusal<'a>> {
        self.discharged(now_ms, sensors)?;
        self.confirmed_ms = Some(now_ms);
        Ok(())
    }

    /// Whether the outputs behind the gate may move (or stay moved) at `now_ms` with these
    /// readings: called at every step while they are moved.
    pub fn allows<'a>(&self, now_ms: u32, sensors: &[HvSensor<'a>]) -> Result<(), HvRefusal<'a>> {
        let at = self.confirmed_ms.ok_or(HvRefusal::NotConfirmed)?;
        if now_ms.wrapping_sub(at) >= HV_CONFIRMATION_MS {
            return Err(HvRefusal::Expired);
        }
        self.discharged(now_ms, sensors)
    }

    /// How long ago the held confirmation was typed at `now_ms` (ms); `None` without one
    /// (it may have expired: [`Self::allows`] says).
    pub fn confirmed_for(&self, now_ms: u32) -> Option<u32> {
        self.confirmed_ms.map(|at| now_ms.wrapping_sub(at))
    }

    /// Forgets the confirmation (on `off`, or when the gate closed and the output dropped).
    pub fn revoke(&mut self) {
        self.confirmed_ms = None;
    }

    /// The discharged limit (V).
    pub const fn discharged_v(&self) -> f32 {
        self.discharged_v
    }

    /// The age limit (ms).
    pub const fn max_age_ms(&self) -> u32 {
        self.max_age_ms
    }

    fn discharged<'a>(&self, now_ms: u32, sensors: &[HvSensor<'a>]) -> Result<(), HvRefusal<'a>> {
        for sensor in sensors {
            let volts = evidence(sensor, now_ms, self.max_age_ms)?;
            if volts >= self.discharged_v {
                return Err(HvRefusal::Live {
                    name: sensor.name,
                    volts,
                    limit_v: self.discharged_v,
                });
            }
        }
        if sensors.is_empty() {
            // Nothing read is nothing known.
            return Err(HvRefusal::Unknown {
                name: "high voltage",
                why: Unknown::Silent("the board has no reading of it"),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::format;

    const SILENT: &str = "no pulses";

    fn sensor(name: &'static str, reading: HvReading) -> HvSensor<'static> {
        HvSensor {
            name,
            reading,
            silent: SILENT,
        }
    }

    fn volts(volts: f32, at_ms: u32) -> HvReading {
        HvReading::Volts { volts, at_ms }
    }

    fn discharged(now_ms: u32) -> [HvSensor<'static>; 2] {
        [
            sensor("accumulator", volts(24.0, now_ms)),
            sensor("tractive system", volts(3.2, now_ms)),
        ]
    }

    #[test]
    fn the_gate_opens_only_for_30_s_after_the_confirmation() {
        let mut gate = HvGate::new(60.0, 10);
        assert_eq!(gate.allows(0, &discharged(0)), Err(HvRefusal::NotConfirmed));
        let start = u32::MAX - 10;
        assert_eq!(gate.confirm(start, &discharged(start)), Ok(()));
        assert_eq!(gate.allows(u32::MAX, &discharged(u32::MAX)), Ok(()));
        let late = HV_CONFIRMATION_MS - 12;
        assert_eq!(
            gate.allows(late, &discharged(late)),
            Ok(()),
            "across the wrap"
        );
        let expired = HV_CONFIRMATION_MS - 11;
        assert_eq!(
            gate.allows(expired, &discharged(expired)),
            Err(HvRefusal::Expired)
        );
        assert_eq!(gate.confirm(5, &discharged(5)), Ok(()));
        gate.revoke();
        assert_eq!(gate.allows(6, &discharged(6)), Err(HvRefusal::NotConfirmed));
    }

    #[test]
    fn the_boards_readings_outweigh_the_typed_word() {
        let mut gate = HvGate::new(60.0, 10);
        let live = [
            sensor("accumulator", volts(402.5, 0)),
            sensor("tractive system", volts(0.5, 0)),
        ];
        let refusal = gate.confirm(0, &live).unwrap_err();
        assert_eq!(
            format!("{refusal}"),
            "accumulator reads 402.5 V, not below 60 V: the high voltage is not disconnected and discharged"
        );
        assert_eq!(gate.allows(1, &discharged(1)), Err(HvRefusal::NotConfirmed));
        // Armed, then the tractive system rises: the gate closes at the next step.
        assert_eq!(gate.confirm(10, &discharged(10)), Ok(()));
        let rising = [
            sensor("accumulator", volts(24.0, 20)),
            sensor("tractive system", volts(60.0, 20)),
        ];
        assert!(matches!(
            gate.allows(20, &rising),
            Err(HvRefusal::Live { .. })
        ));
    }

    #[test]
    fn silence_is_unknown_not_zero_volts() {
        let mut gate = HvGate::new(60.0, 10);
        let dead = [
            sensor("accumulator (pin 14)", HvReading::Silent),
            sensor("tractive system (pin 15)", volts(0.0, 0)),
        ];
        let refusal = gate.confirm(0, &dead).unwrap_err();
        assert_eq!(
            format!("{refusal}"),
            "accumulator (pin 14) gives no reading: no pulses"
        );
        // Armed on live converters, then one goes silent (a wire breaks): closed.
        assert_eq!(gate.confirm(100, &discharged(100)), Ok(()));
        let broken = [
            sensor("accumulator", volts(24.0, 110)),
            sensor("tractive system", HvReading::Silent),
        ];
        assert!(matches!(
            gate.allows(110, &broken),
            Err(HvRefusal::Unknown {
                why: Unknown::Silent(_),
                ..
            })
        ));
        assert!(gate.confirm(0, &[]).is_err(), "no sensor is no evidence");
    }

    #[test]
    fn old_or_implausible_readings_are_unknown() {
        let mut gate = HvGate::new(60.0, 10);
        assert_eq!(gate.confirm(0, &discharged(0)), Ok(()));
        let old = [sensor("DTI DC link", volts(0.0, 100))];
        assert_eq!(gate.allows(110, &old), Ok(()), "10 ms old is fresh");
        let refusal = gate.allows(111, &old).unwrap_err();
        assert_eq!(
            format!("{refusal}"),
            "DTI DC link's reading is 11 ms old, older than 10 ms: unknown, so nothing is armed"
        );
        for bad in [f32::NAN, -10.5, 650.5, f32::INFINITY] {
            let implausible = [sensor("accumulator", volts(bad, 200))];
            assert!(
                matches!(
                    gate.allows(200, &implausible),
                    Err(HvRefusal::Unknown {
                        why: Unknown::Implausible { .. },
                        ..
                    })
                ),
                "{bad}"
            );
        }
        let broken = [sensor("accumulator", volts(812.0, 0))];
        assert_eq!(
            format!("{}", gate.confirm(0, &broken).unwrap_err()),
            "accumulator reads 812.0 V, outside what a pack can show (-10 to 650 V): a broken converter or a wrong scale, so nothing is armed"
        );
    }
}
