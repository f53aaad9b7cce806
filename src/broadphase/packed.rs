//! The packed pair: two slots in one `u64`, the smaller in the high half, so that packed
//! pairs sort as their key pairs do. The passes (full and incremental), the candidates and
//! the checks all read pairs in this form; this file stands on the store alone, so that they
//! share it without importing one another.

use super::store::Store;
use crate::octree::Octree;
use crate::pair::{Pair, ProxyKey};

/// Set on a candidate whose exact boxes overlapped at the last step.
pub(super) const HIT: u64 = 1 << 63;

/// What fills the pair list's gap (see [`super::gapped::Gapped`]): never read.
pub(super) fn null_pair() -> Pair {
    Pair {
        a: ProxyKey::default(),
        b: ProxyKey::default(),
    }
}

/// The key pair of a packed slot pair (slots live, or quarantined since their removal).
#[inline]
pub(super) fn key_pair(store: &Store, p: u64) -> Pair {
    let (a, b) = unpack(p);
    Pair {
        a: store.key(a as u32),
        b: store.key(b as u32),
    }
}

/// The packed pair of two distinct slots: the smaller in the high half.
#[inline]
pub(super) fn pack(a: u32, b: u32) -> u64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    (u64::from(lo) << 32) | u64::from(hi)
}

/// The packed pair of a key pair (both keys live, or quarantined since their removal), the
/// inverse of [`key_pair`]: the key pairs are sorted as their packed pairs are. The pair is
/// canonical (`a < b`, so `a`'s slot is the smaller), which spares [`pack`]'s ordering on the
/// hot reads of the pair list.
#[inline]
pub(super) fn pack_pair(p: &Pair) -> u64 {
    let (a, b) = (crate::pair::slot(p.a), crate::pair::slot(p.b));
    debug_assert!(a < b, "a key pair is canonical");
    (u64::from(a) << 32) | u64::from(b)
}

/// The two slots of a packed pair (with or without [`HIT`]), the smaller first.
#[inline]
pub(super) fn unpack(p: u64) -> (usize, usize) {
    (((p >> 32) as u32 & !(1 << 31)) as usize, p as u32 as usize)
}

/// The second buffer of the pair sorts: while the octree holds spheres, its buffer that sits
/// idle between its passes ([`Octree::idle_buffer`]), so the pair sort and the octree's
/// walk-order sort share one (sized for the larger); else the broadphase's own, so that a
/// world of bodies leaves the octree empty.
pub(super) fn sort_scratch<'a>(octree: &'a mut Octree, own: &'a mut Vec<u64>) -> &'a mut Vec<u64> {
    if octree.is_empty() {
        own
    } else {
        octree.idle_buffer()
    }
}

/// The packed pair of slots `a` and `b` if their groups allow it; `any_groups` false says
/// no proxy has other groups than the default, and every pair is allowed untested. Every
/// pass packs the pairs it finds through this, so a filtered pair is never packed.
#[inline(always)]
pub(super) fn pack_allowed(store: &Store, any_groups: bool, a: u32, b: u32) -> Option<u64> {
    (!any_groups || store.group(a as usize).allows(store.group(b as usize))).then(|| pack(a, b))
}

/// Fills `out` with the key pairs of the packed pairs `packed` (a step's `added` or `removed`).
#[inline]
pub(super) fn keys_into(store: &Store, packed: &[u64], out: &mut Vec<Pair>) {
    out.clear();
    out.extend(packed.iter().map(|&p| key_pair(store, p)));
}

/// [`keys_into`] over rayon's current pool.
#[cfg(feature = "parallel")]
pub(super) fn keys_into_par(store: &Store, packed: &[u64], out: &mut Vec<Pair>) {
    use rayon::prelude::*;
    out.clear();
    out.par_extend(packed.par_iter().map(|&p| key_pair(store, p)));
}
