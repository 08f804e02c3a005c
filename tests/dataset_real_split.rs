//! One file or many gives the same terrain, on a real DEM: Mount St Helens (bundled USGS DEM,
//! 327 x 466, 3,497 voids) cut into 2 x 2 to 3 x 3 tiles at random lines that neighbours
//! share, built as a dataset and as one container with the same options. The dataset extracts
//! to exactly the single file's samples, whole and in random windows, and random scenes over
//! it are covers of their windows (every cell once), cover every visible sample without a
//! window, and keep every block within tau, recomputed in the dataset's frame.

mod common;

use std::sync::OnceLock;

use proptest::prelude::*;

use common::fields::Rng;
use common::tiles::{self, camera, check_scene, cuts};
use fmrh::dataset::Dataset;
use fmrh::model::{BuildOptions, SampleRect, Thresholds};
use fmrh::scene::{Mode, SceneOptions};
use fmrh::store::{Bytes, Store, WriteOptions};
use fmrh::Heightfield;

fn st_helens() -> &'static (Heightfield, Store<Bytes<Vec<u8>>>) {
    static F: OnceLock<(Heightfield, Store<Bytes<Vec<u8>>>)> = OnceLock::new();
    F.get_or_init(|| {
        let hf = fmrh::ingest::load(
            &common::data("mount-st-helens-usgs/SainteHelens.dem"),
            &Default::default(),
        )
        .unwrap();
        let bytes = common::bytes_of(
            &hf,
            9,
            &WriteOptions {
                page_size: 1024,
                ..Default::default()
            },
        );
        (hf, Store::from_bytes(bytes).unwrap())
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 6, ..ProptestConfig::default() })]

    #[test]
    fn a_real_dem_split_into_tiles_is_the_same_terrain(k in 1usize..=2, seed in any::<u64>(), tau in 0.5f64..4.0, uniform in any::<bool>()) {
        let (field, single) = st_helens();
        let (w, h) = (u64::from(field.width()), u64::from(field.height()));
        let mut rng = Rng::new(seed);
        let rects = tiles::split(field, &cuts(w, k, &mut rng), &cuts(h, k, &mut rng), &[]);
        let dir = tempfile::tempdir().unwrap();
        let options = fmrh::dataset::DatasetOptions {
            build: BuildOptions { block_size: 9, thresholds: Thresholds::Ladder, precision: None, thin: Default::default() },
            ..tiles::options(None)
        };
        let ds = Dataset::open(&tiles::build(dir.path(), field, &rects, &options)).unwrap();
        let whole = single.domain().data_rect();
        prop_assert!(common::first_difference(ds.read_window(whole).unwrap().samples(), single.read_window(whole).unwrap().samples()).is_none());
        for _ in 0..4 {
            let (a, b) = (rng.next_u64() % w, rng.next_u64() % w);
            let (c, d) = (rng.next_u64() % h, rng.next_u64() % h);
            let win = SampleRect { col0: a.min(b), row0: c.min(d), col1: a.max(b), row1: c.max(d) };
            prop_assert!(common::first_difference(ds.read_window(win).unwrap().samples(), single.read_window(win).unwrap().samples()).is_none());
        }
        let mode = if uniform { Mode::Uniform } else { Mode::View };
        let cam = camera(&mut rng, w as f64, h as f64);
        let (a, b) = (rng.next_u64() % (w - 1), rng.next_u64() % (w - 1));
        let (c, d) = (rng.next_u64() % (h - 1), rng.next_u64() % (h - 1));
        let win = SampleRect { col0: a.min(b), row0: c.min(d), col1: a.max(b) + 1, row1: c.max(d) + 1 };
        let options = SceneOptions { tau, mode, window: Some(win), gap: fmrh::scene::DEFAULT_GAP };
        check_scene(&ds.scene(&cam, &options, None).unwrap(), field, &rects, &cam, mode, tau, Some(win));
        check_scene(&ds.scene(&cam, &SceneOptions { window: None, ..options }, None).unwrap(), field, &rects, &cam, mode, tau, None);
    }
}
