//! Phase timers for [`crate::CanopyBroadPhase::update`], a profiling aid behind the cargo
//! feature `phase-times` (off by default; without it nothing here is compiled into the update).
//! With it, every update adds the time of each of its steps to the broadphase's
//! [`PhaseTimes`], read with `CanopyBroadPhase::take_phase_times`. The root package forwards
//! the feature: `cargo run --release --features phase-times --example compare` prints the
//! phases of each scene under its table.

use std::time::{Duration, Instant};

/// Time spent in each step of `CanopyBroadPhase::update` (the numbered steps of
/// `broad_phase.rs`), summed over the updates since the last
/// `CanopyBroadPhase::take_phase_times`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PhaseTimes {
    /// Updates counted (updates with nothing modified or removed return early and are not).
    pub updates: u64,
    /// Proxies in the move buffer, summed over the updates.
    pub moved: u64,
    /// Step 1: removals.
    pub removals: Duration,
    /// Step 2: re-examining the modified colliders (their boxes, and new fat boxes).
    pub examine: Duration,
    /// Step 3: refits and rebuilds of the trees.
    pub trees: Duration,
    /// Steps 4 and 5, the search: the queries or marked walks that find the ended and the new
    /// candidates.
    pub search: Duration,
    /// Steps 4 and 5, the pair-set edits: dropping the ended candidates, adding the new ones.
    pub pair_edits: Duration,
    /// Step 6: liveness of the waiting candidates.
    pub liveness: Duration,
    /// The rest: counting the events, clearing the move buffer.
    pub finish: Duration,
}

impl PhaseTimes {
    /// Every phase with its name, in the update's order: `removals`, `examine`, `trees`,
    /// `search`, `pair edits`, `liveness`, `finish`.
    pub fn named(&self) -> [(&'static str, Duration); 7] {
        [
            ("removals", self.removals),
            ("examine", self.examine),
            ("trees", self.trees),
            ("search", self.search),
            ("pair edits", self.pair_edits),
            ("liveness", self.liveness),
            ("finish", self.finish),
        ]
    }

    /// The sum of all phases.
    pub fn total(&self) -> Duration {
        self.named().iter().map(|&(_, d)| d).sum()
    }
}

impl std::ops::AddAssign for PhaseTimes {
    /// Adds every field of `other`, the counts and the phases.
    fn add_assign(&mut self, other: Self) {
        self.updates += other.updates;
        self.moved += other.moved;
        self.removals += other.removals;
        self.examine += other.examine;
        self.trees += other.trees;
        self.search += other.search;
        self.pair_edits += other.pair_edits;
        self.liveness += other.liveness;
        self.finish += other.finish;
    }
}

/// Measures consecutive phases: each [`Clock::lap`] adds the time since the previous one.
pub(crate) struct Clock {
    last: Instant,
}

impl Clock {
    pub fn start() -> Self {
        Self {
            last: Instant::now(),
        }
    }

    /// Adds the time since the last lap (or the start) to `phase`.
    pub fn lap(&mut self, phase: &mut Duration) {
        let now = Instant::now();
        *phase += now - self.last;
        self.last = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn laps_add_up_to_the_elapsed_time() {
        let start = Instant::now();
        let mut clock = Clock::start();
        let mut t = PhaseTimes::default();
        std::thread::sleep(Duration::from_millis(2));
        clock.lap(&mut t.examine);
        std::thread::sleep(Duration::from_millis(1));
        clock.lap(&mut t.search);
        assert!(t.examine >= Duration::from_millis(2));
        assert!(t.search >= Duration::from_millis(1));
        assert!(t.total() <= start.elapsed());
        assert_eq!(t.named()[1], ("examine", t.examine));
        let mut twice = t;
        twice += t;
        assert_eq!(twice.total(), t.total() * 2);
    }
}
