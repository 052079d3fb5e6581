//! Candidate and live pairs. A *candidate* is a pair whose fat boxes overlap. It becomes *live*
//! (reported to Rapier with `AddPair`) once the exact collision boxes overlap, and stays live
//! until it stops being a candidate (fat boxes apart, filter, removal) or the broadphase sees
//! its exact boxes parted (`CanopyBroadPhaseConfig::live_pair_skin`; it is then a waiting
//! candidate again): Rapier's narrow phase pays for every pair it is told about, so pairs that
//! fat boxes alone bring together (the margin, the velocity stretch) are not reported until
//! they matter, nor kept once they stop touching. Only candidates that are not live yet need
//! checking, and per proxy a count of them says whether there are any, so resting stacks, where
//! every candidate is live, cost nothing here.
//!
//! Storage, without a hash map: per proxy the list of its candidate partners (each pair is in
//! both partners' lists), per proxy the number of its candidates not live yet, and one flat list
//! of the candidates not live yet, which the liveness pass reads front to back when many proxies
//! have some, instead of chasing every such proxy's partner list. A pair's edge in the list of
//! its smaller id holds its place in that flat list (or [`LIVE`]), and the flat list holds that
//! edge's index beside the pair; the edge in the other list only says whether it is live. Each
//! edge also holds the index of its twin (the same pair's edge in the other list), kept through
//! every removal, so every lookup of a pair scans only the shorter of the two lists (a ground or
//! a large static collider with thousands of partners is never scanned for one of them), and
//! removing all of a proxy's pairs, or moving an entry of the flat list, scans none.
//!
//! When many proxies moved, the broadphase meets every candidate that goes on in its pair
//! walks; it marks those edges *met* ([`PairSet::mark_met`], on the side of each moved
//! partner), and a moved proxy's candidates left unmarked are the ones that ended
//! ([`PairSet::take_unmet`], which also clears the marks). No partner is looked up to decide.

use crate::broad_phase::prefetch;

/// The place of a live candidate.
const LIVE: u32 = u32::MAX;
/// The place held by the edge in the larger id's list of a candidate that is not live.
const WAITING: u32 = u32::MAX - 1;
/// The bit of [`Edge::twin`] that marks an edge met by this update's pair walks; clear
/// between updates (see [`PairSet::mark_met`]). Twin indices stay below it: a partner list
/// holds at most one edge per other proxy id, far fewer than 2^31.
const MET: u32 = 1 << 31;

/// `PairSet::remove_all` asks for a partner's twin edge this many partners ahead of its turn.
const REMOVE_AHEAD: usize = 2;

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
    /// [`LIVE`]; else, in the smaller id's list, the pair's index in the waiting list, and
    /// [`WAITING`] in the other.
    place: u32,
    /// Index of the twin edge (the same pair) in the partner list of `other`, and the
    /// [`MET`] bit.
    twin: u32,
}

impl Edge {
    /// `true` when the pair is live.
    #[inline]
    pub fn live(&self) -> bool {
        self.place == LIVE
    }

    /// `true` for the edge that holds a waiting pair's place in the waiting list (the edge in
    /// the smaller id's list of a pair that is not live).
    #[inline]
    fn holds_place(&self) -> bool {
        self.place != LIVE && self.place != WAITING
    }

    /// The index of the twin edge in the partner list of `other`.
    #[inline]
    fn twin_index(&self) -> usize {
        (self.twin & !MET) as usize
    }
}

#[derive(Clone, Debug, Default)]
pub(crate) struct PairSet {
    /// Keys of the candidates that are not live, in no particular order.
    waiting_list: Vec<u64>,
    /// Per entry of `waiting_list`: the index of the pair's edge in the partner list of its
    /// smaller id (the edge that holds the entry's place), so that moving an entry needs no
    /// search of the lists.
    waiting_edge: Vec<u32>,
    adjacency: Vec<Vec<Edge>>,
    /// Per proxy: number of its candidates that are not live.
    waiting: Vec<u32>,
    live: usize,
    candidates: usize,
}

