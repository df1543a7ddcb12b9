//! Which signals of a message can share a frame, in time linear in the signals: the order
//! multiplexors must be decoded in, and overlapping bits between signals that can be present
//! together.
//!
//! Multiplexing makes a forest: each multiplexed signal hangs below its selector. Two signals
//! can never share a frame exactly when, where their chains to the root part, the branches
//! take disjoint values of the same selector (above that the chains are the same signals with
//! the same conditions). Comparing signals only per bit they occupy, and alternatives of one
//! selector by their values through a map, keeps a file with thousands of alternatives at the
//! same bits linear, where comparing every pair was quadratic.

use std::collections::HashMap;

use crate::model::{MuxCondition, Signal};

/// Alternatives with value ranges wider than this are compared by scanning, not by value.
const MAX_EXPANDED_VALUES: u64 = 256;

/// The order to decode the signals in, each multiplexor before what it selects: signals in
/// index order, each as early as a pass over them in that order would reach it. `None` when
/// the multiplexors select each other in a cycle.
pub(super) fn decode_order(signals: &[Signal]) -> Option<Vec<usize>> {
    // pass[i]: the pass that reaches signal i. A signal is reached in its selector's pass when
    // it comes after its selector, or in the pass after.
    let mut pass: Vec<Option<usize>> = vec![None; signals.len()];
    let mut chain = Vec::new();
    for start in 0..signals.len() {
        // Walk up until a signal whose pass is known, or the top of the chain.
        let mut i = start;
        let mut above: Option<(usize, usize)> = loop {
            if let Some(p) = pass.get(i).copied().flatten() {
                break Some((i, p));
            }
            if chain.len() > signals.len() {
                return None;
            }
            chain.push(i);
            match selector(signals, i) {
                Some(up) => i = up,
                None => break None,
            }
        };
        // Then assign passes on the way back down.
        while let Some(j) = chain.pop() {
            let p = above.map_or(0, |(sel, p)| p + usize::from(sel > j));
            if let Some(slot) = pass.get_mut(j) {
                *slot = Some(p);
            }
            above = Some((j, p));
        }
    }
    let mut order: Vec<usize> = (0..signals.len()).collect();
    order.sort_by_key(|&i| (pass.get(i).copied().flatten(), i));
    Some(order)
}

/// For each signal that overlaps earlier ones it can share a frame with: (each such earlier
/// signal, the signal), sorted. `order` is the [`decode_order`].
pub(super) fn overlaps(signals: &[Signal], order: &[usize]) -> Vec<(usize, usize)> {
    let forest = Forest::new(signals, order);
    // Per bit, the signals there grouped by their selector (few groups per bit).
    let mut at_bit: Vec<Vec<(Option<usize>, Alternatives)>> = Vec::new();
    let mut found = Vec::new();
    for (b, signal) in signals.iter().enumerate() {
        let bits = signal.bits();
        // Every earlier signal it conflicts with (one per bit and group is enough: a signal
        // over several others meets each of them at some bit).
        let conflicts: std::collections::BTreeSet<usize> = bits
            .iter()
            .filter_map(|&bit| at_bit.get(bit as usize))
            .flatten()
            .filter_map(|(selector, group)| forest.first_conflict(b, *selector, group))
            .collect();
        found.extend(conflicts.into_iter().map(|a| (a, b)));
        let selector = signal.mux.as_ref().map(|m| m.selector);
        for bit in bits {
            let bit = bit as usize;
            if at_bit.len() <= bit {
                at_bit.resize_with(bit + 1, Vec::new);
            }
            let Some(groups) = at_bit.get_mut(bit) else {
                continue;
            };
            let at = match groups.iter().position(|(s, _)| *s == selector) {
                Some(at) => at,
                None => {
                    groups.push((selector, Alternatives::new(b)));
                    groups.len() - 1
                }
            };
            if let Some((_, group)) = groups.get_mut(at) {
                group.add(b, signal.mux.as_ref());
            }
        }
    }
    found.sort_unstable();
    found
}

