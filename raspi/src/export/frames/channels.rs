//! Bus names (`can0`) as the channel numbers the Vector and ASAM tools count (1 = the first
//! CAN channel).

use std::collections::BTreeMap;
use std::sync::Arc;

/// Each interface's channel: its trailing number plus one (`can0` is channel 1, `vcan2` is
/// channel 3), so a bus keeps its channel whichever buses a session happened to use. A name
/// without a number, or whose channel another name took first, gets the next free channel.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Channels {
    by_name: BTreeMap<Arc<str>, u16>,
}

impl Channels {
    /// Gives `interface` a channel, if it has none yet.
    pub fn add(&mut self, interface: &Arc<str>) {
        if self.by_name.contains_key(interface) {
            return;
        }
        let taken = |channel: u16| self.by_name.values().any(|&c| c == channel);
        let numbered = trailing_number(interface)
            .and_then(|n| n.checked_add(1))
            .filter(|&channel| !taken(channel));
        let channel = numbered.unwrap_or_else(|| (1..=u16::MAX).find(|&c| !taken(c)).unwrap_or(0));
        self.by_name.insert(interface.clone(), channel);
    }

    /// The channel of `interface` (0 for a name never added: no writer is given one).
    pub fn of(&self, interface: &str) -> u16 {
        self.by_name.get(interface).copied().unwrap_or(0)
    }

    /// Every interface and its channel, by channel.
    pub fn listed(&self) -> Vec<(u16, &str)> {
        let mut listed: Vec<(u16, &str)> =
            self.by_name.iter().map(|(name, &c)| (c, &**name)).collect();
        listed.sort_unstable();
        listed
    }

    /// `1 = can0, 2 = can1`: how an export says which bus each channel is.
    pub fn describe(&self) -> String {
        self.listed()
            .iter()
            .map(|(channel, name)| format!("{channel} = {name}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The number a name ends with (`can1` -> 1), if it is small enough to be a channel.
fn trailing_number(name: &str) -> Option<u16> {
    let digits = name.len() - name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
    name.get(name.len() - digits..)?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channels(names: &[&str]) -> Channels {
        let mut channels = Channels::default();
        for name in names {
            channels.add(&Arc::from(*name));
        }
        channels
    }

    #[test]
    fn a_bus_keeps_its_number_whichever_buses_came_first() {
        let c = channels(&["can1", "can0"]);
        assert_eq!((c.of("can0"), c.of("can1")), (1, 2));
        assert_eq!(channels(&["can2"]).of("can2"), 3);
        assert_eq!(c.describe(), "1 = can0, 2 = can1");
    }

    #[test]
    fn names_without_a_free_number_get_the_next_free_channel() {
        let c = channels(&["can0", "vcan0", "replay", "can1"]);
        assert_eq!(c.of("can0"), 1);
        assert_eq!(c.of("vcan0"), 2);
        assert_eq!(c.of("replay"), 3);
        // can1's own channel went to vcan0: the next free one.
        assert_eq!(c.of("can1"), 4);
        assert_eq!(c.of("never-seen"), 0);
        assert_eq!(channels(&["x99999999"]).of("x99999999"), 1);
    }
}
