//! One camera for every picture. A scene that is not symmetric east-west (flat ground, an
//! 800 m tower in the east, a 300 m ridge in the north-west) is seen from the south, looking
//! north: the tower must be on the right and the ridge on the left wherever fmrh shows it:
//! where the camera's projection (`View::project`) puts them; in the picture
//! `fmrh::render::perspective` draws and in the PNG `fmrh render` writes; in the `.glb`
//! `fmrh mesh` writes, seen by a glTF camera at the same place (glTF is right-handed, Y up);
//! and in the selection, the camera turned to its screen-right seeing the tower's blocks and
//! not the ridge's, turned to its left the reverse. (fmrh's flat frame is left-handed; until
//! issue 40 the pictures took the screen's right as `forward × up` and came out mirrored.)
//! And for any camera, a flat-frame camera and its mirror image declared right-handed put
//! every point on the same pixel. The viewer's side is checked in the browser suite
//! (`tests/viewer.rs`).

mod common;

use common::tower::{
    camera as camera_on, containers, field, top_of, EYE, RIDGE, SIDE, SPACING, TARGET, TOWER,
};
use fmrh::render::{perspective, Image, Surface};
use fmrh::scene::{Camera, SceneOptions, Terrain, WorldFrame};
use fmrh::Heightfield;
use glam::DVec3;

/// The scene's camera on a 320 × 240 picture.
fn camera() -> Camera {
    camera_on([320, 240])
}

/// The picture of `field`'s exact heights (no blocks: the camera's geometry alone).
fn draw(field: &Heightfield) -> Image {
    let heights: Vec<f64> = field.samples().iter().map(|&v| f64::from(v)).collect();
    let surface = Surface {
        window: fmrh::model::SampleRect {
            col0: 0,
            row0: 0,
            col1: u64::from(SIDE) - 1,
            row1: u64::from(SIDE) - 1,
        },
        heights: &heights,
        blocks: &[],
        frame: WorldFrame::new(Some([SPACING, SPACING])),
    };
    perspective(&surface, &camera()).unwrap()
}

/// The pixels where two pictures differ, as (x, y).
fn differing(a: &Image, b: &Image) -> Vec<(u32, u32)> {
    assert_eq!((a.width, a.height), (b.width, b.height));
    let mut out = Vec::new();
    for y in 0..a.height {
        for x in 0..a.width {
            let i = (y as usize * a.width as usize + x as usize) * 3;
            if a.rgb[i..i + 3] != b.rgb[i..i + 3] {
                out.push((x, y));
            }
        }
    }
    out
}

/// Checks that the feature the two pictures differ by lies on the screen where `at`
/// projects, all of it on the side `right` says.
fn feature_on_its_side(with: &Image, without: &Image, at: DVec3, right: bool, what: &str) {
    let view = camera().view().unwrap();
    let [px, py, _] = view.project(at).unwrap();
    let centre = f64::from(with.width) / 2.0;
    assert_eq!(
        px > centre,
        right,
        "{what}: the camera projects it at x = {px}"
    );
    let diff = differing(with, without);
    assert!(diff.len() > 50, "{what}: drawn in {} pixels", diff.len());
    for &(x, _) in &diff {
        assert_eq!(
            f64::from(x) + 0.5 > centre,
            right,
            "{what}: drawn at x = {x}, the camera puts it at {px}"
        );
    }
    // The drawn feature surrounds where the camera projects its top.
    let (x0, x1) = (
        diff.iter().map(|d| d.0).min(),
        diff.iter().map(|d| d.0).max(),
    );
    let (y0, y1) = (
        diff.iter().map(|d| d.1).min(),
        diff.iter().map(|d| d.1).max(),
    );
    assert!(
        (f64::from(x0.unwrap())..=f64::from(x1.unwrap()) + 1.0).contains(&px)
            && (f64::from(y0.unwrap())..=f64::from(y1.unwrap()) + 1.0).contains(&py),
        "{what}: drawn in x {x0:?}..{x1:?}, y {y0:?}..{y1:?}; projected at ({px}, {py})"
    );
}

#[test]
fn the_projection_puts_east_on_the_right_in_the_flat_frame() {
    let view = camera().view().unwrap();
    // Looking north in a frame where x is east: the screen's right is +x, its up +z.
    assert!((view.right - DVec3::X).length() < 1e-12, "{:?}", view.right);
    assert!(view.up.z > 0.0);
    // Straight down, north up: east is on the right and north at the top.
    let down = Camera::looking_at(DVec3::new(0.0, 0.0, 100.0), DVec3::new(0.0, 0.0, 0.0));
    let v = down.view().unwrap();
    let east = v.project(DVec3::new(10.0, 0.0, 0.0)).unwrap();
    let north = v.project(DVec3::new(0.0, -10.0, 0.0)).unwrap();
    assert!(east[0] > v.centre[0] && (east[1] - v.centre[1]).abs() < 1e-9);
    assert!(north[1] < v.centre[1] && (north[0] - v.centre[0]).abs() < 1e-9);
}

