//! Jobs run on a bounded number of threads, their results in the jobs' order: the requests
//! of one round of a remote source, the tiles of a remote dataset. Scoped threads and no
//! pool kept between calls: the jobs wait on the network, so a few threads cost nothing
//! beside them, and rayon's pool (one thread a core) would bound them by the wrong thing.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// `job` for each of `jobs` on at most `workers` threads (the caller's among them), the
/// results in the order of `jobs`. `None` only if a job's result went missing, which a
/// panicking job prevents by propagating its panic.
pub(crate) fn run_bounded<J: Sync, T: Send>(
    jobs: &[J],
    workers: usize,
    job: impl Fn(&J) -> T + Sync,
) -> Option<Vec<T>> {
    let next = AtomicUsize::new(0);
    let results: Vec<Mutex<Option<T>>> = jobs.iter().map(|_| Mutex::new(None)).collect();
    let work = || loop {
        let k = next.fetch_add(1, Ordering::Relaxed);
        let Some(j) = jobs.get(k) else { break };
        let done = job(j);
        if let Ok(mut slot) = results[k].lock() {
            *slot = Some(done);
        }
    };
    std::thread::scope(|s| {
        for _ in 1..workers.max(1).min(jobs.len()) {
            s.spawn(work);
        }
        work();
    });
    results
        .into_iter()
        .map(|slot| slot.into_inner().ok().flatten())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_job_runs_once_and_results_keep_their_order() {
        let jobs: Vec<u64> = (0..100).collect();
        let runs = AtomicUsize::new(0);
        for workers in [0, 1, 3, 8, 200] {
            runs.store(0, Ordering::Relaxed);
            let out = run_bounded(&jobs, workers, |j| {
                runs.fetch_add(1, Ordering::Relaxed);
                j * j
            });
            assert_eq!(out, Some(jobs.iter().map(|j| j * j).collect()));
            assert_eq!(runs.load(Ordering::Relaxed), 100);
        }
        assert_eq!(run_bounded(&[] as &[u8], 4, |_| 0), Some(Vec::new()));
    }
}
