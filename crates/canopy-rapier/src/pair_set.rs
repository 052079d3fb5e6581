//! Candidate and live pairs. A *candidate* is a pair whose fat boxes overlap. It becomes *live*
//! (reported to Rapier with `AddPair`) once the exact collision boxes overlap, and stays live
//! until it stops being a candidate (fat boxes apart, filter, removal): Rapier's narrow phase
//! pays for every pair it is told about, so pairs that fat boxes alone bring together (the
//! margin, the velocity stretch) are not reported until they matter. Only candidates that are
//! not live yet need checking, and per proxy a count of them says whether there are any, so
//! resting stacks, where every candidate is live, cost nothing here.
//!
//! Storage: a hash map of candidate keys for "is this pair new?", per proxy the list of its
//! candidate partners with the pair's live flag (kept in both partners' lists) and the number of
//! its candidates not live yet, and one flat list of the candidates not live yet (the map holds
//! each one's place in it), which the liveness pass reads front to back when many proxies have
//! some, instead of chasing every such proxy's partner list.

use rustc_hash::FxHashMap;

/// The place in the waiting list of a candidate that is live.
const LIVE: u32 = u32::MAX;

/// The two proxy ids of a key, smaller first.
#[inline]
pub(crate) fn unkey(k: u64) -> (u32, u32) {
    ((k >> 32) as u32, k as u32)
}

#[inline]
fn key(a: u32, b: u32) -> u64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    ((lo as u64) << 32) | hi as u64
}

/// One entry of a proxy's partner list.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Edge {
    pub other: u32,
    pub live: bool,
}

#[derive(Clone, Debug, Default)]
pub(crate) struct PairSet {
    /// Candidate key -> its index in `waiting_list`, or [`LIVE`].
    candidates: FxHashMap<u64, u32>,
    /// Keys of the candidates that are not live, in no particular order.
    waiting_list: Vec<u64>,
    adjacency: Vec<Vec<Edge>>,
    /// Per proxy: number of its candidates that are not live.
    waiting: Vec<u32>,
    live: usize,
}

impl PairSet {
    /// Number of live pairs.
    pub fn live_len(&self) -> usize {
        self.live
    }

    /// Number of candidate pairs (live or not).
    pub fn candidate_len(&self) -> usize {
        self.candidates.len()
    }

    fn adj_mut(&mut self, a: u32) -> &mut Vec<Edge> {
        let a = a as usize;
        if a >= self.adjacency.len() {
            self.adjacency.resize_with(a + 1, Vec::new);
            self.waiting.resize(a + 1, 0);
        }
        &mut self.adjacency[a]
    }

    /// Number of candidates of `a` that are not live yet.
    pub fn waiting(&self, a: u32) -> u32 {
        self.waiting.get(a as usize).copied().unwrap_or(0)
    }

    fn count_waiting(&mut self, a: u32, b: u32, delta: i32) {
        for x in [a, b] {
            let w = &mut self.waiting[x as usize];
            *w = (*w as i32 + delta) as u32;
        }
    }

    /// `true` when `a`-`b` is a live pair.
    pub fn is_live(&self, a: u32, b: u32) -> bool {
        self.partners(a).iter().any(|e| e.other == b && e.live)
    }

    /// Adds a candidate (not live); `false` when it was already there.
    pub fn insert(&mut self, a: u32, b: u32) -> bool {
        let k = key(a, b);
        let place = self.waiting_list.len() as u32;
        match self.candidates.entry(k) {
            std::collections::hash_map::Entry::Occupied(_) => return false,
            std::collections::hash_map::Entry::Vacant(v) => {
                v.insert(place);
            }
        }
        self.waiting_list.push(k);
        self.adj_mut(a).push(Edge {
            other: b,
            live: false,
        });
        self.adj_mut(b).push(Edge {
            other: a,
            live: false,
        });
        self.count_waiting(a, b, 1);
        true
    }

    /// Sets the live flag of candidate `a`-`b`; returns the previous flag.
    pub fn set_live(&mut self, a: u32, b: u32, live: bool) -> bool {
        let mut was = false;
        for (x, y) in [(a, b), (b, a)] {
            if let Some(e) = self.adj_mut(x).iter_mut().find(|e| e.other == y) {
                was = e.live;
                e.live = live;
            }
        }
        if was != live {
            let k = key(a, b);
            if live {
                self.live += 1;
                self.count_waiting(a, b, -1);
                if let Some(at) = self.candidates.get_mut(&k) {
                    let i = std::mem::replace(at, LIVE);
                    self.drop_waiting(i);
                }
            } else {
                self.live -= 1;
                self.count_waiting(a, b, 1);
                let place = self.waiting_list.len() as u32;
                self.waiting_list.push(k);
                self.candidates.insert(k, place);
            }
        }
        was
    }

    /// Takes entry `i` out of the waiting list (nothing for [`LIVE`]); the key moved into its
    /// place gets its new index in the map.
    fn drop_waiting(&mut self, i: u32) {
        if i == LIVE {
            return;
        }
        self.waiting_list.swap_remove(i as usize);
        if let Some(&moved) = self.waiting_list.get(i as usize) {
            if let Some(m) = self.candidates.get_mut(&moved) {
                *m = i;
            }
        }
    }

    /// Keys of the candidates that are not live (see [`unkey`]).
    pub fn waiting_list(&self) -> &[u64] {
        &self.waiting_list
    }