impl PairSet {
    /// Number of live pairs.
    pub fn live_len(&self) -> usize {
        self.live
    }

    /// Number of candidate pairs (live or not).
    pub fn candidate_len(&self) -> usize {
        self.candidates
    }

    fn grow(&mut self, a: u32) {
        let a = a as usize;
        if a >= self.adjacency.len() {
            self.adjacency.resize_with(a + 1, Vec::new);
            self.waiting.resize(a + 1, 0);
        }
    }

    /// Number of candidates of `a` that are not live yet.
    pub fn waiting(&self, a: u32) -> u32 {
        self.waiting.get(a as usize).copied().unwrap_or(0)
    }

    /// `true` when some candidate of `a` is live. Reads the list's length and the count of
    /// its waiting candidates, not the list.
    #[inline]
    pub fn has_live(&self, a: u32) -> bool {
        self.partners(a).len() as u32 > self.waiting(a)
    }

    fn count_waiting(&mut self, a: u32, b: u32, delta: i32) {
        for x in [a, b] {
            let w = &mut self.waiting[x as usize];
            *w = (*w as i32 + delta) as u32;
        }
    }

    /// Indices of the pair `lo`-`hi` (`lo < hi`) in the partner lists of `lo` and of `hi`,
    /// found by scanning the shorter list and following the twin.
    #[inline]
    fn find(&self, lo: u32, hi: u32) -> Option<(usize, usize)> {
        let (lo_list, hi_list) = (self.partners(lo), self.partners(hi));
        if lo_list.len() <= hi_list.len() {
            let i = lo_list.iter().position(|e| e.other == hi)?;
            Some((i, lo_list[i].twin_index()))
        } else {
            let j = hi_list.iter().position(|e| e.other == lo)?;
            Some((hi_list[j].twin_index(), j))
        }
    }

    /// `true` when `a`-`b` is a live pair.
    pub fn is_live(&self, a: u32, b: u32) -> bool {
        let (lo, hi) = (a.min(b), a.max(b));
        self.find(lo, hi)
            .is_some_and(|(i, _)| self.adjacency[lo as usize][i].live())
    }

    /// Takes edge `i` out of the partner list of `a` (swap remove), keeping the twin index of
    /// the edge moved into its place.
    fn take_edge(&mut self, a: u32, i: usize) -> Edge {
        let e = self.adjacency[a as usize].swap_remove(i);
        if let Some(&m) = self.adjacency[a as usize].get(i) {
            let t = &mut self.adjacency[m.other as usize][m.twin_index()].twin;
            *t = (*t & MET) | i as u32;
            if m.holds_place() {
                self.waiting_edge[m.place as usize] = i as u32;
            }
        }
        e
    }

    /// Marks candidate `a`-`b` as met this update: its edge in the list of `a` when `at_a`, in
    /// the list of `b` when `at_b`. Returns `false` (and marks nothing) when `a`-`b` is not a
    /// candidate. Each marked list must be read by [`PairSet::take_unmet`] before any pair is
    /// inserted or removed.
    pub fn mark_met(&mut self, a: u32, b: u32, at_a: bool, at_b: bool) -> bool {
        let (lo, hi) = (a.min(b), a.max(b));
        let Some((i, j)) = self.find(lo, hi) else {
            return false;
        };
        let (at_lo, at_hi) = if a < b { (at_a, at_b) } else { (at_b, at_a) };
        if at_lo {
            self.adjacency[lo as usize][i].twin |= MET;
        }
        if at_hi {
            self.adjacency[hi as usize][j].twin |= MET;
        }
        true
    }

    /// Pushes `(a, other)` for every candidate of `a` whose edge in the list of `a` is not
    /// marked met, in list order, and clears the marks of the others.
    pub fn take_unmet(&mut self, a: u32, out: &mut Vec<(u32, u32)>) {
        let Some(list) = self.adjacency.get_mut(a as usize) else {
            return;
        };
        for e in list {
            if e.twin & MET == 0 {
                out.push((a, e.other));
            }
            e.twin &= !MET;
        }
    }

