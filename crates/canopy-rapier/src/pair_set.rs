//! Candidate and live pairs. A *candidate* is a pair whose fat boxes overlap. It becomes *live*
//! (reported to Rapier with `AddPair`) once the exact collision boxes overlap, and stays live
//! until it stops being a candidate (fat boxes apart, filter, removal): Rapier's narrow phase
//! pays for every pair it is told about, so pairs that fat boxes alone bring together (the
//! margin, the velocity stretch) are not reported until they matter. Only candidates that are
//! not live yet need checking, and per proxy a count of them says whether there are any, so
//! resting stacks, where every candidate is live, cost nothing here.
//!
//! Storage: a hash set of candidate keys for "is this pair new?", and per proxy the list of
//! its candidate partners with the pair's live flag (kept in both partners' lists) and the
//! number of its candidates not live yet, so that nothing ever scans all pairs.

use rustc_hash::FxHashSet;

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
    candidates: FxHashSet<u64>,
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
        if !self.candidates.insert(key(a, b)) {
            return false;
        }
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
            if live {
                self.live += 1;
                self.count_waiting(a, b, -1);
            } else {
                self.live -= 1;
                self.count_waiting(a, b, 1);
            }
        }
        was
    }

    /// Removes candidate `a`-`b`; returns whether it was live (`None` when it was not there).
    pub fn remove(&mut self, a: u32, b: u32) -> Option<bool> {
        if !self.candidates.remove(&key(a, b)) {
            return None;
        }
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
            self.candidates.remove(&key(a, e.other));
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
