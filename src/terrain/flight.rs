//! A moving camera through the door: a [`Flight`] answers each frame's camera with the scene
//! it needs, reading and decoding only the blocks the previous frame did not hold (seed 000
//! Algorithm 3: load what entered the view, drop what left it). What an application that
//! draws a fly-through wants: per frame, the blocks to upload and the ones to free.

use std::collections::HashMap;

use serde::Serialize;

use super::scene::{Block, BlockKey};
use super::Terrain;
use crate::error::Result;
use crate::scene::{Camera, SceneOptions, SceneStats};

/// A camera moving over a terrain ([`Terrain::fly`]): the blocks of the last frame's scene,
/// decoded, kept to be given again while they stay in view.
pub struct Flight<'t> {
    terrain: &'t Terrain,
    options: SceneOptions,
    globe: bool,
    resident: HashMap<BlockKey, std::sync::Arc<Block>>,
    frames: u64,
}

impl std::fmt::Debug for Flight<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Flight")
            .field("frames", &self.frames)
            .field("resident", &self.resident.len())
            .finish_non_exhaustive()
    }
}

/// One frame of a [`Flight`].
#[derive(Clone, Debug, Serialize)]
pub struct FlightFrame {
    /// 0 for the first.
    pub index: u64,
    /// The scene's blocks, decoded, in scene order (a block held from an earlier frame is
    /// the same value, not decoded again).
    #[serde(skip)]
    pub blocks: Vec<std::sync::Arc<Block>>,
    /// Their keys, in the same order.
    pub keys: Vec<BlockKey>,
    /// The blocks read and decoded for this frame: in view now, not in the last frame.
    pub loaded: Vec<BlockKey>,
    /// The blocks of the last frame that left the view, dropped.
    pub evicted: Vec<BlockKey>,
    /// What the selection cost and guarantees (as a scene's).
    pub stats: SceneStats,
}

impl Terrain {
    /// A flight over this terrain: [`Flight::frame`] takes each camera of a path in turn.
    /// The cameras are flat ([`Terrain::scene`]'s frame) or, with `globe`, in ECEF metres
    /// ([`Terrain::scene_on_globe`]'s).
    ///
    /// ```
    /// use fmrh::glam::DVec3;
    /// use fmrh::{Camera, SceneOptions, Terrain};
    ///
    /// # fn main() -> fmrh::Result<()> {
    /// # let dir = tempfile::tempdir().unwrap();
    /// # let path = dir.path().join("hills.fmrh");
    /// let hills = fmrh::Heightfield::from_fn(257, 257, |x, y| {
    ///     40.0 * (x as f32 * 0.05).sin() * (y as f32 * 0.07).cos()
    /// })?;
    /// fmrh::create(&path, hills, &fmrh::CreateOptions::default())?;
    /// let mut terrain = Terrain::open(&path)?;
    /// terrain.set_spacing(Some([1.0, 1.0]))?;
    /// let mut flight = terrain.fly(SceneOptions::new(1.0), false);
    /// let mut held = 0;
    /// for step in 0..10 {
    ///     let eye = DVec3::new(-50.0 + 10.0 * step as f64, -50.0, 120.0);
    ///     let frame = flight.frame(&Camera::looking_at(eye, DVec3::new(128.0, 128.0, 0.0)))?;
    ///     // What a renderer holds: the last frame's blocks, less those evicted, plus those
    ///     // loaded, is this frame's scene.
    ///     held = held + frame.loaded.len() - frame.evicted.len();
    ///     assert_eq!(held, frame.blocks.len());
    /// }
    /// # Ok(()) }
    /// ```
    pub fn fly(&self, options: SceneOptions, globe: bool) -> Flight<'_> {
        Flight {
            terrain: self,
            options,
            globe,
            resident: HashMap::new(),
            frames: 0,
        }
    }
}

impl Flight<'_> {
    /// Moves to `camera`: selects its scene, decodes the blocks not held from the last
    /// frame, drops those that left the view.
    pub fn frame(&mut self, camera: &Camera) -> Result<FlightFrame> {
        let selected = self.terrain.selected(camera, &self.options, self.globe)?;
        let keys = selected.keys();
        let new: Vec<bool> = keys
            .iter()
            .map(|k| !self.resident.contains_key(k))
            .collect();
        let stats = selected.stats();
        let decoded = selected.decode(self.terrain, |i| new[i])?;
        let loaded: Vec<BlockKey> = keys
            .iter()
            .zip(&new)
            .filter(|(_, n)| **n)
            .map(|(k, _)| *k)
            .collect();
        for (k, b) in loaded.iter().zip(decoded.blocks) {
            self.resident.insert(*k, std::sync::Arc::new(b));
        }
        let in_view: std::collections::HashSet<BlockKey> = keys.iter().copied().collect();
        let mut evicted: Vec<BlockKey> = self
            .resident
            .keys()
            .filter(|k| !in_view.contains(k))
            .copied()
            .collect();
        evicted.sort_unstable();
        for k in &evicted {
            self.resident.remove(k);
        }
        let blocks = keys
            .iter()
            .filter_map(|k| self.resident.get(k).cloned())
            .collect();
        let index = self.frames;
        self.frames += 1;
        Ok(FlightFrame {
            index,
            blocks,
            keys,
            loaded,
            evicted,
            stats,
        })
    }
}