    /// Adds `a`-`b`, which the caller knows is not a candidate (the broadphase's new pairs: a
    /// moved proxy's queries skip its known partners, and the pair walks' pairs that are
    /// candidates already are marked met and dropped), without a search of the lists; live when
    /// `live`.
    pub fn insert_new(&mut self, a: u32, b: u32, live: bool) {
        self.grow(a.max(b));
        let (lo, hi) = (a.min(b), a.max(b));
        debug_assert!(
            self.find(lo, hi).is_none(),
            "{lo}-{hi} is a candidate already"
        );
        let (i, j) = (
            self.adjacency[lo as usize].len() as u32,
            self.adjacency[hi as usize].len() as u32,
        );
        let (place, other_place) = if live {
            self.live += 1;
            (LIVE, LIVE)
        } else {
            self.waiting_list.push(key(lo, hi));
            self.waiting_edge.push(i);
            self.count_waiting(lo, hi, 1);
            (self.waiting_list.len() as u32 - 1, WAITING)
        };
        self.adjacency[lo as usize].push(Edge {
            other: hi,
            place,
            twin: j,
        });
        self.adjacency[hi as usize].push(Edge {
            other: lo,
            place: other_place,
            twin: i,
        });
        self.candidates += 1;
    }

    /// Sets the live flag of the candidate whose edge is entry `i` of the partner list of `a`
    /// (callers that read that list, or the waiting list's `waiting_edge`, know it: no search);
    /// returns the previous flag. Edges keep their indices through this call: only insertions
    /// and removals move them.
    pub fn set_live_at(&mut self, a: u32, i: usize, live: bool) -> bool {
        let e = self.adjacency[a as usize][i];
        let (b, j) = (e.other, e.twin_index());
        let (lo, hi, i, j) = if a < b { (a, b, i, j) } else { (b, a, j, i) };
        let place = self.adjacency[lo as usize][i].place;
        let was = place == LIVE;
        if was == live {
            return was;
        }
        if live {
            self.live += 1;
            self.count_waiting(lo, hi, -1);
            self.adjacency[lo as usize][i].place = LIVE;
            self.adjacency[hi as usize][j].place = LIVE;
            self.drop_waiting(place);
        } else {
            self.live -= 1;
            self.count_waiting(lo, hi, 1);
            self.adjacency[lo as usize][i].place = self.waiting_list.len() as u32;
            self.adjacency[hi as usize][j].place = WAITING;
            self.waiting_list.push(key(lo, hi));
            self.waiting_edge.push(i as u32);
        }
        was
    }

    /// Takes entry `i` out of the waiting list; the key moved into its place gets its new
    /// index in its smaller id's edge (found through `waiting_edge`, without a search).
    fn drop_waiting(&mut self, i: u32) {
        self.waiting_list.swap_remove(i as usize);
        self.waiting_edge.swap_remove(i as usize);
        if let Some(&moved) = self.waiting_list.get(i as usize) {
            let (lo, _) = unkey(moved);
            let k = self.waiting_edge[i as usize] as usize;
            self.adjacency[lo as usize][k].place = i;
        }
    }

    /// Keys of the candidates that are not live (see [`unkey`]).
    pub fn waiting_list(&self) -> &[u64] {
        &self.waiting_list
    }

    /// Per entry of [`PairSet::waiting_list`], the index of the pair's edge in the partner
    /// list of its smaller id.
    pub fn waiting_edges(&self) -> &[u32] {
        &self.waiting_edge
    }

    /// Removes candidate `a`-`b`; returns whether it was live (`None` when it was not there).
    pub fn remove(&mut self, a: u32, b: u32) -> Option<bool> {
        let (lo, hi) = (a.min(b), a.max(b));
        let (i, j) = self.find(lo, hi)?;
        let place = self.take_edge(lo, i).place;
        self.take_edge(hi, j);
        self.candidates -= 1;
        let live = place == LIVE;
        if live {
            self.live -= 1;
        } else {
            self.count_waiting(a, b, -1);
            self.drop_waiting(place);
        }
        Some(live)
    }

