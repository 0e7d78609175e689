//! Progress and cancelling for long loops: a `Ticker` counts work done over an atomic counter
//! (callable from rayon workers), calls the caller's progress callback now and then, and
//! turns a `false` from it into `Error::Cancelled` at the next check.
//!
//! The contract every long call keeps (docs/api.md, "Long calls"): work is counted in batches
//! small enough that a batch takes well under `INTERVAL`, so the callback hears of progress
//! at least every ~0.5 s and a cancel is honoured within a second, whatever the request size.

use crate::{Error, Result};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Progress in [0, 1]; returning false cancels. The core's one callback type.
pub type ProgressFn<'a> = dyn Fn(f32) -> bool + Sync + 'a;

/// The least time between two calls of the callback from one `Ticker`: often enough for a
/// progress bar and a prompt cancel, rarely enough that a callback taking a lock costs nothing.
pub const INTERVAL: Duration = Duration::from_millis(20);

/// Work counted across threads, reported to `progress` as a fraction of [from, to].
pub struct Ticker<'a> {
    progress: Option<&'a ProgressFn<'a>>,
    total: u64,
    done: AtomicU64,
    /// Nanoseconds after `start` of the last call (0: none yet).
    last: AtomicU64,
    start: Instant,
    range: (f32, f32),
    stopped: AtomicBool,
}

impl<'a> Ticker<'a> {
    /// A ticker over `total` units of work, reported as fractions of [0, 1].
    pub fn new(progress: Option<&'a ProgressFn<'a>>, total: u64) -> Self {
        Self::span(progress, total, 0.0, 1.0)
    }

    /// A ticker over `total` units reported in [from, to] (one stage of a longer call).
    pub fn span(progress: Option<&'a ProgressFn<'a>>, total: u64, from: f32, to: f32) -> Self {
        Self {
            progress,
            total: total.max(1),
            done: AtomicU64::new(0),
            last: AtomicU64::new(0),
            start: Instant::now(),
            range: (from, to),
            stopped: AtomicBool::new(false),
        }
    }

    /// `n` more units done. Calls the callback when `INTERVAL` has passed since the last call
    /// (one thread at a time wins the call); returns false once the caller has cancelled.
    pub fn add(&self, n: u64) -> bool {
        if self.stopped.load(Ordering::Relaxed) {
            return false;
        }
        let done = self.done.fetch_add(n, Ordering::Relaxed) + n;
        let Some(p) = self.progress else {
            return true;
        };
        let now = self.start.elapsed().as_nanos() as u64 + 1;
        let last = self.last.load(Ordering::Relaxed);
        if now.saturating_sub(last) < INTERVAL.as_nanos() as u64 && last != 0 {
            return true;
        }
        if self
            .last
            .compare_exchange(last, now, Ordering::AcqRel, Ordering::Relaxed)
            .is_err()
        {
            return true; // another thread is calling it now
        }
        let f = (done as f64 / self.total as f64).min(1.0) as f32;
        if !p(self.range.0 + (self.range.1 - self.range.0) * f) {
            self.stopped.store(true, Ordering::Relaxed);
            return false;
        }
        true
    }

    /// Whether the caller has cancelled (a loop checks this before each batch).
    pub fn stopped(&self) -> bool {
        self.stopped.load(Ordering::Relaxed)
    }

    /// `Err(Cancelled)` once the caller has cancelled.
    pub fn check(&self) -> Result<()> {
        if self.stopped() {
            Err(Error::Cancelled)
        } else {
            Ok(())
        }
    }

    /// The units counted so far.
    pub fn done(&self) -> u64 {
        self.done.load(Ordering::Relaxed)
    }
}

/// The callback that only asks whether to stop: what a stage without its own share of the
/// progress bar (an irradiance estimate inside a longer call) passes on.
pub fn cancel_only<'a>(progress: Option<&'a ProgressFn<'a>>) -> impl Fn(f32) -> bool + Sync + 'a {
    move |_| progress.is_none_or(|p| p(f32::NAN))
}

/// `progress` called at its fractions `from..to` for one stage of a longer call (a NaN, which
/// only asks whether to go on, stays NaN).
pub fn stage<'a>(
    progress: Option<&'a ProgressFn<'a>>,
    from: f32,
    to: f32,
) -> impl Fn(f32) -> bool + Sync + 'a {
    move |f| progress.is_none_or(|p| p(from + (to - from) * f))
}

/// The callback that holds the bar at `at` while asking whether to stop: a stage after the
/// last tick of a longer call (an estimate, a point mass) that has no share of its own.
pub fn held_at<'a>(
    progress: Option<&'a ProgressFn<'a>>,
    at: f32,
) -> impl Fn(f32) -> bool + Sync + 'a {
    move |_| progress.is_none_or(|p| p(at))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;
    use std::sync::Mutex;

    #[test]
    fn ticks_from_many_threads_reach_the_callback_spaced_and_in_range() {
        let calls = Mutex::new(Vec::<(Instant, f32)>::new());
        let cb = |f: f32| {
            calls.lock().unwrap().push((Instant::now(), f));
            true
        };
        let t = Ticker::span(Some(&cb), 4000, 0.5, 1.0);
        let start = Instant::now();
        // 4000 units of ~0.1 ms each over the rayon pool: ~0.4 s / threads.
        (0..4000u64).into_par_iter().for_each(|_| {
            let s = Instant::now();
            while s.elapsed() < Duration::from_micros(100) {}
            assert!(t.add(1));
        });
        let took = start.elapsed();
        assert_eq!(t.done(), 4000);
        let calls = calls.into_inner().unwrap();
        // The first add calls at once, then one call per INTERVAL at most.
        assert!(!calls.is_empty());
        let most = 1 + (took.as_secs_f64() / INTERVAL.as_secs_f64()).ceil() as usize;
        assert!(calls.len() <= most, "{} calls in {took:?}", calls.len());
        for (_, f) in &calls {
            assert!((0.5..=1.0).contains(f), "fraction {f}");
        }
        for w in calls.windows(2) {
            // Calls from different threads may land out of order by a hair; the spacing between
            // the winners' clock readings is at least INTERVAL, less the time to push.
            let gap = w[1].0.saturating_duration_since(w[0].0);
            assert!(gap + Duration::from_millis(5) >= INTERVAL, "gap {gap:?}");
        }
    }

    #[test]
    fn a_false_from_the_callback_stops_every_thread_and_checks_as_cancelled() {
        let calls = AtomicU64::new(0);
        let cb = |_: f32| {
            calls.fetch_add(1, Ordering::Relaxed);
            false
        };
        let t = Ticker::new(Some(&cb), 1_000_000);
        assert!(t.check().is_ok());
        let went_on: u64 = (0..1_000_000u64)
            .into_par_iter()
            .map(|_| if t.stopped() { 0 } else { u64::from(t.add(1)) })
            .sum();
        // The first call said stop: nothing after it goes on, and it is asked only once per
        // thread that raced it.
        assert!(went_on <= rayon::current_num_threads() as u64, "{went_on}");
        assert!(calls.load(Ordering::Relaxed) <= rayon::current_num_threads() as u64);
        assert_eq!(t.check(), Err(Error::Cancelled));
    }

    #[test]
    fn without_a_callback_it_only_counts() {
        let t = Ticker::new(None, 10);
        for _ in 0..25 {
            assert!(t.add(1));
        }
        assert_eq!(t.done(), 25);
        assert!(t.check().is_ok());
        let stop = |_: f32| false;
        assert!(!cancel_only(Some(&stop))(0.3));
        assert!(cancel_only(None)(0.3));
    }
}
