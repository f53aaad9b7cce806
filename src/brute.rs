//! The reference every test compares against: the O(n²) all-pairs test, plus a sort-and-sweep
//! that gives the same set in O(n log n + pairs) for tests at scale. Public, so users can diff
//! their own scenes with it. It knows boxes and keys only, none of the structures it checks.

use crate::geom::{self, Aabb, SimdBox};
use crate::pair::{self, Pair, ProxyKey};
use crate::sweep::{self, Ordered};
use glam::Vec3;

/// One proxy as the reference sees it: its key, its (already grown) box, and whether it is
/// static (static×static pairs are never reported).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Proxy {
    /// The proxy's key.
    pub key: ProxyKey,
    /// The box the pair test uses.
    pub aabb: Aabb,
    /// Static proxies do not pair with each other.
    pub is_static: bool,
}

impl Proxy {
    /// A non-static proxy.
    #[must_use]
    pub fn new(key: ProxyKey, aabb: Aabb) -> Self {
        Self {
            key,
            aabb,
            is_static: false,
        }
    }
}

/// Every pair of proxies whose closed boxes overlap, except static×static: sorted by `(a, b)`,
/// each once. O(n²); the definition of the pair set.
#[must_use]
pub fn pairs(proxies: &[Proxy]) -> Vec<Pair> {
    let mut out = Vec::new();
    for (i, p) in proxies.iter().enumerate() {
        for q in &proxies[i + 1..] {
            if !(p.is_static && q.is_static) && p.aabb.overlaps(&q.aabb) {
                out.push(Pair::new(p.key, q.key));
            }
        }
    }
    pair::sort_dedup(&mut out);
    out
}

/// The same set as [`pairs`], by sort-and-sweep on x: sort by `min.x`, and test each box only
/// against the following boxes whose `min.x` does not pass its `max.x`. Exact for any input;
/// O(n log n + k) where k counts the x-overlapping candidates.
#[must_use]
pub fn sweep_pairs(proxies: &[Proxy]) -> Vec<Pair> {
    let boxes: Vec<SimdBox> = proxies.iter().map(|p| SimdBox::new(&p.aabb)).collect();
    let mut order = Vec::new();
    sweep::sort_entries(&mut order, &boxes, 0);
    let list = Ordered {
        order: &order,
        items: &boxes,
        axis: 0,
    };
    let mut out = Vec::new();
    sweep::self_pairs_of(&list, |i, j| {
        let (p, q) = (&proxies[i], &proxies[j]);
        if !(p.is_static && q.is_static) {
            out.push(Pair::new(p.key, q.key));
        }
    });
    pair::sort_dedup(&mut out);
    out
}

/// Keys of every proxy whose box overlaps `aabb`, sorted.
#[must_use]
pub fn query_aabb(proxies: &[Proxy], aabb: &Aabb) -> Vec<ProxyKey> {
    let mut out: Vec<ProxyKey> = proxies
        .iter()
        .filter(|p| p.aabb.overlaps(aabb))
        .map(|p| p.key)
        .collect();
    out.sort_unstable();
    out
}

/// The closest box hit by the segment `origin + t·dir`, `t ∈ [0, max_t]`, with its `t`; ties
/// go to the smaller key.
#[must_use]
pub fn cast_ray_boxes(
    proxies: &[Proxy],
    origin: Vec3,
    dir: Vec3,
    max_t: f32,
) -> Option<(ProxyKey, f32)> {
    let inv = geom::inverse_dir(dir);
    closest(
        proxies
            .iter()
            .filter_map(|p| p.aabb.ray_entry(origin, inv, max_t).map(|t| (p.key, t))),
    )
}

/// The closest sphere hit, for spheres given as `(key, center, radius)`; ties go to the
/// smaller key.
#[must_use]
pub fn cast_ray_spheres(
    spheres: &[(ProxyKey, Vec3, f32)],
    origin: Vec3,
    dir: Vec3,
    max_t: f32,
) -> Option<(ProxyKey, f32)> {
    closest(
        spheres
            .iter()
            .filter_map(|&(k, c, r)| geom::ray_sphere(origin, dir, c, r, max_t).map(|t| (k, t))),
    )
}

/// The hit with the least `t`; ties go to the smaller key.
pub(crate) fn closest(hits: impl Iterator<Item = (ProxyKey, f32)>) -> Option<(ProxyKey, f32)> {
    hits.min_by(|x, y| x.1.total_cmp(&y.1).then(x.0.cmp(&y.0)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use slotmap::SlotMap;

    #[test]
    fn sweep_equals_all_pairs() {
        let mut rng = Rng::new(3);
        let mut sm = SlotMap::<ProxyKey, ()>::with_key();
        for n in [0usize, 1, 2, 10, 200] {
            let proxies: Vec<Proxy> = (0..n)
                .map(|_| {
                    let c = rng.vec3_in(Vec3::splat(-5.0), Vec3::splat(5.0));
                    // Integer-ish sizes make exactly touching boxes common.
                    let h = Vec3::new(
                        rng.below(3) as f32 * 0.5,
                        rng.below(3) as f32 * 0.5,
                        rng.below(3) as f32 * 0.5,
                    );
                    Proxy {
                        key: sm.insert(()),
                        aabb: Aabb::from_center_half_extents(c.round(), h),
                        is_static: rng.below(4) == 0,
                    }
                })
                .collect();
            assert_eq!(pairs(&proxies), sweep_pairs(&proxies));
        }
    }

    #[test]
    fn static_pairs_are_excluded() {
        let mut sm = SlotMap::<ProxyKey, ()>::with_key();
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let ps = [
            Proxy {
                key: sm.insert(()),
                aabb: b,
                is_static: true,
            },
            Proxy {
                key: sm.insert(()),
                aabb: b,
                is_static: true,
            },
            Proxy::new(sm.insert(()), b),
        ];
        assert_eq!(pairs(&ps).len(), 2);
    }
}
