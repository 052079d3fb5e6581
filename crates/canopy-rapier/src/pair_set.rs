//! The live pair set: a hash set of proxy-id pairs for "is this pair new?" and, per proxy, the
//! list of its partners, so that only the pairs of moved proxies are checked for deletion
//! (never a scan of all pairs).

use rustc_hash::FxHashSet;

#[inline]
fn key(a: u32, b: u32) -> u64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    ((lo as u64) << 32) | hi as u64
}

#[derive(Clone, Debug, Default)]
pub(crate) struct PairSet {
    set: FxHashSet<u64>,
    adjacency: Vec<Vec<u32>>,
}

impl PairSet {
    pub fn len(&self) -> usize {
        self.set.len()
    }

    pub fn contains(&self, a: u32, b: u32) -> bool {
        self.set.contains(&key(a, b))
    }

    fn adj_mut(&mut self, a: u32) -> &mut Vec<u32> {
        let a = a as usize;
        if a >= self.adjacency.len() {
            self.adjacency.resize_with(a + 1, Vec::new);
        }
        &mut self.adjacency[a]
    }

    /// Adds the pair; `false` when it was already there.
    pub fn insert(&mut self, a: u32, b: u32) -> bool {
        if !self.set.insert(key(a, b)) {
            return false;
        }
        self.adj_mut(a).push(b);
        self.adj_mut(b).push(a);
        true
    }

    /// Removes the pair; `false` when it was not there.
    pub fn remove(&mut self, a: u32, b: u32) -> bool {
        if !self.set.remove(&key(a, b)) {
            return false;
        }
        for (x, y) in [(a, b), (b, a)] {
            let adj = self.adj_mut(x);
            if let Some(i) = adj.iter().position(|&o| o == y) {
                adj.swap_remove(i);
            }
        }
        true
    }

    /// Partners of `a`.
    pub fn partners(&self, a: u32) -> &[u32] {
        self.adjacency
            .get(a as usize)
            .map(Vec::as_slice)
            .unwrap_or(&[])
    }

    /// Removes every pair of `a` and returns the former partners, in adjacency order.
    pub fn remove_all(&mut self, a: u32) -> Vec<u32> {
        let partners = std::mem::take(self.adj_mut(a));
        for &b in &partners {
            self.set.remove(&key(a, b));
            let adj = self.adj_mut(b);
            if let Some(i) = adj.iter().position(|&o| o == a) {
                adj.swap_remove(i);
            }
        }
        partners
    }

    /// Every live pair as `(smaller id, larger id)`, in no particular order.
    pub fn iter(&self) -> impl Iterator<Item = (u32, u32)> + '_ {
        self.set.iter().map(|&k| ((k >> 32) as u32, k as u32))
    }
}
