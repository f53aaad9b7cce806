//! The query tests' own geometry, written from the definitions alone and in `f64`: distances
//! by clamping, sphere casts by searching the exact gap function. Nothing here calls the
//! crate's `geom`, so a test that compares the two compares two independent computations.
#![allow(
    dead_code,
    reason = "each test binary that includes this module uses a different part of it"
)]

use broadleaf::{Aabb, Vec3};

/// A point in `f64`.
pub type P = [f64; 3];

pub fn p(v: Vec3) -> P {
    [f64::from(v.x), f64::from(v.y), f64::from(v.z)]
}

fn norm(v: P) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn at(o: P, d: P, t: f64) -> P {
    [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]]
}

/// The distance from `q` to the closed box: `q` minus its clamp to the box.
pub fn box_distance(q: P, b: &Aabb) -> f64 {
    let (lo, hi) = (p(b.min), p(b.max));
    norm([0, 1, 2].map(|a| q[a] - q[a].clamp(lo[a], hi[a])))
}

/// The distance from `q` to the solid sphere: `max(|q − c| − r, 0)`.
pub fn sphere_distance(q: P, c: Vec3, r: f32) -> f64 {
    let c = p(c);
    (norm([q[0] - c[0], q[1] - c[1], q[2] - c[2]]) - f64::from(r)).max(0.0)
}

/// A shape a sphere is cast against.
#[derive(Clone, Copy, Debug)]
pub enum Target {
    Sphere(Vec3, f32),
    Box(Aabb),
}

impl Target {
    /// The distance from `q` to the shape.
    pub fn distance(&self, q: P) -> f64 {
        match *self {
            Target::Sphere(c, r) => sphere_distance(q, c, r),
            Target::Box(ref b) => box_distance(q, b),
        }
    }

    /// A centre and a radius whose ball holds the shape.
    fn ball(&self) -> (P, f64) {
        match *self {
            Target::Sphere(c, r) => (p(c), f64::from(r)),
            Target::Box(b) => {
                let (lo, hi) = (p(b.min), p(b.max));
                let c = [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a]));
                (c, norm([0, 1, 2].map(|a| 0.5 * (hi[a] - lo[a]))))
            }
        }
    }
}

/// A sphere cast: centre `o`, radius `r`, moving along `d` for `t ∈ [0, max_t]`.
#[derive(Clone, Copy, Debug)]
pub struct Cast {
    pub o: Vec3,
    pub r: f32,
    pub d: Vec3,
    pub max_t: f32,
}

impl Cast {
    /// How far the moving sphere is from `target` at `t` (negative inside): the centre's
    /// distance to the shape minus the radius. Convex in `t`, as the distance to a convex set
    /// is convex and the centre moves along a line.
    pub fn gap(&self, target: &Target, t: f64) -> f64 {
        target.distance(at(p(self.o), p(self.d), t)) - f64::from(self.r)
    }

    /// The first `t ∈ [0, max_t]` with `gap(t) <= level`. The gap is convex: if it is not
    /// already `<= level` at 0, a golden-section search finds its minimum, and if that is
    /// `<= level` a bisection finds the first crossing on the decreasing stretch before it.
    pub fn first_within(&self, target: &Target, level: f64) -> Option<f64> {
        let g = |t: f64| self.gap(target, t);
        if g(0.0) <= level {
            return Some(0.0);
        }
        if !self.may_reach(target, level) {
            return None;
        }
        let (mut a, mut b) = (0.0f64, f64::from(self.max_t));
        let k = (5f64.sqrt() - 1.0) / 2.0;
        for _ in 0..160 {
            let (m1, m2) = (b - k * (b - a), a + k * (b - a));
            if g(m1) <= g(m2) {
                b = m2;
            } else {
                a = m1;
            }
        }
        let t_min = [a, b, f64::from(self.max_t)]
            .into_iter()
            .min_by(|x, y| g(*x).total_cmp(&g(*y)))?;
        if g(t_min) > level {
            return None;
        }
        let (mut lo, mut hi) = (0.0f64, t_min);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if g(mid) <= level {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        Some(hi)
    }

    /// False if the segment of centres stays farther from the shape's bounding ball than
    /// `r + level` (a cheap reject before the search).
    fn may_reach(&self, target: &Target, level: f64) -> bool {
        let (c, rad) = target.ball();
        let (o, d) = (p(self.o), p(self.d));
        let dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let m = [c[0] - o[0], c[1] - o[1], c[2] - o[2]];
        let t = if dd > 0.0 {
            ((m[0] * d[0] + m[1] * d[1] + m[2] * d[2]) / dd).clamp(0.0, f64::from(self.max_t))
        } else {
            0.0
        };
        let q = at(o, d, t);
        let closest = norm([q[0] - c[0], q[1] - c[1], q[2] - c[2]]);
        closest <= rad + f64::from(self.r) + level.max(0.0) + 1e-9 * (closest + rad)
    }
}

/// What a cast against a set of shapes must return, with tolerance `eps` on the gap: the
/// shapes touched within `eps` and those clearly entered (gap `<= −eps`) by `max_t`.
#[derive(Debug)]
pub struct CastExpect {
    /// Per shape: the first `t` with gap `<= eps`, and with gap `<= −eps`.
    pub near: Vec<Option<f64>>,
    pub deep: Vec<Option<f64>>,
}

impl CastExpect {
    pub fn new(cast: &Cast, targets: &[Target], eps: f64) -> Self {
        CastExpect {
            near: targets.iter().map(|s| cast.first_within(s, eps)).collect(),
            deep: targets.iter().map(|s| cast.first_within(s, -eps)).collect(),
        }
    }

