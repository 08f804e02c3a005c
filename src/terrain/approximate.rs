//! Reading within an error bound through the door: a window of the surface that the coarsest
//! error level within the bound draws ([`Terrain::read_within`]), at every sample or at the
//! level's own resolution. What a GIS reader wants from a pyramid's overview, with the
//! overview's error measured rather than guessed.

use super::{Source, Terrain};
use crate::error::Result;
use crate::heightfield::{Heightfield, Metadata};
use crate::model::SampleRect;

/// A window of the surface drawn within an error bound ([`Terrain::read_within`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Approximation {
    /// The window, inclusive samples.
    pub window: SampleRect,
    /// The surface at every sample of the window (the georeference moved to the window):
    /// each real sample within `max_error` of its stored height, plus the rounding of the
    /// surface (evaluated in `f64`) to `f32`. Voids carry the height the surface draws
    /// there (a coarse level does not know where the voids are); samples no tile covers (a
    /// dataset's holes) are NaN.
    pub heights: Heightfield,
    /// The largest measured error `e*` of the blocks it was drawn from: at most the bound.
    pub max_error: f64,
    /// The finest stride (samples between grid points) of those blocks: its own resolution.
    pub stride: u64,
}

/// An [`Approximation`] at its own resolution ([`Approximation::at_stride`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Strided {
    /// Samples between its points, along rows and columns.
    pub stride: u64,
    /// Point `(i, j)` is the surface at sample `(window.col0 + i·stride, window.row0 +
    /// j·stride)` (the georeference's step is `stride` samples').
    pub heights: Heightfield,
}

impl Approximation {
    /// Every `stride`-th sample of the window along rows and columns, from its north-west
    /// sample: all the detail the blocks drawn have, in `stride²` times fewer samples. Where
    /// the window starts on the stride's lattice (`col0` and `row0` multiples of it, in a
    /// container or a tile), these are the level's own grid points.
    pub fn at_stride(&self) -> Result<Strided> {
        let s = self.stride.max(1);
        let (w, h) = (
            u64::from(self.heights.width()),
            u64::from(self.heights.height()),
        );
        let (sw, sh) = (w.div_ceil(s), h.div_ceil(s));
        let all = self.heights.samples();
        let mut samples = Vec::with_capacity((sw * sh) as usize);
        for j in 0..sh {
            let row = &all[(j * s * w) as usize..][..w as usize];
            samples.extend(row.iter().step_by(s as usize));
        }
        let mut metadata: Metadata = self.heights.metadata.clone();
        if let Some(g) = metadata.georeference.as_mut() {
            g.step = [g.step[0] * s as f64, g.step[1] * s as f64];
        }
        if let Some(d) = metadata.spacing_m.as_mut() {
            *d = [d[0] * s as f64, d[1] * s as f64];
        }
        Ok(Strided {
            stride: s,
            heights: Heightfield::new(sw as u32, sh as u32, samples)?.with_metadata(metadata),
        })
    }
}

impl Terrain {
    /// The surface over `window` (inclusive samples; `None`: all of it) drawn by the
    /// coarsest error level whose every block is within `max_error` height units of the
    /// stored samples ([`Terrain::cut`]'s blocks), evaluated at every sample with the
    /// triangulation of `format-spec/model.md` §4 that the errors were measured with. So
    /// every real sample is within `max_error` of what [`Terrain::read`] gives, and a bound
    /// of 0 reads the physical blocks.
    ///
    /// ```
    /// use fmrh::types::SampleRect;
    ///
    /// # fn main() -> fmrh::Result<()> {
    /// # let dir = tempfile::tempdir().unwrap();
    /// # let path = dir.path().join("waves.fmrh");
    /// let waves = fmrh::Heightfield::from_fn(300, 200, |x, y| {
    ///     30.0 * (x as f32 * 0.05).sin() + 10.0 * (y as f32 * 0.11).cos()
    /// })?;
    /// fmrh::create(&path, waves, &fmrh::CreateOptions::default())?;
    /// let terrain = fmrh::Terrain::open(&path)?;
    /// let window = SampleRect { col0: 7, row0: 3, col1: 250, row1: 190 };
    /// let exact = terrain.read(Some(window))?;
    /// let within = terrain.read_within(Some(window), 2.0)?;
    /// assert!(within.max_error <= 2.0 && within.stride > 1);
    /// for (a, b) in within.heights.samples().iter().zip(exact.samples()) {
    ///     assert!((a - b).abs() <= 2.0 + 1e-4);
    /// }
    /// let own = within.at_stride()?;
    /// assert_eq!(own.heights.width() as u64, (244 + within.stride - 1) / within.stride);
    /// # Ok(()) }
    /// ```
    pub fn read_within(&self, window: Option<SampleRect>, max_error: f64) -> Result<Approximation> {
        let (rec, metadata) = match &self.source {
            Source::Container(store) => {
                let window = window.unwrap_or_else(|| store.domain().data_rect());
                window.check_inside(&store.domain().data_rect(), "data")?;
                let selector = crate::scene::Terrain::with_spacing(store, None)?;
                let scene = selector.cut(window, max_error, crate::scene::DEFAULT_GAP)?;
                let rec = crate::scene::reconstruct(store, &scene, window)?;
                (rec, store.header().metadata.clone())
            }
            Source::Dataset(ds) => {
                let window = window.unwrap_or_else(|| ds.grid());
                let scene = ds.cut(window, max_error)?;
                let rec = ds.reconstruct(&scene, window)?;
                let metadata = Metadata {
                    spacing_m: ds.spacing_m(),
                    georeference: ds.georeference(),
                    units: None,
                    source_format: "fmrh-dataset".into(),
                    vertical_datum: ds.vertical_datum()?,
                };
                (rec, metadata)
            }
        };
        let max_error = rec
            .bound
            .iter()
            .copied()
            .filter(|e| !e.is_nan())
            .fold(0.0, f64::max);
        Ok(Approximation {
            window: rec.window,
            heights: rec.to_heightfield(&metadata)?,
            max_error,
            stride: rec.stride.max(1),
        })
    }
}
