//! Which addresses may be an XCP master: networks in CIDR form (`10.9.0.0/24`, `::1/128`).

use std::net::IpAddr;
use thiserror::Error;

/// One allowed network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Network {
    address: IpAddr,
    prefix: u8,
}

/// Why an allow-list entry is not a network.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{entry:?} is not a network such as 10.9.0.0/24 or 10.9.0.2 ({why})")]
pub struct NetworkError {
    pub entry: String,
    pub why: &'static str,
}

impl std::str::FromStr for Network {
    type Err = NetworkError;

    fn from_str(entry: &str) -> Result<Self, Self::Err> {
        let error = |why| NetworkError {
            entry: entry.to_owned(),
            why,
        };
        let (address, prefix) = match entry.split_once('/') {
            Some((address, prefix)) => (address, Some(prefix)),
            None => (entry, None),
        };
        let address: IpAddr = address.trim().parse().map_err(|_| error("bad address"))?;
        let bits = if address.is_ipv4() { 32 } else { 128 };
        let prefix = match prefix {
            Some(prefix) => prefix.trim().parse().map_err(|_| error("bad prefix"))?,
            None => bits,
        };
        if prefix > bits {
            return Err(error("prefix longer than the address"));
        }
        Ok(Self { address, prefix })
    }
}

impl Network {
    /// True when `peer` is in this network (an IPv4 peer seen as IPv4-mapped IPv6 counts as
    /// IPv4).
    pub fn contains(&self, peer: IpAddr) -> bool {
        let peer = match peer {
            IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(peer, IpAddr::V4),
            v4 => v4,
        };
        match (self.address, peer) {
            (IpAddr::V4(net), IpAddr::V4(peer)) => {
                same_prefix(&net.octets(), &peer.octets(), self.prefix)
            }
            (IpAddr::V6(net), IpAddr::V6(peer)) => {
                same_prefix(&net.octets(), &peer.octets(), self.prefix)
            }
            _ => false,
        }
    }
}

/// True when the first `prefix` bits of `a` and `b` are equal.
fn same_prefix(a: &[u8], b: &[u8], prefix: u8) -> bool {
    let whole = usize::from(prefix / 8);
    let rest = prefix % 8;
    if a.get(..whole) != b.get(..whole) {
        return false;
    }
    if rest == 0 {
        return true;
    }
    let mask = 0xFFu8 << (8 - rest);
    match (a.get(whole), b.get(whole)) {
        (Some(x), Some(y)) => x & mask == y & mask,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn network(text: &str) -> Network {
        text.parse().expect("a network")
    }

    #[test]
    fn networks_hold_their_addresses_and_no_others() {
        let pit = network("10.9.0.0/24");
        assert!(pit.contains("10.9.0.2".parse().unwrap()));
        assert!(!pit.contains("10.9.1.2".parse().unwrap()));
        let one = network("10.9.0.2");
        assert!(one.contains("10.9.0.2".parse().unwrap()));
        assert!(!one.contains("10.9.0.3".parse().unwrap()));
        assert!(network("10.8.0.0/15").contains("10.9.255.1".parse().unwrap()));
        assert!(network("0.0.0.0/0").contains("192.168.1.1".parse().unwrap()));
        assert!(network("::1/128").contains("::1".parse().unwrap()));
        assert!(!network("::1/128").contains("127.0.0.1".parse().unwrap()));
        // A dual-stack listener sees IPv4 peers as IPv4-mapped IPv6.
        assert!(network("127.0.0.1/32").contains("::ffff:127.0.0.1".parse().unwrap()));
    }

    #[test]
    fn entries_that_are_not_networks_are_refused_with_the_reason() {
        for (entry, why) in [
            ("10.9.0.0/33", "prefix longer than the address"),
            ("10.9.0/24", "bad address"),
            ("10.9.0.0/x", "bad prefix"),
            ("pit", "bad address"),
        ] {
            let error = entry.parse::<Network>().expect_err(entry);
            assert_eq!(error.why, why, "{entry}");
        }
    }
}
