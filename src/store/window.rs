//! Assembling full-resolution samples from the physical blocks that hold them: what
//! `extract`, a transaction's first model and the validator's rebuild all start from.
//!
//! Neighbouring blocks repeat their shared edge. The assembly takes each shared sample from
//! the first block (by row, then column) that holds it, and reports any later block whose
//! copy differs: a valid file has none (I-15).

use super::source::Source;
use super::Store;
use crate::error::{Error, Result};
use crate::format::{Invariant, Violation};
use crate::heightfield::Heightfield;
use crate::model::SampleRect;
use crate::progress::{Phase, Progress, Unit};

impl<S: Source> Store<S> {
    /// The samples of `window` (inclusive, inside the data) exactly as stored: voids NaN.
    pub fn read_window(&self, window: SampleRect) -> Result<Heightfield> {
        self.read_window_with_progress(window, &crate::progress::Silent)
    }

    /// As [`Store::read_window`], telling `progress` of each block assembled.
    pub fn read_window_with_progress(
        &self,
        window: SampleRect,
        progress: &dyn Progress,
    ) -> Result<Heightfield> {
        let samples = self.assemble(window, |_, _, _| {}, progress)?;
        let (w, h) = window_size(&window);
        let mut metadata = self.header.metadata.clone();
        if let Some(g) = metadata.georeference.as_mut() {
            g.origin = [
                g.origin[0] + window.col0 as f64 * g.step[0],
                g.origin[1] + window.row0 as f64 * g.step[1],
            ];
        }
        metadata.source_format = "fmrh".into();
        let hf = Heightfield::new(w, h, samples).map_err(|e| {
            self.corrupt(Violation::new(
                Invariant::Payload,
                "window",
                format!("stored samples: {e}"),
            ))
        })?;
        Ok(hf.with_metadata(metadata))
    }

    /// The samples of `window`, row-major, from the blocks that hold them (see the module
    /// docs). `on_disagreement(x, y, n)` hears of each block `(x, y)` whose copy of `n` shared
    /// samples differs from the copy taken.
    pub(crate) fn assemble(
        &self,
        window: SampleRect,
        mut on_disagreement: impl FnMut(u32, u32, u64),
        progress: &dyn Progress,
    ) -> Result<Vec<f32>> {
        let d = *self.domain();
        let data = d.data_rect();
        window.check_inside(&data, "data")?;
        // Refuse to allocate more than the file could back. A 1.x file holds four bytes per
        // data sample. A 2.x or 3.x file codes its payloads and shares identical ones (a
        // thousand sea blocks may name one constant payload of nine bytes), so the bound is
        // per block instead: each block of the window has its 32-byte record, in a table
        // page of the file or in a page of the metadata bundle (whose decompressed bytes
        // this store already holds).
        let cells = u64::from(d.block_size() - 1);
        let blocks = (window.col1 / cells - window.col0 / cells + 1)
            * (window.row1 / cells - window.row0 / cells + 1);
        let (needed, capacity) = if self.commit.payloads_coded() {
            let bundle = self.bundle_pages() * u64::from(self.page_size);
            (
                blocks.saturating_mul(BLOCK_RECORD_BYTES),
                self.commit.file_length.get().saturating_add(bundle),
            )
        } else {
            (
                window.samples().saturating_mul(4),
                self.commit.file_length.get(),
            )
        };
        if needed > capacity {
            return Err(self.corrupt(Violation::new(
                Invariant::DatasetHeader,
                "dataset header",
                "the data size exceeds what the file can hold",
            )));
        }
        let (w, _) = window_size(&window);
        let w = u64::from(w);
        let total = usize::try_from(window.samples()).map_err(|_| Error::TooLarge {
            what: "window".into(),
            detail: format!("{} samples", window.samples()),
        })?;
        let mut samples = vec![f32::NAN; total];
        let (cols, rows) = d.nodes_across(d.finest_level());
        // Block columns and rows are below 2^20.
        let bx = |c: u64| u32::try_from(c / cells).unwrap_or(u32::MAX).min(cols - 1);
        let by = |r: u64| u32::try_from(r / cells).unwrap_or(u32::MAX).min(rows - 1);
        let (x0, y0) = (bx(window.col0), by(window.row0));
        let blocks = u64::from(bx(window.col1) - x0 + 1) * u64::from(by(window.row1) - y0 + 1);
        let phase = Phase::start(progress, "assembling blocks", blocks, Unit::Steps);
        let mut parent = None;
        for y in y0..=by(window.row1) {
            for x in x0..=bx(window.col1) {
                let block = self.block_reusing(x, y, &mut parent)?;
                let view = block.view();
                let r = block.rect;
                let width = u64::from(view.width);
                let mut disagree = 0u64;
                for row in window.row0.max(r.row0)..=window.row1.min(r.row1) {
                    for col in window.col0.max(r.col0)..=window.col1.min(r.col1) {
                        let at = (row - r.row0) * width + col - r.col0;
                        let v = view.samples()[index(at)].get();
                        let slot = &mut samples[index((row - window.row0) * w + col - window.col0)];
                        let shared = (col == r.col0 && x > x0) || (row == r.row0 && y > y0);
                        if !shared {
                            *slot = v;
                        } else if slot.to_bits() != v.to_bits() {
                            disagree += 1;
                        }
                    }
                }
                if disagree > 0 {
                    on_disagreement(x, y, disagree);
                }
                phase.advance(1);
            }
        }
        Ok(samples)
    }
}

/// The bytes of a block record (format §6.2): the least a block of a coded file takes, since
/// its payload may be shared with any number of others.
const BLOCK_RECORD_BYTES: u64 = 32;

/// The columns and rows of a window inside the data (each at most 2^20).
fn window_size(window: &SampleRect) -> (u32, u32) {
    let side = |a: u64, b: u64| u32::try_from(b - a + 1).unwrap_or(u32::MAX);
    (
        side(window.col0, window.col1),
        side(window.row0, window.row1),
    )
}

/// A sample index inside a buffer already allocated to hold it.
fn index(i: u64) -> usize {
    usize::try_from(i).unwrap_or(usize::MAX)
}
