//! What the buses carry, measured: each bus's frames and bits, and each message's rate, over
//! the window since the last report, beside what the schema declares (the build-time bus
//! load in `generated/docs/can.md`, each message's cycle time). Bits are counted with the
//! generator's own formula (`aer::runtime::frame_bits`, worst-case stuffing), so the measured
//! load and the declared one compare like for like. Rates come from the frames' own receive
//! times, so a replay reports the rates of the recorded session however fast it runs.

use aer::runtime::{BIT_RATE, MessageMeta, frame_bits};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};

/// One bus's traffic in the window, as the status reports it.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct BusTraffic {
    /// Frames in the window.
    pub frames: u64,
    pub frames_per_s: f64,
    /// Bits per second on the wire, worst-case stuffing.
    pub bits_per_s: f64,
    /// `bits_per_s` over the schema's bit rate (`aer::runtime::BIT_RATE`): 0.40 is 40 %.
    pub load: f64,
}

/// One message's rate on one bus in the window against its declared cycle time.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct MessageRate {
    /// Frames in the window.
    pub frames: u64,
    /// Frames per second measured (`null` below two frames).
    pub measured_hz: Option<f64>,
    /// What the schema's cycle time implies (`null` for a message sent on demand).
    pub declared_hz: Option<f64>,
}

/// Frames counted since the window started, and when the first and the last came.
#[derive(Debug, Clone, Copy, Default)]
struct Window {
    frames: u64,
    first_us: u64,
    last_us: u64,
}

impl Window {
    fn add(&mut self, ts_us: u64) {
        if self.frames == 0 {
            self.first_us = ts_us;
        }
        self.frames += 1;
        self.first_us = self.first_us.min(ts_us);
        self.last_us = self.last_us.max(ts_us);
    }

    fn rate(&self) -> Option<f64> {
        measured_hz(self.frames, self.first_us, self.last_us)
    }
}

/// Frames per second of `frames` received from `first_us` to `last_us`: the intervals between
/// them over their span (`None` below two frames, or with no time between them).
pub fn measured_hz(frames: u64, first_us: u64, last_us: u64) -> Option<f64> {
    let span_us = last_us.saturating_sub(first_us);
    (frames >= 2 && span_us > 0).then(|| (frames - 1) as f64 * 1e6 / span_us as f64)
}

/// The rate `meta`'s cycle time declares (`None` for a message sent on demand).
pub fn declared_hz(meta: &MessageMeta) -> Option<f64> {
    meta.cycle_time_ms
        .filter(|ms| *ms > 0)
        .map(|ms| 1_000.0 / f64::from(ms))
}

/// The meter: every frame of every bus, every decoded message.
#[derive(Debug, Default)]
pub struct Traffic {
    /// By bus number.
    buses: Vec<(Window, u64)>,
    /// By bus number and message name: a message sent on two buses (CCM_Status) has a rate
    /// on each.
    messages: HashMap<(u8, &'static str), (&'static MessageMeta, Window)>,
    /// Interface names by bus number (`bus<N>` for a bus not named).
    names: Vec<String>,
}

impl Traffic {
    /// Names bus `index` (its interface, such as `can0`), as the sources announce them.
    pub fn name_bus(&mut self, index: u8, name: &str) {
        let index = usize::from(index);
        if self.names.len() <= index {
            self.names.resize(index + 1, String::new());
        }
        if let Some(slot) = self.names.get_mut(index) {
            name.clone_into(slot);
        }
    }

    /// A frame of `len` payload bytes on `bus`, received at `ts_us`.
    pub fn frame(&mut self, bus: u8, ts_us: u64, len: usize, extended: bool) {
        let bus = usize::from(bus);
        if self.buses.len() <= bus {
            self.buses.resize(bus + 1, Default::default());
        }
        if let Some((window, bits)) = self.buses.get_mut(bus) {
            window.add(ts_us);
            *bits += u64::from(frame_bits(len, extended));
        }
    }

    /// A frame of message `meta` on `bus`, received at `ts_us`.
    pub fn message(&mut self, bus: u8, meta: &'static MessageMeta, ts_us: u64) {
        self.messages
            .entry((bus, meta.name))
            .or_insert((meta, Window::default()))
            .1
            .add(ts_us);
    }

