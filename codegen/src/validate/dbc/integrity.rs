//! Rolling counters and checksums, declared on their signals with attributes CANalyzer and
//! cantools keep: `CounterStep` (INT: what the sender adds on every frame; 0, the default,
//! marks no counter) and `ChecksumAlgorithm` (ENUM or STRING: `None`, `SumXorFF`,
//! `Crc8SaeJ1850`). The generated `MessageMeta` then carries them, and `seal`/`verify` fill and
//! check them on every tier. Also: a cycle time on a message sent on demand.

use can_dbc::{AttributeDefinition, AttributeValue, AttributeValueType, MessageId};

use super::{Builder, Draft, Frame};
use crate::diagnostic::Code;
use crate::model::{Checksum, ChecksumAlgorithm, Counter, Encoding, Signal};

/// The signal attribute that marks a rolling counter, with its step.
const COUNTER: &str = "CounterStep";
/// The signal attribute that marks a checksum, with its algorithm.
const CHECKSUM: &str = "ChecksumAlgorithm";
/// Widest counter the runtime keeps (bits).
const MAX_COUNTER_BITS: u32 = 8;

impl<'a> Builder<'a, '_> {
    /// The message's counter and checksum; `None` (reported) when one is declared on a signal
    /// that cannot carry it.
    pub(super) fn integrity(
        &mut self,
        frame: &Frame<'a>,
        drafts: &[Draft<'a>],
        signals: &[Signal],
    ) -> Option<(Option<Counter>, Option<Checksum>)> {
        let mut counter: Option<(Counter, usize)> = None;
        let mut checksum: Option<(Checksum, usize)> = None;
        let mut ok = true;
        for (index, (d, s)) in drafts.iter().zip(signals).enumerate() {
            if let Some(step) = self.counter_step(frame.msg.id, &d.sig.name) {
                match (self.check_counter(frame, d, s, step), counter) {
                    (Some(_), Some((_, first))) => {
                        self.r.report(
                            Code::CounterInvalid,
                            d.line,
                            format!(
                                "message `{}` declares a second rolling counter `{}` (the first is on line {first})",
                                frame.name, s.name
                            ),
                            "a message has at most one counter: set CounterStep on one signal",
                        );
                        ok = false;
                    }
                    (Some(step), None) => {
                        counter = Some((
                            Counter {
                                signal: index,
                                step,
                            },
                            d.line,
                        ));
                    }
                    (None, _) => ok = false,
                }
            }
            if let Some(algorithm) = self.checksum_algorithm(frame, d)? {
                match (self.check_checksum(frame, d, s), checksum) {
                    (Some(_), Some((_, first))) => {
                        self.r.report(
                            Code::ChecksumInvalid,
                            d.line,
                            format!(
                                "message `{}` declares a second checksum `{}` (the first is on line {first})",
                                frame.name, s.name
                            ),
                            "a message has at most one checksum: set ChecksumAlgorithm on one signal",
                        );
                        ok = false;
                    }
                    (Some(byte), None) => {
                        checksum = Some((
                            Checksum {
                                signal: index,
                                byte,
                                algorithm,
                            },
                            d.line,
                        ));
                    }
                    (None, _) => ok = false,
                }
            }
        }
        ok.then_some((counter.map(|c| c.0), checksum.map(|c| c.0)))
    }

    /// The signal's `CounterStep`, when it marks a counter (non-zero).
    fn counter_step(&self, id: MessageId, signal: &str) -> Option<i128> {
        let value = self
            .index
            .signal_attributes(COUNTER, id, signal)
            .first()
            .copied()
            .or_else(|| self.index.attribute_default(COUNTER))?;
        let step = match value {
            AttributeValue::Uint(v) => i128::from(*v),
            AttributeValue::Int(v) => i128::from(*v),
            AttributeValue::Double(v) if v.fract() == 0.0 => *v as i128,
            _ => return None,
        };
        (step != 0).then_some(step)
    }

    /// The step, if the signal can be a counter (reported otherwise).
    fn check_counter(
        &mut self,
        frame: &Frame<'_>,
        d: &Draft<'_>,
        s: &Signal,
        step: i128,
    ) -> Option<u8> {
        let why = if s.encoding != Encoding::Unsigned || s.factor != 1.0 || s.offset != 0.0 {
            Some("it is not an unsigned integer with factor 1 and offset 0".to_owned())
        } else if s.len > MAX_COUNTER_BITS {
            Some(format!(
                "it is {} bits wide; a counter has at most {MAX_COUNTER_BITS}",
                s.len
            ))
        } else if step < 1 || step >= 1i128 << s.len {
            Some(format!(
                "its step {step} does not fit its {} bits (1 to {})",
                s.len,
                (1u32 << s.len) - 1
            ))
        } else if s.mux.is_some() || s.is_multiplexor {
            Some("it is multiplexed (or a multiplexor): every frame must carry it".to_owned())
        } else {
            None
        };
        match why {
            Some(why) => {
                self.r.report(
                    Code::CounterInvalid,
                    d.line,
                    format!("signal `{}` of `{}` is declared a rolling counter, but {why}", s.name, frame.name),
                    "make the counter a plain unsigned signal of 1-8 bits, or remove its CounterStep",
                );
                None
            }
            None => u8::try_from(step).ok(),
        }
    }

    /// The signal's checksum algorithm: `Ok(None)` when it marks none; `None` (reported) for an
    /// algorithm the runtime does not know.
    fn checksum_algorithm(
        &mut self,
        frame: &Frame<'_>,
        d: &Draft<'_>,
    ) -> Option<Option<ChecksumAlgorithm>> {
        let value = self
            .index
            .signal_attributes(CHECKSUM, frame.msg.id, &d.sig.name)
            .first()
            .copied()
            .or_else(|| self.index.attribute_default(CHECKSUM));
        let name = match value {
            None => return Some(None),
            Some(AttributeValue::String(name)) => name.clone(),
            // An ENUM attribute's value is the index of its name in the definition.
            Some(AttributeValue::Uint(i)) => self.enum_name_or_index(CHECKSUM, i128::from(*i)),
            Some(AttributeValue::Int(i)) => self.enum_name_or_index(CHECKSUM, i128::from(*i)),
            Some(AttributeValue::Double(v)) => format!("{v}"),
        };
        if name.is_empty() || name == "None" {
            return Some(None);
        }
        let known = ChecksumAlgorithm::NAMES
            .iter()
            .find(|(known, _)| *known == name)
            .map(|(_, algorithm)| *algorithm);
        if known.is_none() {
            let names: Vec<&str> = ChecksumAlgorithm::NAMES.iter().map(|(n, _)| *n).collect();
            self.r.report(
                Code::ChecksumInvalid,
                d.line,
                format!(
                    "signal `{}` of `{}` names the checksum algorithm `{name}`, which the generator does not know",
                    d.sig.name, frame.name
                ),
                format!("use one of {} (or None)", names.join(", ")),
            );
            return None;
        }
        Some(known)
    }

    /// The name at `index` in an ENUM attribute's definition, or `#index` when the definition
    /// has none there (an index past the list names no algorithm).
    fn enum_name_or_index(&self, attribute: &str, index: i128) -> String {
        let name = self.enum_name(attribute, usize::try_from(index).ok());
        if name.is_empty() {
            format!("#{index}")
        } else {
            name
        }
    }

    /// The name at `index` in a signal or message ENUM attribute's definition.
    fn enum_name(&self, attribute: &str, index: Option<usize>) -> String {
        self.loaded
            .dbc
            .attribute_definitions
            .iter()
            .find_map(|def| match def {
                AttributeDefinition::Signal(name, AttributeValueType::Enum(values))
                | AttributeDefinition::Message(name, AttributeValueType::Enum(values))
                    if name == attribute =>
                {
                    index.and_then(|i| values.get(i)).cloned()
                }
                _ => None,
            })
            .unwrap_or_default()
    }

    /// The byte a checksum signal occupies, if it is one whole, unscaled byte (reported
    /// otherwise).
    fn check_checksum(&mut self, frame: &Frame<'_>, d: &Draft<'_>, s: &Signal) -> Option<u8> {
        let bits = s.bits();
        let byte = bits.first().map(|b| b / 8);
        let whole_byte = s.len == 8 && bits.iter().all(|b| Some(b / 8) == byte);
        let why = if s.encoding != Encoding::Unsigned || s.factor != 1.0 || s.offset != 0.0 {
            Some("it is not an unsigned integer with factor 1 and offset 0")
        } else if !whole_byte {
            Some("it is not one whole byte (8 bits starting at a byte boundary)")
        } else if s.mux.is_some() || s.is_multiplexor {
            Some("it is multiplexed (or a multiplexor): every frame must carry it")
        } else {
            None
        };
        if let Some(why) = why {
            self.r.report(
                Code::ChecksumInvalid,
                d.line,
                format!(
                    "signal `{}` of `{}` is declared a checksum, but {why}",
                    s.name, frame.name
                ),
                "make the checksum one whole unsigned byte, or remove its ChecksumAlgorithm",
            );
            return None;
        }
        byte.and_then(|b| u8::try_from(b).ok())
    }

    /// Warns about a cycle time on a message the schema says is sent on demand: receivers
    /// would expect it periodically and call it lost.
    pub(super) fn check_send_type(&mut self, frame: &Frame<'_>, cycle_time_ms: Option<u32>) {
        let Some(ms) = cycle_time_ms else { return };
        let send_type = match self.message_attribute("GenMsgSendType", frame.msg.id) {
            Some(AttributeValue::String(name)) => name.clone(),
            Some(AttributeValue::Uint(i)) => {
                self.enum_name("GenMsgSendType", usize::try_from(*i).ok())
            }
            Some(AttributeValue::Int(i)) => {
                self.enum_name("GenMsgSendType", usize::try_from(*i).ok())
            }
            _ => return,
        };
        if send_type == "NoMsgSendType" {
            self.r.report(
                Code::CycleTimeOnEvent,
                frame.line,
                format!(
                    "message `{}` is sent on demand (GenMsgSendType NoMsgSendType) but declares a cycle time of {ms} ms",
                    frame.name
                ),
                "remove its GenMsgCycleTime, or make it Cyclic if it is sent periodically",
            );
        }
    }
}