#[test]
fn on_the_globe_east_is_on_the_right_too() {
    // 45° N 7° E, 2 km up, looking north and down: a point east of the meridian is on the
    // right, one to the west on the left.
    let cam = Camera::on_globe(45.0, 7.0, 2000.0, 0.0, -20.0);
    let v = cam.view().unwrap();
    let east = v.project(fmrh::globe::ecef_point(7.05, 45.1, 0.0)).unwrap();
    let west = v.project(fmrh::globe::ecef_point(6.95, 45.1, 0.0)).unwrap();
    assert!(
        east[0] > v.centre[0] && west[0] < v.centre[0],
        "{east:?} {west:?}"
    );
}

#[test]
fn the_picture_draws_each_feature_where_the_camera_projects_it() {
    let both = draw(&field(true, true));
    let no_tower = draw(&field(false, true));
    let no_ridge = draw(&field(true, false));
    feature_on_its_side(
        &both,
        &no_tower,
        top_of(TOWER, common::tower::TOWER_M),
        true,
        "the tower",
    );
    feature_on_its_side(
        &both,
        &no_ridge,
        top_of(RIDGE, common::tower::RIDGE_M),
        false,
        "the ridge",
    );
}

#[test]
fn fmrh_render_draws_the_tower_right_and_the_ridge_left() {
    let dir = tempfile::tempdir().unwrap();
    let mut pictures = Vec::new();
    for file in containers(dir.path()) {
        let png = file.with_extension("png");
        let out = common::fmrh(&[
            "render",
            file.to_str().unwrap(),
            "--eye",
            EYE,
            "--target",
            TARGET,
            "--tau",
            "1",
            "--viewport",
            "320x240",
            "-o",
            png.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let decoder =
            png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
        let mut reader = decoder.read_info().unwrap();
        let mut rgb = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut rgb).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb);
        rgb.truncate(info.buffer_size());
        pictures.push(Image {
            width: info.width,
            height: info.height,
            rgb,
        });
    }
    feature_on_its_side(
        &pictures[0],
        &pictures[1],
        top_of(TOWER, common::tower::TOWER_M),
        true,
        "the tower",
    );
    feature_on_its_side(
        &pictures[0],
        &pictures[2],
        top_of(RIDGE, common::tower::RIDGE_M),
        false,
        "the ridge",
    );
}

