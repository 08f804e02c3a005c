//! The surface a grid draws (model §4): each cell split along its north-west to south-east
//! diagonal, evaluated exactly in `f64`. Measuring (the static error), meshing, reconstructing
//! and resampling all draw with this one formula, so they agree bit for bit.

/// The surface of one grid cell at offset `(u, v)` from its north-west corner (`u` east, `v`
/// south, both in `0..=s` samples; `s` is the cell side, a power of two).
///
/// The cell is split along its NW–SE diagonal. Where `u >= v` the point lies in the north-east
/// triangle (NW, NE, SE), otherwise in the south-west one (NW, SW, SE). The surface is the
/// barycentric combination, evaluated in `f64` in exactly this order:
///
/// ```text
///   u >= v:  s = ((s-u)/s · NW + (u-v)/s · NE) + v/s · SE
///   u <  v:  s = ((s-v)/s · NW + (v-u)/s · SW) + u/s · SE
/// ```
///
/// The weights are exact (integers over a power of two). So the surface equals a vertex's
/// height exactly at that vertex, and along a shared edge two neighbouring cells compute the
/// same value.
#[inline(always)]
pub fn surface(nw: f32, ne: f32, sw: f32, se: f32, s: u64, u: u64, v: u64) -> f64 {
    let inv = 1.0 / s as f64;
    if u >= v {
        ((s - u) as f64 * inv * f64::from(nw) + (u - v) as f64 * inv * f64::from(ne))
            + v as f64 * inv * f64::from(se)
    } else {
        ((s - v) as f64 * inv * f64::from(nw) + (v - u) as f64 * inv * f64::from(sw))
            + u as f64 * inv * f64::from(se)
    }
}
