//! When the rounds stop paying: the outcome of a run of rounds and the watches that decide it.

/// Rounds after which a gap that has not halved counts as stalled.
pub(super) const STALL_ROUNDS: usize = 12;
/// Hard cap on the rounds (each one is cheap; real rigs need 10-40).
pub(super) const MAX_ROUNDS: usize = 300;

pub(super) enum Outcome {
    Done,
    /// The gap stopped shrinking; carries the last dual variables (`Y`, or `(Y, U)` stacked)
    /// for the fallback.
    Stalled(Vec<f64>),
    /// The next round's support factors would exceed the memory limit; carries the last
    /// round's dual variables (as `Stalled`), `None` before the first round.
    OverBudget(Option<Vec<f64>>),
}

/// Tracks whether the certified gap still shrinks.
pub(super) struct StallWatch {
    best_gap: f64,
    since: usize,
}

impl StallWatch {
    /// A watch that starts from the certified gap `gap`.
    pub fn new(gap: f64) -> Self {
        StallWatch {
            best_gap: gap,
            since: 0,
        }
    }

    /// Records a round's gap; true once it has not halved in `window` rounds.
    pub fn stalled(&mut self, gap: f64, window: usize) -> bool {
        if gap < 0.5 * self.best_gap {
            self.best_gap = gap;
            self.since = 0;
        } else {
            self.since += 1;
        }
        self.since >= window
    }
}

/// When the partition-of-unity rounds hand over to L-BFGS.
#[derive(Clone, Copy)]
pub(super) enum Watch {
    /// The certified gap has not halved in this many rounds.
    Gap(usize),
    /// Neither of the rounds' own bounds improved on its best by `tol / 2` (relative) in each of
    /// two rounds ([`OwnBounds`]). Their lower bound keeps rising after the weights have
    /// settled, and more rounds beat L-BFGS's crawl there.
    Bounds,
}

/// The best upper and lower bound the rounds have found themselves, and for how many rounds in
/// a row neither has improved by more than a relative step.
pub(super) struct OwnBounds {
    upper: f64,
    lower: f64,
    quiet: usize,
}

impl OwnBounds {
    pub fn new() -> Self {
        OwnBounds {
            upper: f64::INFINITY,
            lower: f64::NEG_INFINITY,
            quiet: 0,
        }
    }

    /// Records a round's bounds; returns the number of quiet rounds so far. Bounds are compared
    /// with the best so far, so bounds that oscillate (a cycling support) count as quiet
    /// instead of keeping the rounds alive until `MAX_ROUNDS`.
    pub fn quiet_rounds(&mut self, upper: f64, lower: f64, step: f64) -> usize {
        let size = upper.abs().max(1e-300);
        let moved = (self.upper - upper).max(lower - self.lower) / size;
        self.upper = self.upper.min(upper);
        self.lower = self.lower.max(lower);
        self.quiet = if moved < step { self.quiet + 1 } else { 0 };
        self.quiet
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn oscillating_bounds_count_as_quiet() {
        let mut own = OwnBounds::new();
        assert_eq!(own.quiet_rounds(10.0, 5.0, 1e-6), 0);
        assert_eq!(own.quiet_rounds(9.0, 6.0, 1e-6), 0);
        // A cycling support: the bounds jump back and forth without beating their best.
        assert_eq!(own.quiet_rounds(9.5, 5.5, 1e-6), 1);
        assert_eq!(own.quiet_rounds(9.0, 6.0, 1e-6), 2);
        assert_eq!(own.quiet_rounds(9.5, 5.5, 1e-6), 3);
        // A real improvement of either bound resets the count.
        assert_eq!(own.quiet_rounds(9.5, 6.5, 1e-6), 0);
        assert_eq!(own.quiet_rounds(8.0, 5.0, 1e-6), 0);
        assert_eq!(own.quiet_rounds(8.0 - 1e-7, 6.5, 1e-6), 1);
    }
}
