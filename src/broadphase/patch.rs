//! The incremental regime's lookup hints and list patches: data the regime keeps (see
//! `regime`) and the incremental pass (`slack`) fills and reads.

use super::gapped::Scratch;

/// Where each proxy's candidates were last found, by slot: the index in `cand` of its first
/// candidate (the first with it as the lower side) and the index in `rev` of its first
/// reverse entry. The lists move a few entries per step (the patches), so a lookup that
/// starts at its hint and gallops outward (`slack`'s search) reads a cache line or two near
/// it, where a binary search over the whole list misses the cache at most of its last steps.
/// Any value is only slower, never wrong: the hints are exact after a rebuild of their list
/// and refreshed for every proxy looked up.
#[derive(Clone, Debug, Default)]
pub(super) struct Hints {
    pub(super) cand: Vec<u32>,
    pub(super) rev: Vec<u32>,
}

impl Hints {
    pub(super) fn heap_bytes(&self) -> usize {
        (self.cand.capacity() + self.rev.capacity()) * 4
    }
}

/// Scratch of the incremental pass's candidate update (`slack`): the candidates it visits
/// and the list patches it collects. Reused by every step; never shrinks.
#[derive(Clone, Debug, Default)]
pub(super) struct Patch {
    /// Indices of the candidates to visit, ascending.
    pub(super) touched: Vec<u32>,
    /// The radix sort's second buffer for `touched`, and its counters.
    pub(super) touched_tmp: Vec<u32>,
    pub(super) counts: Vec<u32>,
    /// A bit per candidate position, clear between steps: `touched` is put in order through
    /// it when it is long (see `slack::order_touched`).
    pub(super) touched_bits: Vec<u64>,
    /// Indices of the candidates dropped, ascending.
    pub(super) cand_gone: Vec<u32>,
    /// The new candidates, each with the index of the old list it goes before.
    pub(super) cand_at: Vec<u32>,
    pub(super) cand_new: Vec<u64>,
    /// The reverse entries of the dropped candidates, then their indices in `rev`.
    pub(super) rev_keys: Vec<u64>,
    pub(super) rev_gone: Vec<u32>,
    /// The reverse entries of the new candidates, with where they go.
    pub(super) rev_at: Vec<u32>,
    pub(super) rev_new: Vec<u64>,
    /// The radix sort's second buffer for `rev_keys` and `rev_new`.
    pub(super) keys_tmp: Vec<u64>,
    /// Indices of the pairs that stopped overlapping, in the old pair list, ascending.
    pub(super) pairs_gone: Vec<u32>,
    /// Where each pair that started overlapping goes in the old pair list.
    pub(super) pairs_at: Vec<u32>,
    /// The patches' scratch (see `gapped`).
    pub(super) scratch: Scratch,
}

impl Patch {
    /// Every list: the index lists and the key lists.
    fn lists(&mut self) -> ([&mut Vec<u32>; 8], [&mut Vec<u64>; 4]) {
        (
            [
                &mut self.touched,
                &mut self.touched_tmp,
                &mut self.cand_gone,
                &mut self.cand_at,
                &mut self.rev_gone,
                &mut self.rev_at,
                &mut self.pairs_gone,
                &mut self.pairs_at,
            ],
            [
                &mut self.cand_new,
                &mut self.rev_keys,
                &mut self.rev_new,
                &mut self.keys_tmp,
            ],
        )
    }

    pub(super) fn clear(&mut self) {
        let (index, keys) = self.lists();
        index.into_iter().for_each(|v| v.clear());
        keys.into_iter().for_each(|v| v.clear());
    }

    /// Grows every list ahead of its peaks (see `radix::ahead`), to at least `floor`:
    /// their lengths follow the loud proxies, the escapes and the pairs that change, which
    /// swing from step to step.
    pub(super) fn keep_headroom(&mut self, floor: usize) {
        fn grow<T>(v: &mut Vec<T>, floor: usize) {
            crate::radix::ahead(v);
            if v.capacity() < floor {
                v.reserve(floor - v.len());
            }
        }
        let (index, keys) = self.lists();
        index.into_iter().for_each(|v| grow(v, floor));
        keys.into_iter().for_each(|v| grow(v, floor));
        self.scratch.ahead();
    }

    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        (self.touched.capacity()
            + self.touched_tmp.capacity()
            + self.counts.capacity()
            + self.cand_gone.capacity()
            + self.cand_at.capacity()
            + self.rev_gone.capacity()
            + self.rev_at.capacity()
            + self.pairs_gone.capacity()
            + self.pairs_at.capacity())
            * 4
            + (self.cand_new.capacity()
                + self.rev_keys.capacity()
                + self.rev_new.capacity()
                + self.keys_tmp.capacity()
                + self.touched_bits.capacity())
                * 8
            + self.scratch.heap_bytes()
    }
}