    /// Starts loading the head of `a`'s partner list (where the list is), without waiting.
    #[inline]
    pub fn prefetch_list_head(&self, a: u32) {
        prefetch(self.adjacency.as_ptr().wrapping_add(a as usize));
    }

    /// Starts loading the first edges of `a`'s partner list (reads its head, which
    /// `prefetch_list_head` should have asked for earlier).
    #[inline]
    pub fn prefetch_list(&self, a: u32) {
        prefetch(self.partners(a).as_ptr());
    }

    /// Candidate partners of `a`.
    pub fn partners(&self, a: u32) -> &[Edge] {
        self.adjacency
            .get(a as usize)
            .map(Vec::as_slice)
            .unwrap_or(&[])
    }

    /// Removes every candidate of `a` and appends the former partners (with live flags) to
    /// `out`, in list order. Each partner's edge is found through its twin index, without a
    /// search. The list keeps its allocation: a removed collider's index comes back with the
    /// next collider inserted (Rapier's arenas reuse freed slots), whose list then grows
    /// without reallocating (`spawn_storm`: about a third of the insertions reallocated a
    /// list before).
    pub fn remove_all(&mut self, a: u32, out: &mut Vec<Edge>) {
        let count = self.partners(a).len();
        // The partners' lists are scattered: every partner's list head is asked for at once,
        // then each twin edge a few partners ahead of its turn (its address is in the head).
        for e in self.partners(a) {
            self.prefetch_list_head(e.other);
        }
        for k in 0..count {
            if let Some(ahead) = self.partners(a).get(k + REMOVE_AHEAD) {
                let list = self.partners(ahead.other);
                prefetch(list.as_ptr().wrapping_add(ahead.twin_index()));
            }
            // Read afresh: removing earlier partners' edges may have changed this one's place
            // (an entry moved in the waiting list), never its twin (no edge of `a` moves).
            let e = self.adjacency[a as usize][k];
            let twin = self.take_edge(e.other, e.twin_index());
            self.candidates -= 1;
            if e.live() {
                self.live -= 1;
            } else {
                let w = &mut self.waiting[e.other as usize];
                *w -= 1;
                let place = if a < e.other { e.place } else { twin.place };
                self.drop_waiting(place);
            }
        }
        if let Some(w) = self.waiting.get_mut(a as usize) {
            *w = 0;
        }
        if let Some(list) = self.adjacency.get_mut(a as usize) {
            out.extend_from_slice(list);
            list.clear();
        }
    }

