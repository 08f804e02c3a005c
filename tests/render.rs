//! Pictures of scenes (`fmrh::render`, `fmrh render`) show what they claim: looking
//! straight down at terrain that fills the view leaves no sky; looking away from it leaves
//! nothing but sky; on an overhead map every block is drawn in its level's hue (blocks of one
//! level alike on flat ground, of different levels apart), its edges dark, the eye in the
//! frustum's colour, and a legend of each level's hue; the same scene gives the same bytes; the PNG holds the picture. The
//! CLI writes both kinds and keeps an existing file without --force.

mod common;

use fmrh::render::{
    perspective, top, Image, MapGround, Surface, FRUSTUM_COLOUR, LEGEND_MARGIN, LEGEND_SWATCH,
};
use fmrh::scene::{reconstruct, Camera, SceneOptions, Terrain, WorldFrame};
use fmrh::store::Store;
use fmrh::store::WriteOptions;
use glam::DVec3;

/// A container of `field` (blocks of 17 samples) in memory.
fn store_of(field: &fmrh::Heightfield) -> Store<fmrh::store::Bytes<Vec<u8>>> {
    Store::from_bytes(common::bytes_of(field, 17, &WriteOptions::default())).unwrap()
}

/// The scene of `camera` at `tau` and the picture `draw` makes of it, over `window` (or the
/// scene's).
fn picture(
    store: &Store<fmrh::store::Bytes<Vec<u8>>>,
    camera: &Camera,
    tau: f64,
    whole: bool,
    draw: impl Fn(&Surface<'_>) -> Image,
) -> (fmrh::scene::Scene, Image) {
    let terrain = Terrain::with_spacing(store, Some([10.0, 10.0])).unwrap();
    let scene = terrain.scene(camera, &SceneOptions::new(tau)).unwrap();
    let window = if whole {
        store.domain().data_rect()
    } else {
        scene.window.unwrap()
    };
    let rec = reconstruct(store, &scene, window).unwrap();
    let surface = Surface {
        window,
        heights: &rec.values,
        blocks: &scene.blocks,
        frame: WorldFrame::new(Some([10.0, 10.0])),
    };
    let image = draw(&surface);
    (scene, image)
}

/// The sky's colour at row `y` of a picture `height` rows high.
fn sky(y: u32, height: u32) -> [u8; 3] {
    let t = y as f32 / height as f32;
    [(150.0 + 70.0 * t) as u8, (190.0 + 45.0 * t) as u8, 240]
}

#[test]
fn looking_down_at_terrain_that_fills_the_view_leaves_no_sky() {
    let field = common::fields::make(257, 257, common::fields::Character::Hills, 0.0, 3);
    let store = store_of(&field);
    // 2,560 m across; from 1,500 m up a 40° view sees about 1,100 m of it.
    let mut camera = Camera::looking_at(
        DVec3::new(1280.0, 1280.0, 1500.0),
        DVec3::new(1280.0, 1281.0, 0.0),
    );
    camera.fov_y_deg = 40.0;
    camera.viewport = [320, 240];
    let (scene, image) = picture(&store, &camera, 1.0, false, |s| {
        perspective(s, &camera).unwrap()
    });
    assert!(!scene.blocks.is_empty());
    assert_eq!((image.width, image.height), (320, 240));
    for y in 0..image.height {
        for x in 0..image.width {
            assert_ne!(image.pixel(x, y), sky(y, image.height), "({x}, {y}) is sky");
        }
    }
}

#[test]
fn looking_away_from_the_terrain_shows_only_sky() {
    let field = common::fields::make(129, 129, common::fields::Character::Hills, 0.0, 5);
    let store = store_of(&field);
    let mut camera = Camera::looking_at(
        DVec3::new(640.0, 640.0, 5000.0),
        DVec3::new(640.0, 0.0, 9000.0),
    );
    camera.viewport = [160, 120];
    let terrain = Terrain::with_spacing(&store, Some([10.0, 10.0])).unwrap();
    let scene = terrain.scene(&camera, &SceneOptions::new(1.0)).unwrap();
    // The scene sees nothing; draw the whole terrain anyway: none of it is in view.
    let window = store.domain().data_rect();
    let rec = reconstruct(&store, &scene, window).unwrap();
    let surface = Surface {
        window,
        heights: &rec.values,
        blocks: &scene.blocks,
        frame: WorldFrame::new(Some([10.0, 10.0])),
    };
    let image = perspective(&surface, &camera).unwrap();
    for y in 0..image.height {
        for x in 0..image.width {
            assert_eq!(image.pixel(x, y), sky(y, image.height));
        }
    }
}

#[test]
fn an_overhead_map_tints_blocks_by_level_and_marks_the_eye() {
    // Flat ground: every sample gets the same light, so a block's colour is its level's.
    let field = fmrh::Heightfield::from_fn(257, 257, |x, y| {
        (x as f32 * 0.001).floor() + (y as f32 * 0.0)
    })
    .unwrap();
    let field = {
        // Rough enough in one corner that the scene refines there and stays coarse elsewhere.
        let mut samples = field.samples().to_vec();
        for y in 0..64usize {
            for x in 0..64usize {
                samples[y * 257 + x] = ((x * 7919 + y * 104_729) % 13) as f32 * 3.0;
            }
        }
        fmrh::Heightfield::new(257, 257, samples).unwrap()
    };
    let store = store_of(&field);
    let camera = Camera::looking_at(
        DVec3::new(300.0, 300.0, 400.0),
        DVec3::new(1500.0, 1500.0, 0.0),
    );
    let side = 514;
    let (scene, image) = picture(&store, &camera, 1.0, true, |s| {
        top(s, &camera, side, MapGround::Grid { north_deg: None })
            .unwrap()
            .image
    });
    let levels: std::collections::BTreeSet<u8> = scene.blocks.iter().map(|b| b.level).collect();
    assert!(levels.len() >= 2, "levels {levels:?}");
    // The picture spans the terrain (the eye is above it): 2 pixels a sample.
    assert_eq!((image.width, image.height), (side, side));
    let mut colour_of_level = std::collections::BTreeMap::new();
    for b in &scene.blocks {
        // A pixel well inside the block, away from its edges and the frustum's lines.
        let (cx, cy) = ((b.col0 + b.col1) as f64, (b.row0 + b.row1) as f64);
        let (px, py) = (cx as u32, cy as u32);
        let c = image.pixel(px, py);
        if c == FRUSTUM_COLOUR {
            continue;
        }
        let flat = (b.col0 >= 64 || b.row0 >= 64) && b.max_height == b.min_height;
        if flat {
            let seen = colour_of_level.entry(b.level).or_insert(c);
            assert_eq!(*seen, c, "level {} drawn two ways", b.level);
        }
        // Its right edge, when another block lies beyond it, is drawn dark: in its hue or
        // in its neighbour's (the two share the edge's samples; whichever draws them).
        let mid_row = (b.row0 + b.row1) / 2;
        let beyond = scene.blocks.iter().find(|n| {
            (n.col0..=n.col1).contains(&(b.col1 + 1)) && (n.row0..=n.row1).contains(&mid_row)
        });
        if let Some(n) = beyond {
            let dark =
                |l: u8| fmrh::render::level_colour(l).map(|v| (f32::from(v) * 0.45).round() as u8);
            let span = (b.col1 * 2).saturating_sub(2) as u32..=(b.col1 * 2 + 1) as u32;
            let found = span.clone().any(|x| {
                let c = image.pixel(x, py);
                c == dark(b.level) || c == dark(n.level) || c == FRUSTUM_COLOUR
            });
            assert!(
                found,
                "block {:?}: no edge at pixels {span:?}",
                (b.level, b.x, b.y)
            );
        }
    }
    let distinct: std::collections::BTreeSet<[u8; 3]> = colour_of_level.values().copied().collect();
    assert_eq!(distinct.len(), colour_of_level.len(), "{colour_of_level:?}");
    // The eye, at (300 m, 300 m): sample 30, pixel 60.
    assert_eq!(image.pixel(60, 60), FRUSTUM_COLOUR);
    // The legend, in the north-west corner: a swatch of each level's own hue, one under
    // another, on white.
    let (m, sw) = (LEGEND_MARGIN as u32, LEGEND_SWATCH as u32);
    assert_eq!(image.pixel(m, m), [255, 255, 255]);
    for (i, &l) in levels.iter().enumerate() {
        let (x0, y0) = (m + 4, m + 4 + (sw + 4) * i as u32);
        for y in y0..y0 + sw {
            for x in x0..x0 + sw {
                assert_eq!(
                    image.pixel(x, y),
                    fmrh::render::level_colour(l),
                    "legend of level {l}"
                );
            }
        }
    }
    let below = m + 4 + (sw + 4) * levels.len() as u32;
    assert_eq!(image.pixel(m + 4 + sw, below + sw / 2), FRUSTUM_COLOUR);
}

#[test]
fn pictures_are_deterministic_and_their_png_holds_them() {
    let field = common::fields::make(129, 129, common::fields::Character::Cliff, 0.05, 9);
    let store = store_of(&field);
    let mut camera = Camera::looking_at(
        DVec3::new(-200.0, 640.0, 800.0),
        DVec3::new(640.0, 640.0, 0.0),
    );
    camera.viewport = [200, 150];
    let draw = |s: &Surface<'_>| perspective(s, &camera).unwrap();
    let (_, a) = picture(&store, &camera, 2.0, false, draw);
    let (_, b) = picture(&store, &camera, 2.0, false, draw);
    assert_eq!(a, b);
    let mut png_bytes = Vec::new();
    a.write_png(&mut png_bytes).unwrap();
    let decoder = png::Decoder::new(std::io::Cursor::new(png_bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (200, 150));
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(&buf[..info.buffer_size()], &a.rgb[..]);
}

#[test]
fn the_cli_draws_both_pictures_and_keeps_an_existing_file() {
    let dir = tempfile::tempdir().unwrap();
    let container = dir.path().join("ps1k.fmrh");
    let png_in = common::bundled_dir().join("puget-sound-1k/ps_height_1k.png");
    let out = common::fmrh(&[
        "build",
        png_in.to_str().unwrap(),
        "--z-scale",
        "0.1",
        "--spacing",
        "160",
        "-o",
        container.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let camera = [
        "--eye",
        "20000,180000,6000",
        "--target",
        "80000,80000,500",
        "--tau",
        "2",
        "--viewport",
        "320x240",
    ];
    for (extra, name, size) in [
        (None, "view.png", (320, 240)),
        (Some("--top"), "top.png", (227, 256)),
    ] {
        let path = dir.path().join(name);
        let mut args = vec!["render", container.to_str().unwrap()];
        args.extend(camera);
        args.extend(extra);
        args.extend(["--size", "256", "-o", path.to_str().unwrap()]);
        let out = common::fmrh(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let decoder =
            png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()));
        let reader = decoder.read_info().unwrap();
        assert_eq!((reader.info().width, reader.info().height), size, "{name}");
        // Again without --force: refused, the picture kept.
        let before = std::fs::read(&path).unwrap();
        let out = common::fmrh(&args);
        assert_eq!(out.status.code(), Some(2));
        assert_eq!(std::fs::read(&path).unwrap(), before);
    }
}

/// A dataset is drawn across its tiles: seen whole from high above, its overhead map has no
/// sample left undrawn and shows the eye; its view through the camera has the viewport's
/// size.
#[test]
fn the_cli_draws_a_dataset_across_its_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let field = common::fields::make(257, 257, common::fields::Character::Hills, 0.0, 21);
    let rects = common::tiles::split(&field, &[0, 128, 256], &[0, 128, 256], &[]);
    let ds = common::tiles::build(dir.path(), &field, &rects, &common::tiles::options(None));
    // 2,560 m a side, 10 m a sample; the eye above its centre, high.
    let camera = [
        "--eye",
        "1280,1300,9000",
        "--target",
        "1280,1280,0",
        "--tau",
        "4",
        "--viewport",
        "200x150",
    ];
    let top = dir.path().join("top.png");
    let mut args = vec!["render", ds.to_str().unwrap()];
    args.extend(camera);
    args.extend(["--top", "--size", "257", "-o", top.to_str().unwrap()]);
    let out = common::fmrh(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&top).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (257, 257));
    let pixel = |x: u32, y: u32| {
        let i = ((y * info.width + x) * 3) as usize;
        [buf[i], buf[i + 1], buf[i + 2]]
    };
    // The white panels of the legend (north-west), the north arrow (north-east) and the
    // scale bar (south-west), each from its corner along its edges.
    let white = [255, 255, 255];
    let panel = |x0: u32, y0: u32, dx: i64, dy: i64| {
        assert_eq!(pixel(x0, y0), white, "a panel's corner at ({x0}, {y0})");
        let run = |step: &dyn Fn(i64) -> (u32, u32)| {
            (0..)
                .map(step)
                .take_while(|&(x, y)| x < info.width && y < info.height && pixel(x, y) == white)
                .last()
                .unwrap()
        };
        let (x1, _) = run(&|k| ((i64::from(x0) + dx * k) as u32, y0));
        let (_, y1) = run(&|k| (x0, (i64::from(y0) + dy * k) as u32));
        (x0.min(x1)..=x0.max(x1), y0.min(y1)..=y0.max(y1))
    };
    let m = LEGEND_MARGIN as u32;
    let corner = 8;
    let panels = [
        panel(m, m, 1, 1),
        panel(info.width - 1 - corner, corner, -1, 1),
        panel(corner, info.height - 1 - corner, 1, -1),
    ];
    for y in 0..info.height {
        for x in 0..info.width {
            if panels
                .iter()
                .any(|(xs, ys)| xs.contains(&x) && ys.contains(&y))
            {
                continue;
            }
            let [r, g, b] = pixel(x, y);
            assert_ne!([r, g, b], [235, 235, 235], "({x}, {y}) undrawn");
            // Drawn by a block: tinted by its level, never the grey of no block.
            assert!(!(r == g && g == b), "({x}, {y}) grey: no block drew it");
        }
    }
    assert_eq!(pixel(128, 130), FRUSTUM_COLOUR);
    let view = dir.path().join("view.png");
    let mut args = vec!["render", ds.to_str().unwrap()];
    args.extend(camera);
    args.extend(["-o", view.to_str().unwrap()]);
    let out = common::fmrh(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&view).unwrap()));
    let reader = decoder.read_info().unwrap();
    assert_eq!((reader.info().width, reader.info().height), (200, 150));
}
