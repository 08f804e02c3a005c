//! Camera paths: one camera a line in a CSV file, and generators of the three kinds of
//! flight the shipped paths are made of (straight, orbit, low pass).
//!
//! A line is `eye_x,eye_y,eye_z,target_x,target_y,target_z` in world metres (see
//! [`super::camera`]). Blank lines, lines starting with `#`, and a first line that is not
//! numeric (a header) are skipped. Field of view and viewport come from the caller.

use glam::DVec3;

use crate::error::{Error, Result};

use super::camera::Camera;

/// The CSV header the generators write.
pub const HEADER: &str = "eye_x,eye_y,eye_z,target_x,target_y,target_z";

/// Parses a path; every camera gets `template`'s up, field of view and viewport.
pub fn parse(text: &str, template: &Camera) -> Result<Vec<Camera>> {
    parse_lines(text, &format!("six numbers {HEADER}"), |v| {
        (v.len() == 6).then(|| Camera {
            eye: DVec3::new(v[0], v[1], v[2]),
            target: DVec3::new(v[3], v[4], v[5]),
            ..*template
        })
    })
}

/// Parses a path of cameras on the globe: one camera a line,
/// `latitude,longitude,height,heading,pitch` (degrees, metres above the ellipsoid, heading
/// clockwise from north, pitch above the horizontal), placed by [`Camera::on_globe`] in
/// ECEF metres. Lines are skipped as [`parse`] skips them; field of view and viewport come
/// from `template`.
pub fn parse_geo(text: &str, template: &Camera) -> Result<Vec<Camera>> {
    parse_lines(
        text,
        "latitude,longitude,height,heading,pitch (latitude within -90..=90)",
        |v| {
            (v.len() == 5 && v[0].abs() <= 90.0).then(|| Camera {
                fov_y_deg: template.fov_y_deg,
                viewport: template.viewport,
                ..Camera::on_globe(v[0], v[1], v[2], v[3], v[4])
            })
        },
    )
}

/// The cameras `camera` makes of the numbers of each line of `text` (`None`: not a camera,
/// so not `expected`), blank lines, `#` comments and a non-numeric first line (a header)
/// skipped; each camera must make a view.
fn parse_lines(
    text: &str,
    expected: &str,
    camera: impl Fn(&[f64]) -> Option<Camera>,
) -> Result<Vec<Camera>> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let values: Option<Vec<f64>> = line.split(',').map(|f| f.trim().parse().ok()).collect();
        let cam = match values {
            Some(v) if v.iter().all(|x| x.is_finite()) => camera(&v),
            None if out.is_empty() && n == 0 => continue, // a header
            _ => None,
        };
        let Some(cam) = cam else {
            return Err(Error::InvalidArgument(format!(
                "camera path line {}: expected {expected}, got `{line}`",
                n + 1
            )));
        };
        cam.view()
            .map_err(|e| Error::InvalidArgument(format!("camera path line {}: {e}", n + 1)))?;
        out.push(cam);
    }
    if out.is_empty() {
        return Err(Error::InvalidArgument(
            "the camera path has no camera".into(),
        ));
    }
    Ok(out)
}

/// Writes cameras as CSV (with [`HEADER`]), numbers rounded to centimetres.
#[cfg(any(test, feature = "testing"))]
pub fn to_csv(cameras: &[Camera]) -> String {
    let mut s = format!("{HEADER}\n");
    for c in cameras {
        let [a, b, d] = c.eye.to_array();
        let [e, f, g] = c.target.to_array();
        s.push_str(&format!("{a:.2},{b:.2},{d:.2},{e:.2},{f:.2},{g:.2}\n"));
    }
    s
}

/// The terrain a path is laid over: its extent in metres and a way to ask for the highest
/// ground near a point.
#[cfg(any(test, feature = "testing"))]
pub struct Ground<'a> {
    /// East extent in metres.
    pub width: f64,
    /// South extent in metres.
    pub height: f64,
    /// The highest ground within `radius` metres of `(x, y)`.
    pub highest: &'a dyn Fn(f64, f64, f64) -> f64,
}