fn selector(signals: &[Signal], i: usize) -> Option<usize> {
    signals.get(i)?.mux.as_ref().map(|m| m.selector)
}

/// The signals at one bit under one selector (or under none), earliest first.
struct Alternatives {
    first: usize,
    /// The earliest signal selected by each value.
    by_value: HashMap<u64, usize>,
    /// Signals selected by value ranges too wide to list.
    wide: Vec<(usize, Vec<(u64, u64)>)>,
}

impl Alternatives {
    fn new(first: usize) -> Self {
        Self {
            first,
            by_value: HashMap::new(),
            wide: Vec::new(),
        }
    }

    fn add(&mut self, index: usize, condition: Option<&MuxCondition>) {
        let Some(condition) = condition else {
            return;
        };
        if span(&condition.ranges) <= MAX_EXPANDED_VALUES {
            for &(lo, hi) in &condition.ranges {
                for value in lo..=hi {
                    self.by_value.entry(value).or_insert(index);
                }
            }
        } else {
            self.wide.push((index, condition.ranges.clone()));
        }
    }

    /// The earliest alternative selected by any value in `ranges`.
    fn first_selected_by(&self, ranges: &[(u64, u64)]) -> Option<usize> {
        let listed = if span(ranges) <= MAX_EXPANDED_VALUES {
            ranges
                .iter()
                .flat_map(|&(lo, hi)| lo..=hi)
                .filter_map(|value| self.by_value.get(&value).copied())
                .min()
        } else {
            self.by_value
                .iter()
                .filter(|(value, _)| ranges.iter().any(|&(lo, hi)| (lo..=hi).contains(*value)))
                .map(|(_, &index)| index)
                .min()
        };
        let wide = self
            .wide
            .iter()
            .filter(|(_, theirs)| intersect(theirs, ranges))
            .map(|&(index, _)| index);
        listed.into_iter().chain(wide).min()
    }
}

/// How many values the ranges hold (saturating).
fn span(ranges: &[(u64, u64)]) -> u64 {
    ranges.iter().fold(0u64, |n, &(lo, hi)| {
        n.saturating_add(hi.saturating_sub(lo).saturating_add(1))
    })
}

fn intersect(a: &[(u64, u64)], b: &[(u64, u64)]) -> bool {
    a.iter()
        .any(|&(lo1, hi1)| b.iter().any(|&(lo2, hi2)| lo1 <= hi2 && lo2 <= hi1))
}

/// The multiplexing forest of one message.
struct Forest<'s> {
    signals: &'s [Signal],
    depth: Vec<usize>,
}

impl<'s> Forest<'s> {
    fn new(signals: &'s [Signal], order: &[usize]) -> Self {
        let mut depth = vec![0; signals.len()];
        // Decoding order puts every selector before what it selects.
        for &i in order {
            let d = selector(signals, i)
                .and_then(|s| depth.get(s).copied())
                .map_or(0, |d| d + 1);
            if let Some(slot) = depth.get_mut(i) {
                *slot = d;
            }
        }
        Self { signals, depth }
    }

