//! Progress of long operations: a listener the library tells how a phase advances, and the
//! command line draws as a bar. The library never draws anything itself.
//!
//! Phases come one at a time: `start`, any number of `advance`, `finish`. Ingest has no
//! phases here (a reader does not know its work ahead); the model build reports one step a
//! level measured, the writer bytes of payload written, `verify` bytes of payload checked,
//! blocks assembled and levels re-measured, and window reads blocks assembled.

/// What a phase counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    /// Bytes.
    Bytes,
    /// Steps of the phase's own kind (levels, blocks): the phase's name says which.
    Steps,
}

/// Hears how a long operation advances. Every method does nothing unless implemented.
pub trait Progress: Send + Sync {
    /// A phase of `total` units starts.
    fn start(&self, _phase: &str, _total: u64, _unit: Unit) {}
    /// `n` more units are done.
    fn advance(&self, _n: u64) {}
    /// The phase is over.
    fn finish(&self) {}
}

/// A [`Progress`] that ignores everything.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Progress for Silent {}

/// A phase in progress: finished when dropped, so an early return (an error) still ends it.
pub struct Phase<'a>(&'a dyn Progress);

impl<'a> Phase<'a> {
    /// Starts phase `name` of `total` units on `progress`.
    pub fn start(progress: &'a dyn Progress, name: &str, total: u64, unit: Unit) -> Phase<'a> {
        progress.start(name, total, unit);
        Phase(progress)
    }

    /// `n` more units are done.
    pub fn advance(&self, n: u64) {
        self.0.advance(n);
    }
}

impl Drop for Phase<'_> {
    fn drop(&mut self) {
        self.0.finish();
    }
}
