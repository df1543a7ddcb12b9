//! The bus load a schema implies: every periodic message's frame at its worst-case length
//! (stuff bits included) over its cycle time, per bus, plus the telemetry packet's ISO-TP
//! frames on the bus it is sent on. A signal added at 1 kHz shows here at `cargo build`,
//! not first on the car.

use crate::model::{Database, Telemetry};

/// The bit rate assumed when the schema gives none (the car's buses run at 500 kbit/s).
pub(crate) const DEFAULT_BIT_RATE: u32 = 500_000;
/// Above this share of the bit rate (worst-case stuffing) the generator warns (W0210): the
/// headroom arbitration needs for the lowest-priority frames to keep their latency, and for
/// retransmissions after errors.
pub(crate) const WARN_LOAD: f64 = 0.5;
/// The bus name for messages of a file that names no buses.
pub(crate) const UNNAMED_BUS: &str = "CAN";

/// One bus's load.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct BusLoad {
    pub bus: String,
    /// Periodic messages on it.
    pub messages: usize,
    /// Messages on it without a cycle time (sent on demand: not counted).
    pub on_demand: usize,
    /// Frames per second (the telemetry packet's counted frame by frame).
    pub frames_per_s: f64,
    /// Bits per second at worst-case stuffing.
    pub bits_per_s: f64,
    /// `bits_per_s` over the bit rate.
    pub load: f64,
}

pub(crate) use crate::runtime::frame_bits::frame_bits;

/// Every bus's load: the DBC's periodic messages, and the telemetry packet (its first and
/// consecutive frames and one flow control frame, all 8 bytes) on its bus.
pub(crate) fn loads(db: &Database, telemetry: Option<&Telemetry>) -> Vec<BusLoad> {
    let bit_rate = f64::from(db.bit_rate.unwrap_or(DEFAULT_BIT_RATE).max(1));
    let mut loads: Vec<BusLoad> = Vec::new();
    let mut on = |bus: &str, periodic: bool, frames_per_s: f64, bits_per_s: f64| {
        let index = match loads.iter().position(|l| l.bus == bus) {
            Some(index) => index,
            None => {
                loads.push(BusLoad {
                    bus: bus.to_owned(),
                    messages: 0,
                    on_demand: 0,
                    frames_per_s: 0.0,
                    bits_per_s: 0.0,
                    load: 0.0,
                });
                loads.len() - 1
            }
        };
        if let Some(load) = loads.get_mut(index) {
            if periodic {
                load.messages += 1;
            } else {
                load.on_demand += 1;
            }
            load.frames_per_s += frames_per_s;
            load.bits_per_s += bits_per_s;
            load.load = load.bits_per_s / bit_rate;
        }
    };
    for m in &db.messages {
        let buses: Vec<&str> = if m.buses.is_empty() {
            vec![UNNAMED_BUS]
        } else {
            m.buses.iter().map(String::as_str).collect()
        };
        let rate = m.cycle_time_ms.map_or(0.0, |ms| 1_000.0 / f64::from(ms));
        let bits = f64::from(frame_bits(m.len, m.extended)) * rate;
        for bus in buses {
            on(bus, m.cycle_time_ms.is_some(), rate, bits);
        }
    }
    if let Some(t) = telemetry {
        let frames = isotp_frames(t.len) as f64;
        let rate = 1_000.0 / f64::from(t.period_ms.max(1));
        let bus = t.bus.as_deref().unwrap_or(UNNAMED_BUS);
        on(
            bus,
            true,
            frames * rate,
            frames * rate * f64::from(frame_bits(8, false)),
        );
    }
    loads
}

/// The load of the telemetry's bus with the packet grown by its planned headroom, `None`
/// without headroom.
pub(crate) fn planned(db: &Database, t: &Telemetry) -> Option<BusLoad> {
    if t.headroom_bytes == 0 {
        return None;
    }
    let grown = Telemetry {
        len: t.len + t.headroom_bytes,
        ..t.clone()
    };
    let bus = t.bus.as_deref().unwrap_or(UNNAMED_BUS);
    loads(db, Some(&grown)).into_iter().find(|l| l.bus == bus)
}

/// ISO-TP frames a packet of `len` bytes takes on classic CAN: a single frame up to 7 bytes,
/// else a first frame (6 bytes), consecutive frames (7 each) and one flow control frame.
pub(crate) fn isotp_frames(len: usize) -> usize {
    if len <= 7 {
        1
    } else {
        2 + len.saturating_sub(6).div_ceil(7)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worst_case_frame_lengths_match_the_standard() {
        // 8 data bytes: 111 bits nominal + 24 stuff bits (standard), 131 + 29 (extended); both
        // with the 3-bit interframe space.
        assert_eq!(frame_bits(8, false), 135);
        assert_eq!(frame_bits(8, true), 160);
        assert_eq!(frame_bits(0, false), 55);
        assert_eq!(frame_bits(2, true), 100);
    }
}
