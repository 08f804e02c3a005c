//! A flight from Python: the door's `Flight` run on a thread of its own, one frame ahead of
//! the caller (a bounded channel of one), so the next frame is selected and decoded while
//! Python draws this one. Each frame crosses as its loaded blocks (converted to numpy
//! once, when they enter the view) and the keys of the rest.

use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::{Arc, Mutex};

use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::{block_dict, to_py, FmrhError};

type Key = (Option<u64>, u8, u32, u32);

/// One frame as the thread sends it.
struct Sent {
    index: u64,
    keys: Vec<Key>,
    loaded: Vec<(Key, Arc<fmrh::Block>)>,
    evicted: Vec<Key>,
    max_screen_error: f64,
    schedule_ns: u64,
}

fn key(k: &fmrh::types::BlockKey) -> Key {
    (k.tile, k.level, k.x, k.y)
}

/// An iterator of a flight's frames (`Terrain.fly`).
#[pyclass(module = "fmrh._fmrh", frozen)]
pub struct Flight {
    frames: Mutex<State>,
}

/// Where the frames are: waiting to be asked for, being waited for by a caller (the lock is
/// not held while it waits, so the GIL and the lock are never held crosswise), or done.
enum State {
    Ready(Receiver<fmrh::Result<Sent>>),
    Waiting,
    Done,
}

impl Flight {
    /// Starts flying `terrain` along `cameras` (flat, or with `globe` in ECEF) on a thread
    /// of its own.
    pub fn start(
        terrain: Arc<fmrh::Terrain>,
        cameras: Vec<fmrh::Camera>,
        options: fmrh::SceneOptions,
        globe: bool,
    ) -> Flight {
        let (tx, rx) = sync_channel(1);
        std::thread::spawn(move || {
            let mut flight = terrain.fly(options, globe);
            for camera in cameras {
                let sent = flight.frame(&camera).map(|f| {
                    let entered: std::collections::HashSet<_> = f.loaded.iter().collect();
                    let loaded = f
                        .keys
                        .iter()
                        .zip(&f.blocks)
                        .filter(|(k, _)| entered.contains(k))
                        .map(|(k, b)| (key(k), b.clone()))
                        .collect();
                    Sent {
                        index: f.index,
                        keys: f.keys.iter().map(key).collect(),
                        loaded,
                        evicted: f.evicted.iter().map(key).collect(),
                        max_screen_error: f.stats.max_screen_error,
                        schedule_ns: f.stats.schedule_ns,
                    }
                });
                let failed = sent.is_err();
                // The caller stopped iterating (the receiver is gone): stop flying.
                if tx.send(sent).is_err() || failed {
                    return;
                }
            }
        });
        Flight {
            frames: Mutex::new(State::Ready(rx)),
        }
    }
}

#[pymethods]
impl Flight {
    fn __iter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    /// The next frame as a dict: `index`, `keys` (every block in view, as `(tile, level, x,
    /// y)`, in scene order), `loaded` (the blocks that entered the view: `(key, block)`
    /// pairs, each block a dict as `Terrain.scene` gives), `evicted` (keys that left the
    /// view), `max_screen_error`, `schedule_ns`. The GIL is released while it waits.
    fn __next__<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let rx = {
            let mut state = self.frames.lock().unwrap_or_else(|p| p.into_inner());
            match std::mem::replace(&mut *state, State::Waiting) {
                State::Ready(rx) => rx,
                State::Waiting => {
                    return Err(FmrhError::new_err(
                        "the flight's next frame is being read by another thread",
                    ))
                }
                State::Done => {
                    *state = State::Done;
                    return Ok(None);
                }
            }
        };
        let (rx, got) = py.detach(move || {
            let got = rx.recv();
            (rx, got)
        });
        let mut state = self.frames.lock().unwrap_or_else(|p| p.into_inner());
        let sent = match got {
            Ok(Ok(sent)) => {
                // Closed meanwhile: leave it closed.
                if matches!(*state, State::Waiting) {
                    *state = State::Ready(rx);
                }
                sent
            }
            Ok(Err(e)) => {
                *state = State::Done;
                return Err(to_py(e));
            }
            Err(_) => {
                // The path is done.
                *state = State::Done;
                return Ok(None);
            }
        };
        drop(state);
        let d = PyDict::new(py);
        d.set_item("index", sent.index)?;
        d.set_item("keys", sent.keys)?;
        let loaded = sent
            .loaded
            .iter()
            .map(|(k, b)| Ok((*k, block_dict(py, b)?)))
            .collect::<PyResult<Vec<_>>>()?;
        d.set_item("loaded", loaded)?;
        d.set_item("evicted", sent.evicted)?;
        d.set_item("max_screen_error", sent.max_screen_error)?;
        d.set_item("schedule_ns", sent.schedule_ns)?;
        Ok(Some(d))
    }

    /// Stops the flight: the thread ends after the frame it is on.
    fn close(&self) {
        *self.frames.lock().unwrap_or_else(|p| p.into_inner()) = State::Done;
    }
}
