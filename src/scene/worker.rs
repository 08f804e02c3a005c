//! A thread that serves the newest of the requests sent to it: what a prefetcher runs on.
//! A prediction made for frame `n` is worthless once frame `n + 1` has asked for its own, so
//! requests that queued up while the thread worked are skipped, and only the last is served.
//! A caller can wait until every request it sent is served or skipped (tests, and readers
//! that want a deterministic warm cache).
//!
//! The worker knows nothing of what it serves: the scheduler of one store and a dataset's
//! scheduler each give it their own closure.

use std::sync::mpsc::{self, Sender};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;

/// Locks `m`; a panic in the worker leaves what it guards usable (the users keep whole
/// entries under their locks).
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// See the module docs.
pub(crate) struct NewestWorker<R: Send + 'static> {
    /// Requests sent, and the number of the last one served (with a condition variable to
    /// wait on).
    sent: u64,
    done: Arc<(Mutex<u64>, Condvar)>,
    requests: Option<Sender<(u64, R)>>,
    thread: Option<JoinHandle<()>>,
}

impl<R: Send + 'static> NewestWorker<R> {
    /// Starts the thread `name`, which calls `serve` on the newest request each time it
    /// wakes. If the thread cannot start, requests are dropped: prefetch is only a hint.
    pub fn start(name: &str, mut serve: impl FnMut(R) + Send + 'static) -> NewestWorker<R> {
        let (tx, rx) = mpsc::channel::<(u64, R)>();
        let done: Arc<(Mutex<u64>, Condvar)> = Arc::default();
        let thread_done = Arc::clone(&done);
        let thread = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                while let Ok(mut request) = rx.recv() {
                    while let Ok(newer) = rx.try_recv() {
                        request = newer;
                    }
                    let (number, r) = request;
                    serve(r);
                    *lock(&thread_done.0) = number;
                    thread_done.1.notify_all();
                }
            })
            .ok();
        NewestWorker {
            sent: 0,
            done,
            requests: thread.is_some().then_some(tx),
            thread,
        }
    }

    /// Sends `request`.
    pub fn ask(&mut self, request: R) {
        if let Some(tx) = &self.requests {
            self.sent += 1;
            // A closed channel means the thread ended; prefetch is only ever a hint.
            if tx.send((self.sent, request)).is_err() {
                self.requests = None;
            }
        }
    }

    /// Blocks until every request sent so far is served or skipped.
    pub fn wait(&self) {
        if self.requests.is_none() {
            return;
        }
        let (lock_done, cv) = &*self.done;
        let mut done = lock(lock_done);
        while *done < self.sent {
            done = cv.wait(done).unwrap_or_else(|p| p.into_inner());
        }
    }
}

impl<R: Send + 'static> Drop for NewestWorker<R> {
    fn drop(&mut self) {
        self.requests = None; // ends the loop
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_worker_serves_the_newest_and_waits_for_all() {
        let seen: Arc<Mutex<Vec<u32>>> = Arc::default();
        let (gate_tx, gate_rx) = mpsc::channel::<()>();
        let gate = Mutex::new(gate_rx);
        let log = Arc::clone(&seen);
        let mut w = NewestWorker::start("test-worker", move |r: u32| {
            // The first request holds the thread until the others have queued.
            if r == 0 {
                let _ = lock(&gate).recv();
            }
            lock(&log).push(r);
        });
        w.ask(0);
        w.ask(1);
        w.ask(2);
        w.ask(3);
        gate_tx.send(()).unwrap();
        w.wait();
        let served = lock(&seen).clone();
        // Either 0 was taken before the others queued (then 1 and 2 were skipped for 3), or
        // all four queued first and only 3 was served.
        assert!(
            served == [0, 3] || served == [3],
            "queued requests are skipped: {served:?}"
        );
    }
}
