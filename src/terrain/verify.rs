//! Checking a terrain through the door: every numbered invariant of its container, or of its
//! dataset and each tile (`format-spec/container.md` §9, `dataset.md` §6).

use serde::Serialize;

use super::{Source, Terrain};
use crate::dataset::DatasetReport;
use crate::error::Result;
use crate::store::{CheckStatus, VerifyMode, VerifyReport};

/// The validator's report ([`Terrain::verify`]).
#[derive(Clone, Debug, Serialize)]
#[serde(untagged)]
pub enum Verification {
    /// A container's: one check per invariant, I-1 to I-16.
    Container(VerifyReport),
    /// A dataset's: D-1 to D-5, and each tile's container checks.
    Dataset(DatasetReport),
}

impl Verification {
    /// Whether every check passed.
    pub fn valid(&self) -> bool {
        match self {
            Verification::Container(r) => r.valid,
            Verification::Dataset(r) => r.valid,
        }
    }

    /// Whether a check could not be decided because a writer was committing: run again.
    pub fn busy(&self) -> bool {
        match self {
            Verification::Container(r) => r.busy,
            Verification::Dataset(r) => r.checks.iter().any(|c| c.status == CheckStatus::Busy),
        }
    }

    /// Every failure, each `INVARIANT: where and what` (a tile's prefixed with its file).
    pub fn failures(&self) -> Vec<String> {
        let of = |checks: &[crate::store::CheckReport]| -> Vec<String> {
            checks
                .iter()
                .flat_map(|c| c.failures.iter().map(move |f| format!("{}: {f}", c.id)))
                .collect()
        };
        match self {
            Verification::Container(r) => of(&r.checks),
            Verification::Dataset(r) => {
                let mut out = of(&r.checks);
                for t in &r.tile_reports {
                    out.extend(t.failures.iter().map(|f| format!("{}: {f}", t.name)));
                }
                out
            }
        }
    }
}

impl Terrain {
    /// Checks the terrain's file or dataset as it stands now (its latest state: the one this
    /// terrain reads, unless a writer committed since) against every numbered invariant,
    /// registered against page reuse while it reads (a commit meanwhile makes the checks
    /// around the state *busy*, never *invalid*). `Fast` checks
    /// structure and every checksum, `Full` also rebuilds every error, grid and cut from the
    /// full-resolution samples. A broken invariant is a failure in the report, never an
    /// `Err`; an `Err` is an I/O failure or data that cannot be opened at all.
    ///
    /// ```
    /// # fn main() -> fmrh::Result<()> {
    /// # let dir = tempfile::tempdir().unwrap();
    /// # let path = dir.path().join("ramp.fmrh");
    /// let ramp = fmrh::Heightfield::from_fn(70, 50, |x, y| (x * 3 + y) as f32)?;
    /// fmrh::create(&path, ramp, &fmrh::CreateOptions::default())?;
    /// let report = fmrh::Terrain::open(&path)?.verify(fmrh::types::VerifyMode::Full)?;
    /// assert!(report.valid(), "{:?}", report.failures());
    /// # Ok(()) }
    /// ```
    pub fn verify(&self, mode: VerifyMode) -> Result<Verification> {
        match &self.source {
            Source::Container(_) => Ok(Verification::Container(crate::store::verify(
                crate::store::AnySource::open(&self.location)?,
                mode,
            )?)),
            Source::Dataset(_) => Ok(Verification::Dataset(crate::dataset::verify(
                &self.location,
                mode,
                &crate::progress::Silent,
            )?)),
        }
    }
}