/// A straight, level flight across the terrain from the south-west to the north-east at
/// `altitude` metres above the highest ground, looking ahead and down, `frames` cameras.
#[cfg(any(test, feature = "testing"))]
pub fn straight(ground: &Ground<'_>, altitude: f64, frames: usize) -> Vec<Camera> {
    let top = (ground.highest)(
        ground.width / 2.0,
        ground.height / 2.0,
        ground.width.max(ground.height),
    );
    let z = top + altitude;
    let (a, b) = (
        DVec3::new(0.1 * ground.width, 0.9 * ground.height, z),
        DVec3::new(0.9 * ground.width, 0.1 * ground.height, z),
    );
    let dir = (b - a).normalize();
    let look = dir * (0.25 * ground.width.max(ground.height));
    (0..frames)
        .map(|i| {
            let t = i as f64 / (frames.max(2) - 1) as f64;
            let eye = a + (b - a) * t;
            Camera::looking_at(
                eye,
                DVec3::new(eye.x + look.x, eye.y + look.y, z - 3.0 * altitude),
            )
        })
        .collect()
}

/// An orbit around the centre at `radius_frac` of the extent, `altitude` above the highest
/// ground, always looking at the centre, one full turn in `frames` cameras.
#[cfg(any(test, feature = "testing"))]
pub fn orbit(ground: &Ground<'_>, radius_frac: f64, altitude: f64, frames: usize) -> Vec<Camera> {
    let (cx, cy) = (ground.width / 2.0, ground.height / 2.0);
    let r = radius_frac * ground.width.max(ground.height);
    let top = (ground.highest)(cx, cy, ground.width.max(ground.height));
    let centre = DVec3::new(cx, cy, (ground.highest)(cx, cy, 0.0));
    (0..frames)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / frames as f64;
            let eye = DVec3::new(cx + r * a.cos(), cy + r * a.sin(), top + altitude);
            Camera::looking_at(eye, centre)
        })
        .collect()
}

/// A low pass: from the west edge to the east edge at `row_frac` of the way south,
/// `clearance` metres above the highest ground within `lookahead` metres, looking
/// `lookahead` ahead at ground level, `frames` cameras. Over rough ground the eye rides up
/// and down with the terrain.
#[cfg(any(test, feature = "testing"))]
pub fn low_pass(
    ground: &Ground<'_>,
    row_frac: f64,
    clearance: f64,
    lookahead: f64,
    frames: usize,
) -> Vec<Camera> {
    let y = ground.height * row_frac;
    (0..frames)
        .map(|i| {
            let t = i as f64 / (frames.max(2) - 1) as f64;
            let x = 0.02 * ground.width + 0.96 * ground.width * t;
            let z = (ground.highest)(x, y, lookahead) + clearance;
            let ahead = (x + lookahead).min(ground.width);
            let tz = (ground.highest)(ahead, y, 0.0);
            Camera::looking_at(DVec3::new(x, y, z), DVec3::new(ahead + 1.0, y, tz))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_round_trips_and_reports_bad_lines() {
        let flat = |_: f64, _: f64, _: f64| 10.0;
        let g = Ground {
            width: 1000.0,
            height: 800.0,
            highest: &flat,
        };
        let cams = orbit(&g, 0.3, 200.0, 12);
        let text = to_csv(&cams);
        let template = Camera::looking_at(DVec3::ZERO, DVec3::X);
        let back = parse(&text, &template).unwrap();
        assert_eq!(back.len(), 12);
        for (a, b) in cams.iter().zip(&back) {
            assert!((a.eye - b.eye).length() < 0.01 && (a.target - b.target).length() < 0.01);
        }
        assert!(parse("", &template).is_err());
        let err = parse("1,2,3,4,5\n", &template).unwrap_err().to_string();
        assert!(err.contains("line 1"), "{err}");
        let err = parse(&format!("{HEADER}\n1,2,3,1,2,3\n"), &template)
            .unwrap_err()
            .to_string();
        assert!(err.contains("line 2") && err.contains("differ"), "{err}");
        let err = parse("1,2,3,4,5,6\nx,y,z,a,b,c\n", &template)
            .unwrap_err()
            .to_string();
        assert!(err.contains("line 2"), "{err}");
        assert!(parse("1,2,nan,4,5,6\n", &template).is_err());
    }
}