    /// Every live pair, each once as `(a, b)` with `a < b`, in no particular order.
    pub fn live_pairs(&self) -> impl Iterator<Item = (u32, u32)> + '_ {
        self.adjacency.iter().enumerate().flat_map(|(a, adj)| {
            adj.iter()
                .filter(move |e| e.live() && (a as u32) < e.other)
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
        Insert(u32, u32, bool),
        Live(u32, u32, bool),
        Remove(u32, u32),
        RemoveAll(u32),
        /// Mark the candidates of the proxy whose positions (in partner order) are set in the
        /// mask as met, then take its unmet ones.
        Met(u32, u16),
    }

    fn op() -> impl Strategy<Value = Op> {
        let id = 0u32..12;
        prop_oneof![
            4 => (id.clone(), id.clone(), prop::bool::ANY).prop_map(|(a, b, l)| Op::Insert(a, b, l)),
            3 => (id.clone(), id.clone(), prop::bool::ANY).prop_map(|(a, b, l)| Op::Live(a, b, l)),
            2 => (id.clone(), id.clone()).prop_map(|(a, b)| Op::Remove(a, b)),
            1 => id.clone().prop_map(Op::RemoveAll),
            2 => (id, prop::num::u16::ANY).prop_map(|(a, m)| Op::Met(a, m)),
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
                    Op::Insert(a, b, live) if a != b => match model.get(&norm(a, b)) {
                        // `insert_new` is only for pairs that are not candidates.
                        None => {
                            set.insert_new(a, b, live);
                            model.insert(norm(a, b), live);
                        }
                        Some(&was) => prop_assert_eq!(set.is_live(a, b), was),
                    },
                    Op::Live(a, b, live) if a != b => {
                        if let Some(was) = model.get_mut(&norm(a, b)) {
                            // From either end's list.
                            let i = set.partners(a).iter().position(|e| e.other == b);
                            prop_assert!(i.is_some());
                            prop_assert_eq!(set.set_live_at(a, i.unwrap_or(0), live), *was);
                            *was = live;
                        }
                    }
                    Op::Remove(a, b) if a != b => {
                        prop_assert_eq!(set.remove(a, b), model.remove(&norm(a, b)));
                    }
                    Op::RemoveAll(a) => {
                        let mut edges = Vec::new();
                        set.remove_all(a, &mut edges);
                        let mut gone: Vec<(u32, bool)> = edges
                            .iter()
                            .map(|e| (e.other, e.live()))
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
                    Op::Met(a, mask) => {
                        let mut others: Vec<u32> = model
                            .keys()
                            .filter(|&&(x, y)| x == a || y == a)
                            .map(|&(x, y)| if x == a { y } else { x })
                            .collect();
                        others.sort();
                        let mut expected = Vec::new();
                        for (k, &o) in others.iter().enumerate() {
                            if mask & (1 << (k % 16)) != 0 {
                                // Both argument orders.
                                let marked = if k % 2 == 0 {
                                    set.mark_met(a, o, true, false)
                                } else {
                                    set.mark_met(o, a, false, true)
                                };
                                prop_assert!(marked);
                            } else {
                                expected.push((a, o));
                            }
                        }
                        prop_assert!(!set.mark_met(a, a, true, true));
                        let mut unmet = Vec::new();
                        set.take_unmet(a, &mut unmet);
                        unmet.sort();
                        prop_assert_eq!(unmet, expected);
                        // The marks are gone: with nothing marked, every candidate is unmet.
                        let mut all = Vec::new();
                        set.take_unmet(a, &mut all);
                        prop_assert_eq!(all.len(), others.len());
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
                // Each waiting entry knows where its smaller id's edge is.
                prop_assert_eq!(set.waiting_edge.len(), set.waiting_list().len());
                for (i, (&k, &at)) in set.waiting_list().iter().zip(&set.waiting_edge).enumerate() {
                    let (lo, hi) = unkey(k);
                    let e = set.partners(lo)[at as usize];
                    prop_assert_eq!((e.other, e.place), (hi, i as u32));
                }
                for id in 0..12u32 {
                    let w = model.iter().filter(|(&(x, y), &l)| !l && (x == id || y == id)).count();
                    prop_assert_eq!(set.waiting(id) as usize, w);
                    let live = model.iter().any(|(&(x, y), &l)| l && (x == id || y == id));
                    prop_assert_eq!(set.has_live(id), live);
                    let mut partners: Vec<(u32, bool)> =
                        set.partners(id).iter().map(|e| (e.other, e.live())).collect();
                    partners.sort();
                    let mut expected: Vec<(u32, bool)> = model
                        .iter()
                        .filter(|(&(x, y), _)| x == id || y == id)
                        .map(|(&(x, y), &l)| (if x == id { y } else { x }, l))
                        .collect();
                    expected.sort();
                    prop_assert_eq!(partners, expected);
                    // Twins point at each other and agree; the smaller id's edge of a waiting
                    // pair holds its place in the waiting list.
                    for (k, e) in set.partners(id).iter().enumerate() {
                        let twin = set.partners(e.other)[e.twin_index()];
                        prop_assert_eq!((twin.other, twin.twin_index()), (id, k));
                        prop_assert_eq!(twin.live(), e.live());
                        if id < e.other && !e.live() {
                            prop_assert_eq!(set.waiting_list()[e.place as usize], key(id, e.other));
                        }
                    }
                }
            }
        }
    }
}