    /// Each bus's traffic in the window, by interface name (buses that carried nothing are
    /// left out).
    pub fn buses(&self) -> BTreeMap<String, BusTraffic> {
        self.buses
            .iter()
            .enumerate()
            .filter(|(_, (window, _))| window.frames > 0)
            .map(|(bus, (window, bits))| {
                let name = self.bus_name(bus);
                let frames_per_s = window.rate().unwrap_or(0.0);
                // The window's average frame at the measured frame rate.
                let bits_per_s = *bits as f64 / window.frames as f64 * frames_per_s;
                let traffic = BusTraffic {
                    frames: window.frames,
                    frames_per_s,
                    bits_per_s,
                    load: bits_per_s / f64::from(BIT_RATE.max(1)),
                };
                (name, traffic)
            })
            .collect()
    }

    /// Each message's rate in the window, by interface and schema name (messages not seen
    /// are left out).
    pub fn messages(&self) -> BTreeMap<String, BTreeMap<String, MessageRate>> {
        let mut rates: BTreeMap<String, BTreeMap<String, MessageRate>> = BTreeMap::new();
        for ((bus, name), (meta, window)) in &self.messages {
            let rate = MessageRate {
                frames: window.frames,
                measured_hz: window.rate(),
                declared_hz: declared_hz(meta),
            };
            rates
                .entry(self.bus_name(usize::from(*bus)))
                .or_default()
                .insert((*name).to_owned(), rate);
        }
        rates
    }

    /// Bus `index`'s interface name, `bus<N>` before the source has named it.
    fn bus_name(&self, index: usize) -> String {
        self.names
            .get(index)
            .filter(|name| !name.is_empty())
            .cloned()
            .unwrap_or_else(|| format!("bus{index}"))
    }

    /// Starts a new window (after each report).
    pub fn restart(&mut self) {
        self.buses
            .iter_mut()
            .for_each(|bus| *bus = Default::default());
        self.messages.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aer::can::{DtiTemperatures, Mcu1};

    #[test]
    fn rates_and_load_follow_the_frames_own_times() {
        let mut traffic = Traffic::default();
        traffic.name_bus(0, "can0");
        // 101 MCU1 frames 10 ms apart on can0 (1 s), 3 DTI_Temperatures 100 ms apart on bus 1.
        for i in 0..=100 {
            traffic.frame(0, 1_000_000 + i * 10_000, 8, false);
            traffic.message(0, Mcu1::META, 1_000_000 + i * 10_000);
        }
        for i in 0..3 {
            traffic.frame(1, 5_000_000 + i * 100_000, 8, true);
            traffic.message(1, DtiTemperatures::META, 5_000_000 + i * 100_000);
        }
        let buses = traffic.buses();
        let can0 = buses["can0"];
        assert_eq!(can0.frames, 101);
        assert!((can0.frames_per_s - 100.0).abs() < 1e-9);
        // 135 bits a standard 8-byte frame at worst-case stuffing, 100 a second, of 500 kbit/s.
        assert!((can0.bits_per_s - 13_500.0).abs() < 1e-6, "{can0:?}");
        assert!((can0.load - 0.027).abs() < 1e-9);
        assert!((buses["bus1"].frames_per_s - 10.0).abs() < 1e-9);

        let messages = traffic.messages();
        let mcu1 = messages["can0"]["MCU1"];
        assert_eq!(mcu1.frames, 101);
        assert!((mcu1.measured_hz.unwrap() - 100.0).abs() < 1e-9);
        assert_eq!(
            mcu1.declared_hz,
            Some(1_000.0 / f64::from(Mcu1::CYCLE_TIME_MS))
        );
        let dti = messages["bus1"]["DTI_Temperatures"];
        assert!((dti.measured_hz.unwrap() - 10.0).abs() < 1e-9);

        traffic.restart();
        assert!(traffic.buses().is_empty() && traffic.messages().is_empty());
        // One frame gives no rate.
        traffic.message(0, Mcu1::META, 9);
        assert_eq!(traffic.messages()["can0"]["MCU1"].measured_hz, None);
    }
}
