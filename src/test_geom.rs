//! Geometry the unit tests compute on their own, in `f64`, independent of `geom`.

use glam::Vec3;

/// The part of `t ∈ [0, max_t]` the segment `o + t·d` spends in the box `lo..=hi`, in
/// `f64`, by the test's own slab loop; `None` if it misses.
pub(crate) fn segment_in_box(
    o: Vec3,
    d: Vec3,
    max_t: f32,
    lo: Vec3,
    hi: Vec3,
) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, f64::from(max_t));
    for a in 0..3 {
        let (o, d, lo, hi) = (
            f64::from(o[a]),
            f64::from(d[a]),
            f64::from(lo[a]),
            f64::from(hi[a]),
        );
        if d == 0.0 {
            if o < lo || o > hi {
                return None;
            }
        } else {
            let (a, b) = ((lo - o) / d, (hi - o) / d);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
    }
    (t0 <= t1).then_some((t0, t1))
}