    fn condition(&self, i: usize) -> Option<&'s MuxCondition> {
        self.signals.get(i)?.mux.as_ref()
    }

    fn up(&self, i: usize) -> Option<usize> {
        self.condition(i).map(|m| m.selector)
    }

    fn depth(&self, i: usize) -> usize {
        self.depth.get(i).copied().unwrap_or(0)
    }

    /// The earliest signal of `group` (all selected by `selector`, at a bit `b` uses) that can
    /// share a frame with `b`.
    fn first_conflict(
        &self,
        b: usize,
        selector: Option<usize>,
        group: &Alternatives,
    ) -> Option<usize> {
        let Some(s) = selector else {
            // Signals that are always present conflict with everything at their bits.
            return Some(group.first);
        };
        // If `s` is on b's chain, the group's own values decide: against the condition of b's
        // branch below `s`.
        if let Some(branch) = self.branch_below(b, s) {
            let ranges = self.condition(branch).map(|c| c.ranges.as_slice())?;
            return group.first_selected_by(ranges);
        }
        // Otherwise the group's values do not matter: it is present wherever `s` is.
        (!self.exclusive(s, b)).then_some(group.first)
    }

    /// The signal on `b`'s chain (b itself or above) whose selector is `s`.
    fn branch_below(&self, b: usize, s: usize) -> Option<usize> {
        let mut i = b;
        for _ in 0..=self.depth(b) {
            let up = self.up(i)?;
            if up == s {
                return Some(i);
            }
            i = up;
        }
        None
    }

    /// True when `x` and `y` can never be in the same frame.
    fn exclusive(&self, x: usize, y: usize) -> bool {
        let (mut x, mut y) = (x, y);
        // Bring both to the same depth; an ancestor is present whenever its descendant is.
        while self.depth(x) > self.depth(y) {
            match self.up(x) {
                Some(up) if up == y => return false,
                Some(up) => x = up,
                None => return false,
            }
        }
        while self.depth(y) > self.depth(x) {
            match self.up(y) {
                Some(up) if up == x => return false,
                Some(up) => y = up,
                None => return false,
            }
        }
        // Climb together until the chains meet: there the two branches' values decide.
        while x != y {
            match (self.condition(x), self.condition(y)) {
                (Some(cx), Some(cy)) if cx.selector == cy.selector => {
                    return !intersect(&cx.ranges, &cy.ranges);
                }
                (Some(cx), Some(cy)) => {
                    x = cx.selector;
                    y = cy.selector;
                }
                _ => return false,
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{ByteOrder, Encoding, PhysType};
    use proptest::prelude::*;

    /// The earlier quadratic check, kept as the oracle: for each signal with a conflict, its
    /// first earlier one.
    fn pairwise_overlaps(signals: &[Signal]) -> Vec<(usize, usize)> {
        let mut found = Vec::new();
        let mut reported = std::collections::HashSet::new();
        for (a, b) in all_pairwise_overlaps(signals) {
            if reported.insert(b) {
                found.push((a, b));
            }
        }
        found
    }

    /// Every pair of signals that share a bit and can share a frame: every pair, every
    /// condition on both chains.
    fn all_pairwise_overlaps(signals: &[Signal]) -> Vec<(usize, usize)> {
        let chain = |mut i: usize| {
            let mut conditions = Vec::new();
            while let Some(m) = signals[i].mux.as_ref() {
                conditions.push(m);
                i = m.selector;
                if conditions.len() > signals.len() {
                    break;
                }
            }
            conditions
        };
        let exclusive = |a: usize, b: usize| {
            chain(a).iter().any(|ca| {
                chain(b)
                    .iter()
                    .any(|cb| ca.selector == cb.selector && !intersect(&ca.ranges, &cb.ranges))
            })
        };
        let mut found = Vec::new();
        for a in 0..signals.len() {
            for b in a + 1..signals.len() {
                let shares = signals[a]
                    .bits()
                    .iter()
                    .any(|x| signals[b].bits().contains(x));
                if shares && !exclusive(a, b) {
                    found.push((a, b));
                }
            }
        }
        found
    }

    /// The earlier pass-by-pass decoding order.
    fn passes_order(signals: &[Signal]) -> Option<Vec<usize>> {
        let mut order = Vec::new();
        let mut done = vec![false; signals.len()];
        while order.len() < signals.len() {
            let before = order.len();
            for (i, s) in signals.iter().enumerate() {
                if !done[i] && s.mux.as_ref().is_none_or(|m| done[m.selector]) {
                    done[i] = true;
                    order.push(i);
                }
            }
            if order.len() == before {
                return None;
            }
        }
        Some(order)
    }

    fn signal(start_bit: u32, len: u32, mux: Option<MuxCondition>) -> Signal {
        Signal {
            name: String::new(),
            field: String::new(),
            start_bit,
            len,
            byte_order: ByteOrder::LittleEndian,
            encoding: Encoding::Unsigned,
            factor: 1.0,
            offset: 0.0,
            min: None,
            max: None,
            unit: String::new(),
            comment: None,
            receivers: Vec::new(),
            phys: PhysType::F64,
            value_labels: Vec::new(),
            mux,
            is_multiplexor: false,
        }
    }

    /// Up to 14 signals in 24 bits; some selected by another signal (cycles included) with
    /// one or two value ranges, some narrow, some wider than the value map takes.
    fn signals() -> impl Strategy<Value = Vec<Signal>> {
        let one = (
            0u32..20,
            1u32..5,
            prop::option::of((
                any::<prop::sample::Index>(),
                prop::collection::vec((0u64..6, prop_oneof![0u64..3, 300u64..400]), 1..3),
            )),
        );
        prop::collection::vec(one, 1..14).prop_map(|drafts| {
            let n = drafts.len();
            drafts
                .into_iter()
                .map(|(start, len, mux)| {
                    let mux = mux.map(|(selector, ranges)| MuxCondition {
                        selector: selector.index(n),
                        ranges: ranges.into_iter().map(|(lo, w)| (lo, lo + w)).collect(),
                    });
                    signal(start, len, mux)
                })
                .collect()
        })
    }

    /// The signals with every selection that would close a cycle dropped.
    fn without_cycles(mut signals: Vec<Signal>) -> Vec<Signal> {
        let wanted: Vec<Option<MuxCondition>> = signals.iter_mut().map(|s| s.mux.take()).collect();
        for (i, mux) in wanted.into_iter().enumerate() {
            let Some(mux) = mux else { continue };
            let mut up = Some(mux.selector);
            while let Some(j) = up.filter(|&j| j != i) {
                up = signals[j].mux.as_ref().map(|m| m.selector);
            }
            if up.is_none() {
                signals[i].mux = Some(mux);
            }
        }
        signals
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2_000))]

        #[test]
        fn decoding_order_matches_the_pass_by_pass_order(signals in signals()) {
            prop_assert_eq!(decode_order(&signals), passes_order(&signals));
        }

        #[test]
        fn overlaps_match_the_pairwise_check(signals in signals()) {
            // Overlaps are only checked once the order exists (no cycle).
            let signals = without_cycles(signals);
            let order = decode_order(&signals).expect("no cycle");
            // Every pair found conflicts; every signal with a conflict is found, with its
            // first earlier one (a signal over several others is reported with each it meets
            // at some bit: at least the first).
            let found = overlaps(&signals, &order);
            let pairwise = pairwise_overlaps(&signals);
            let all: std::collections::HashSet<(usize, usize)> =
                all_pairwise_overlaps(&signals).into_iter().collect();
            for pair in &found {
                prop_assert!(all.contains(pair), "{pair:?} is no conflict");
            }
            let mut first_by_b = std::collections::BTreeMap::new();
            for &(a, b) in &found {
                let first = first_by_b.entry(b).or_insert(a);
                *first = a.min(*first);
            }
            let first_found: Vec<(usize, usize)> =
                first_by_b.into_iter().map(|(b, a)| (a, b)).collect();
            let mut pairwise_by_b = pairwise.clone();
            pairwise_by_b.sort_by_key(|&(a, b)| (b, a));
            prop_assert_eq!(first_found, pairwise_by_b);
        }
    }

    #[test]
    fn alternatives_of_one_selector_at_the_same_bits_do_not_overlap() {
        let mut signals = vec![signal(0, 8, None)];
        for value in 0..200 {
            signals.push(signal(
                8,
                8,
                Some(MuxCondition {
                    selector: 0,
                    ranges: vec![(value, value)],
                }),
            ));
        }
        signals.push(signal(
            12,
            2,
            Some(MuxCondition {
                selector: 0,
                ranges: vec![(150, 160)],
            }),
        ));
        let order = decode_order(&signals).expect("no cycle");
        assert_eq!(overlaps(&signals, &order), vec![(151, 201)]);
    }
}