    /// Removes candidate `a`-`b`; returns whether it was live (`None` when it was not there).
    pub fn remove(&mut self, a: u32, b: u32) -> Option<bool> {
        let i = self.candidates.remove(&key(a, b))?;
        self.drop_waiting(i);
        let mut live = false;
        for (x, y) in [(a, b), (b, a)] {
            let adj = self.adj_mut(x);
            if let Some(i) = adj.iter().position(|e| e.other == y) {
                live = adj[i].live;
                adj.swap_remove(i);
            }
        }
        if live {
            self.live -= 1;
        } else {
            self.count_waiting(a, b, -1);
        }
        Some(live)
    }

    /// Candidate partners of `a`.
    pub fn partners(&self, a: u32) -> &[Edge] {
        self.adjacency
            .get(a as usize)
            .map(Vec::as_slice)
            .unwrap_or(&[])
    }

    /// Removes every candidate of `a`; returns the former partners (with live flags), in list
    /// order.
    pub fn remove_all(&mut self, a: u32) -> Vec<Edge> {
        let partners = std::mem::take(self.adj_mut(a));
        for e in &partners {
            if let Some(i) = self.candidates.remove(&key(a, e.other)) {
                self.drop_waiting(i);
            }
            let adj = self.adj_mut(e.other);
            if let Some(i) = adj.iter().position(|f| f.other == a) {
                adj.swap_remove(i);
            }
            if e.live {
                self.live -= 1;
            } else {
                self.waiting[e.other as usize] -= 1;
            }
        }
        self.waiting[a as usize] = 0;
        partners
    }

    /// Every live pair, each once as `(a, b)` with `a < b`, in no particular order.
    pub fn live_pairs(&self) -> impl Iterator<Item = (u32, u32)> + '_ {
        self.adjacency.iter().enumerate().flat_map(|(a, adj)| {
            adj.iter()
                .filter(move |e| e.live && (a as u32) < e.other)
                .map(move |e| (a as u32, e.other))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::BTreeMap;

    #[derive(Clone, Debug)]
    enum Op {
        Insert(u32, u32),
        Live(u32, u32),
        Remove(u32, u32),
        RemoveAll(u32),
    }

    fn op() -> impl Strategy<Value = Op> {
        let id = 0u32..12;
        prop_oneof![
            4 => (id.clone(), id.clone()).prop_map(|(a, b)| Op::Insert(a, b)),
            3 => (id.clone(), id.clone()).prop_map(|(a, b)| Op::Live(a, b)),
            2 => (id.clone(), id.clone()).prop_map(|(a, b)| Op::Remove(a, b)),
            1 => id.prop_map(Op::RemoveAll),
        ]
    }

    proptest! {
        /// Against a map of candidate -> live flag: the answers of every call, the counts, the
        /// per-proxy waiting counts and partner lists, and the flat waiting list.
        #[test]
        fn matches_a_plain_map(ops in prop::collection::vec(op(), 0..200)) {
            let mut set = PairSet::default();
            let mut model: BTreeMap<(u32, u32), bool> = BTreeMap::new();
            let norm = |a: u32, b: u32| (a.min(b), a.max(b));
            for op in ops {
                match op {
                    Op::Insert(a, b) if a != b => {
                        let new = !model.contains_key(&norm(a, b));
                        prop_assert_eq!(set.insert(a, b), new);
                        model.entry(norm(a, b)).or_insert(false);
                    }
                    Op::Live(a, b) if a != b => {
                        if let Some(live) = model.get_mut(&norm(a, b)) {
                            prop_assert_eq!(set.set_live(a, b, true), *live);
                            *live = true;
                        }
                    }
                    Op::Remove(a, b) if a != b => {
                        prop_assert_eq!(set.remove(a, b), model.remove(&norm(a, b)));
                    }
                    Op::RemoveAll(a) => {
                        let mut gone: Vec<(u32, bool)> = set
                            .remove_all(a)
                            .iter()
                            .map(|e| (e.other, e.live))
                            .collect();
                        gone.sort();
                        let mut expected = Vec::new();
                        model.retain(|&(x, y), &mut live| {
                            if x == a || y == a {
                                expected.push((if x == a { y } else { x }, live));
                                false
                            } else {
                                true
                            }
                        });
                        expected.sort();
                        prop_assert_eq!(gone, expected);
                    }
                    _ => {}
                }
                prop_assert_eq!(set.candidate_len(), model.len());
                prop_assert_eq!(set.live_len(), model.values().filter(|&&l| l).count());
                let mut waiting: Vec<(u32, u32)> =
                    set.waiting_list().iter().map(|&k| unkey(k)).collect();
                waiting.sort();
                let expected: Vec<(u32, u32)> =
                    model.iter().filter(|(_, &l)| !l).map(|(&p, _)| p).collect();
                prop_assert_eq!(waiting, expected);
                for id in 0..12u32 {
                    let w = model.iter().filter(|(&(x, y), &l)| !l && (x == id || y == id)).count();
                    prop_assert_eq!(set.waiting(id) as usize, w);
                    let mut partners: Vec<(u32, bool)> =
                        set.partners(id).iter().map(|e| (e.other, e.live)).collect();
                    partners.sort();
                    let mut expected: Vec<(u32, bool)> = model
                        .iter()
                        .filter(|(&(x, y), _)| x == id || y == id)
                        .map(|(&(x, y), &l)| (if x == id { y } else { x }, l))
                        .collect();
                    expected.sort();
                    prop_assert_eq!(partners, expected);
                }
            }
        }
    }
}