    /// Panics unless `got` (the index of the shape hit and its `t`) is a correct answer up to
    /// the tolerance: `None` only if no shape is clearly entered; otherwise the shape touches
    /// within `eps` at `t`, no shape is touched before the earliest `near` time, none is
    /// entered before `t` (`t` is at most the earliest `deep` time, up to `t_tol`), and when
    /// one shape is clearly first (entered before any other comes near) it is that one.
    pub fn check(
        &self,
        cast: &Cast,
        targets: &[Target],
        got: Option<(usize, f32)>,
        eps: f64,
        t_tol: f64,
        what: &str,
    ) {
        let min = |v: &[Option<f64>]| v.iter().flatten().copied().reduce(f64::min);
        let (near, deep) = (min(&self.near), min(&self.deep));
        let Some((i, t)) = got else {
            assert!(
                deep.is_none(),
                "{what}: nothing hit, but a shape is entered at {deep:?}"
            );
            return;
        };
        let t = f64::from(t);
        assert!(
            (0.0..=f64::from(cast.max_t)).contains(&t),
            "{what}: t {t} outside [0, {}]",
            cast.max_t
        );
        let gap = cast.gap(&targets[i], t);
        assert!(gap <= eps, "{what}: shape {i} is {gap} away at t {t}");
        let near = near.expect("a hit shape is near");
        assert!(
            t >= near - t_tol,
            "{what}: t {t} before any shape comes near ({near})"
        );
        if let Some(deep) = deep {
            assert!(
                t <= deep + t_tol,
                "{what}: t {t} after a shape is entered at {deep}"
            );
        }
        let first = self.deep.iter().enumerate().find(|&(j, d)| {
            d.is_some_and(|d| {
                self.near
                    .iter()
                    .enumerate()
                    .all(|(k, n)| k == j || n.is_none_or(|n| n > d + t_tol))
            })
        });
        if let Some((j, _)) = first {
            assert_eq!(
                i, j,
                "{what}: hit shape {i}, but shape {j} is clearly first"
            );
        }
    }
}

/// Panics unless `got` (indices and distances, as a `nearest` query returned them) is a
/// correct `k`-nearest answer for the reference distances `refd` up to `tol`: the right
/// length, distances within `tol` of the reference, and no shape left out that is clearly
/// nearer than one taken; when the `k`-th and the next reference distance are more than
/// `2·tol` apart, exactly the reference's set.
pub fn check_nearest(refd: &[f64], k: usize, got: &[(usize, f32)], tol: f64, what: &str) {
    assert_eq!(got.len(), k.min(refd.len()), "{what}: length");
    let mut order: Vec<usize> = (0..refd.len()).collect();
    order.sort_by(|&a, &b| refd[a].total_cmp(&refd[b]));
    let taken: std::collections::BTreeSet<usize> = got.iter().map(|g| g.0).collect();
    assert_eq!(taken.len(), got.len(), "{what}: a shape returned twice");
    for &(i, d) in got {
        let diff = (f64::from(d) - refd[i]).abs();
        assert!(
            diff <= tol,
            "{what}: shape {i} at {d}, reference {}",
            refd[i]
        );
    }
    if got.is_empty() {
        return;
    }
    let kth = refd[order[got.len() - 1]];
    for (i, &d) in refd.iter().enumerate() {
        if taken.contains(&i) {
            assert!(
                d <= kth + tol,
                "{what}: shape {i} at {d} taken, the k-th is {kth}"
            );
        } else {
            assert!(
                d >= kth - tol,
                "{what}: shape {i} at {d} left out, the k-th is {kth}"
            );
        }
    }
    let next = order.get(got.len()).map_or(f64::INFINITY, |&i| refd[i]);
    if next - kth > 2.0 * tol {
        let want: std::collections::BTreeSet<usize> = order[..got.len()].iter().copied().collect();
        assert_eq!(taken, want, "{what}: not the reference's nearest set");
    }
}