#[test]
fn the_glb_puts_the_tower_on_a_gltf_cameras_right() {
    let dir = tempfile::tempdir().unwrap();
    let [file, _, _] = containers(dir.path());
    let glb = dir.path().join("tower.glb");
    let out = common::fmrh(&[
        "mesh",
        file.to_str().unwrap(),
        "--eye",
        EYE,
        "--target",
        TARGET,
        "--tau",
        "1",
        "-o",
        glb.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (json, bin) = common::gltf::chunks(&std::fs::read(&glb).unwrap());
    let origin = &json["scenes"][0]["extras"]["fmrh"]["origin"]["world_m"];
    let (ox, oy) = (origin[0].as_f64().unwrap(), origin[1].as_f64().unwrap());
    // The camera in glTF's axes (X east, Y up, Z south from the origin), right-handed: its
    // right is forward × up.
    let gltf = |p: DVec3| DVec3::new(p.x - ox, p.z, p.y - oy);
    let cam = camera();
    let (eye, target) = (gltf(cam.eye), gltf(cam.target));
    let forward = (target - eye).normalize();
    let right = forward.cross(DVec3::Y).normalize();
    let (mut tower, mut ridge) = (0, 0);
    for mesh in json["meshes"].as_array().unwrap() {
        let a = mesh["primitives"][0]["attributes"]["POSITION"]
            .as_u64()
            .unwrap();
        for p in common::gltf::read_accessor(&json, &bin, a).chunks_exact(3) {
            let p = DVec3::new(p[0], p[1], p[2]);
            let side = (p - eye).dot(right);
            if p.y > 799.0 {
                tower += 1;
                assert!(
                    side > 0.0,
                    "a tower vertex {p} is on the glTF camera's left"
                );
            } else if (p.y - 300.0).abs() < 0.01 {
                ridge += 1;
                assert!(
                    side < 0.0,
                    "a ridge vertex {p} is on the glTF camera's right"
                );
            }
        }
    }
    assert!(
        tower > 4 && ridge > 4,
        "tower {tower}, ridge {ridge} vertices"
    );
}

#[test]
fn turned_to_its_right_the_camera_selects_the_tower_and_not_the_ridge() {
    let field = field(true, true);
    let store =
        fmrh::store::Store::from_bytes(common::bytes_of(&field, 17, &Default::default())).unwrap();
    let terrain = Terrain::with_spacing(&store, Some([SPACING, SPACING])).unwrap();
    let cam = camera();
    let view = cam.view().unwrap();
    // Turned by half the horizontal field of view: the old centre line is the new frustum's
    // edge, so a feature on the screen's right is in view only when turned right.
    let tan_x = (cam.fov_y_deg.to_radians() / 2.0).tan() * 320.0 / 240.0;
    for (turn, sees_tower) in [(1.0, true), (-1.0, false)] {
        let turned = Camera {
            target: cam.eye + view.forward + view.right * (turn * tan_x),
            ..cam
        };
        let scene = terrain.scene(&turned, &SceneOptions::new(1.0)).unwrap();
        let holds = |r: [u32; 4]| {
            scene.blocks.iter().any(|b| {
                b.col0 <= u64::from(r[2])
                    && b.col1 >= u64::from(r[0])
                    && b.row0 <= u64::from(r[3])
                    && b.row1 >= u64::from(r[1])
            })
        };
        assert_eq!(holds(TOWER), sees_tower, "turned {turn}: the tower");
        assert_eq!(holds(RIDGE), !sees_tower, "turned {turn}: the ridge");
    }
}

/// `p` seen in a mirror that turns y round: the right-handed twin of a flat-frame point.
fn mirrored(p: DVec3) -> DVec3 {
    DVec3::new(p.x, -p.y, p.z)
}

proptest::proptest! {
    /// The handedness is the only difference between the two frames: a flat-frame camera
    /// and its mirror image, declared right-handed, put every point and its mirror image on
    /// the same pixel. (Had either basis been built the wrong way round, the two would be
    /// mirror images of each other.)
    #[test]
    fn a_camera_and_its_mirror_image_agree_on_every_pixel(
        eye in proptest::array::uniform3(-5000.0f64..5000.0),
        target in proptest::array::uniform3(-5000.0f64..5000.0),
        p in proptest::array::uniform3(-5000.0f64..5000.0),
        up in proptest::array::uniform3(-1.0f64..1.0),
        fov in 10.0f64..120.0,
    ) {
        let (eye, target, p, up) = (
            DVec3::from_array(eye),
            DVec3::from_array(target),
            DVec3::from_array(p),
            DVec3::from_array(up),
        );
        proptest::prop_assume!((target - eye).length() > 1.0 && up.length() > 0.1);
        let left = Camera {
            up,
            fov_y_deg: fov,
            viewport: [640, 480],
            ..Camera::looking_at(eye, target)
        };
        let right = Camera {
            eye: mirrored(eye),
            target: mirrored(target),
            up: mirrored(up),
            handedness: fmrh::scene::Handedness::Right,
            ..left
        };
        let (Ok(a), Ok(b)) = (left.view(), right.view()) else {
            // The same degenerate camera either way round.
            proptest::prop_assert_eq!(left.view().is_ok(), right.view().is_ok());
            return Ok(());
        };
        match (a.project(p), b.project(mirrored(p))) {
            (Some(a), Some(b)) => {
                for i in 0..3 {
                    let scale = 1.0 + a[i].abs();
                    proptest::prop_assert!((a[i] - b[i]).abs() < 1e-6 * scale, "{a:?} {b:?}");
                }
            }
            (a, b) => proptest::prop_assert!(a.is_none() && b.is_none(), "{a:?} {b:?}"),
        }
        // The view's own axes: forward lands on the centre, right to its right, up above it.
        let ahead = a.project(eye + a.forward * 100.0).unwrap();
        let right_of = a.project(eye + a.forward * 100.0 + a.right).unwrap();
        let above = a.project(eye + a.forward * 100.0 + a.up).unwrap();
        proptest::prop_assert!((ahead[0] - a.centre[0]).abs() < 1e-6 && (ahead[1] - a.centre[1]).abs() < 1e-6);
        proptest::prop_assert!(right_of[0] > ahead[0] && above[1] < ahead[1]);
        // And in the flat frame, right is up × forward: east of a camera looking north.
        proptest::prop_assert!(a.up.cross(a.forward).dot(a.right) > 0.999);
    }
}
