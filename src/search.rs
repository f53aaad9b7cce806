//! What the structures' and the broadphase's searches share: the running first hit of a cast
//! and the expanding-radius k-nearest loop. Depends on `pair` only.

use crate::pair::ProxyKey;

/// The smallest `(t, key)` offered so far, within `[0, max_t]`: a cast's answer, with ties
/// going to the smaller key.
#[derive(Clone, Copy, Debug)]
pub(crate) struct FirstHit {
    max_t: f32,
    best: Option<(ProxyKey, f32)>,
}

impl FirstHit {
    pub(crate) fn new(max_t: f32) -> Self {
        FirstHit { max_t, best: None }
    }

    /// The `t` a later hit must not exceed: the best so far, else `max_t`.
    #[inline]
    pub(crate) fn limit(&self) -> f32 {
        self.best.map_or(self.max_t, |(_, t)| t)
    }

    /// Keeps `(key, t)` if it comes before the best so far; returns the new limit.
    #[inline]
    pub(crate) fn offer(&mut self, key: ProxyKey, t: Option<f32>) -> f32 {
        if let Some(t) = t
            && self.best.is_none_or(|(k, b)| (t, key) < (b, k))
        {
            self.best = Some((key, t));
        }
        self.limit()
    }

    pub(crate) fn best(&self) -> Option<(ProxyKey, f32)> {
        self.best
    }
}

/// The `k` nearest of `n` objects by an expanding search: from `radius`, each round has
/// `collect(radius, out)` push `(key, exact distance)` for every object that may be within
/// `radius` (a superset is fine; every object within it must be there) and doubles the
/// radius until `k` pushed ones are within it, all `n` were pushed, or the radius is
/// infinite. An object not pushed is farther than the radius, so the first `k` pushed in
/// `(distance, key)` order are the answer.
pub(crate) fn nearest_expanding(
    k: usize,
    n: usize,
    mut radius: f32,
    mut collect: impl FnMut(f32, &mut Vec<(ProxyKey, f32)>),
) -> Vec<(ProxyKey, f32)> {
    let mut out = Vec::new();
    loop {
        out.clear();
        collect(radius, &mut out);
        let within = out.iter().filter(|&&(_, d)| d <= radius).count();
        if within >= k || out.len() >= n || radius == f32::INFINITY {
            break;
        }
        radius = (radius * 2.0).max(f32::MIN_POSITIVE);
    }
    out.sort_unstable_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    out.truncate(k);
    out
}
