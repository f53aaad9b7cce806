//! The fat-box layer of the incremental regime: how far each proxy moves per step, the fat
//! box its structure holds while the candidates are kept (a skin of a few steps of its own
//! motion), and the marks that list the slots a step must look at.

use super::store::flag;
use super::{BodyKind, BroadPhase, Shape};
use crate::geom::SimdBox;
use crate::{Aabb, Vec3};
use glam::Vec3A;

/// A proxy's skin covers this many steps of its last measured motion.
pub(super) const LOOKAHEAD_STEPS: f32 = 3.0;
/// A proxy that leaves its fat box while moving gets one stretched along its last motion:
/// the box it would sweep over this many steps (times the jitter, see [`jitter`]) of that
/// motion, at most [`MAX_PREDICT`] of its size (half of it before the jitter). A body or
/// sphere keeps its velocity from one step to the next far more often than it turns, so the
/// next escape comes about twice as late as from a box of the same size centred where the
/// proxy is.
pub(super) const PREDICT_STEPS: f32 = 6.0;
/// Steps after entering the incremental regime in which two steps over the full pass's
/// estimate do not leave it, and one leaves at once only much further over it:
/// the entry gives every proxy a fat box at once, centred (no motion is known yet) with a
/// skin of up to `2·LOOKAHEAD_STEPS` steps of its speed, so the fast movers leave them
/// within that many steps, together, in a burst that says nothing of the steps after it; the
/// boxes they get then are swept along their motion and jittered, and their escapes spread
/// out.
pub(super) const ENTRY_BURST_STEPS: u32 = 2 * LOOKAHEAD_STEPS as u32 + 1;

/// The predicted fat box is grown on every side by this many steps of the speed, so that a
/// proxy that turns does not leave it at once.
const PREDICT_SIDE_STEPS: f32 = 1.0;
/// The longest predicted sweep, as a multiple of the box's largest extent (a teleport must
/// not leave a long box behind).
const MAX_PREDICT: f32 = 1.0;
/// The smallest skin, as a fraction of the box's largest extent: resting proxies keep a
/// box this much larger than exact, so jitter does not make them escape.
const MIN_SKIN: f32 = 1.0 / 64.0;
/// The largest skin, as a fraction of the box's largest extent: a teleport must not
/// leave a huge fat box behind.
const MAX_SKIN: f32 = 0.5;

/// The skin of a box of largest extent `size` moving `speed` metres per step.
#[inline]
fn skin_for(speed: f32, size: f32) -> f32 {
    clamp_skin(speed * LOOKAHEAD_STEPS, size)
}

/// A skin `m` for a box of largest extent `size`, kept between [`MIN_SKIN`] and
/// [`MAX_SKIN`] of that extent.
#[inline]
fn clamp_skin(m: f32, size: f32) -> f32 {
    m.min(size * MAX_SKIN).max(size * MIN_SKIN)
}

/// A factor in `[1, 2)` on the skin, hashed from the slot and the step the box is made
/// at. Proxies given fat boxes in the same step at the same speed would otherwise all leave
/// them in the same later step (a burst of queries); spread skins spread the escapes. A
/// factor fixed per slot would give each proxy a fixed period in whole steps, and the
/// proxies of equal periods would keep escaping together: hashing in the step redraws it at
/// every new fat box.
#[inline]
fn jitter(slot: u32, now: u32) -> f32 {
    let h = (slot ^ now.wrapping_mul(0x85EB_CA6B)).wrapping_mul(0x9E37_79B9) >> 8;
    1.0 + h as f32 / (1u32 << 24) as f32
}

/// The speed (metres per step, largest axis) of a box that moved from `old` to `new` since
/// step `stamp`, at step `now`.
#[cfg(feature = "parallel")]
#[inline(always)]
pub(super) fn speed(old: &SimdBox, new: &SimdBox, stamp: u32, now: u32) -> f32 {
    speed_of(displacement(old, new, stamp, now))
}

/// The speed of a motion of `d` per step: metres per step along its largest axis.
#[inline(always)]
fn speed_of(d: Vec3A) -> f32 {
    d.abs().max_element()
}

/// What the updates applied since the last step say of the movers' motion: what the pass
/// estimate reads outside the incremental regime to price that regime (see
/// [`Motion::note`]).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Motion {
    /// Movers that outgrow the smallest skin ([`outgrows_min_skin`]): in the
    /// incremental regime about one in [`PREDICT_STEPS`] of them would leave its fat box each
    /// step.
    pub(super) fast: usize,
    /// The other movers: they would stay in their fat boxes.
    pub(super) slow: usize,
    /// Over the slow movers, the sum of each one's speed as a fraction of its box's largest
    /// extent (per step): a slow mover re-tests its candidates about once in the steps it
    /// takes to drift half their least slack, so the loud movers of a step follow this sum.
    pub(super) slow_motion: f64,
    /// Over the fast movers, the sum of each one's skin as a fraction of its size
    /// (times the jitter's mean of 1.5): how much larger than exact their fat boxes would be,
    /// which makes their candidates outnumber their pairs.
    pub(super) fast_skin: f64,
}

impl Motion {
    /// Counts a mover of box extent `size` moving `speed` metres per step.
    #[inline(always)]
    pub(super) fn note(&mut self, speed: f32, size: f32) {
        if outgrows_min_skin(speed, size) {
            self.fast += 1;
            // Fast, so `size` is 0 only where the skin is too: a point grows by nothing.
            if size > 0.0 {
                self.fast_skin += f64::from(1.5 * skin_for(speed, size) / size);
            }
        } else {
            self.slow += 1;
            // Not fast, so `speed` is 0 where `size` is.
            if speed > 0.0 {
                self.slow_motion += f64::from(speed / size);
            }
        }
    }

    /// The escapes per step of one fast mover in the incremental regime: its fat box is swept
    /// over [`PREDICT_STEPS`] of its motion, times a jitter of 1.5 on average, so one that
    /// keeps its velocity escapes about once in that many steps.
    pub(super) fn escapes_per_fast() -> f64 {
        1.0 / (1.5 * f64::from(PREDICT_STEPS))
    }

    /// The motion of two sets of movers together.
    #[cfg(feature = "parallel")]
    pub(super) fn add(self, other: Motion) -> Motion {
        Motion {
            fast: self.fast + other.fast,
            slow: self.slow + other.slow,
            slow_motion: self.slow_motion + other.slow_motion,
            fast_skin: self.fast_skin + other.fast_skin,
        }
    }
}

/// How far the centre of a box that moved from `old` to `new` since step `stamp` moved per
/// step, at step `now`.
#[inline(always)]
pub(super) fn displacement(old: &SimdBox, new: &SimdBox, stamp: u32, now: u32) -> Vec3A {
    let moved = ((new.min + new.max) - (old.min + old.max)) * 0.5;
    let steps = now.wrapping_sub(stamp).max(1);
    moved / steps as f32
}

/// True if a box of largest extent `size` moving `speed` per step gets a skin above the
/// smallest: it will leave its fat box every few steps.
#[inline]
pub(super) fn outgrows_min_skin(speed: f32, size: f32) -> bool {
    speed * LOOKAHEAD_STEPS > size * MIN_SKIN
}

impl BroadPhase {
    /// Records how far slot `s` moved per step since its last update (from the exact box it
    /// was last applied at, `old`, to its new one, `exact`), for its skin and the pass
    /// estimate, and returns that motion (see [`displacement`]).
    #[inline]
    pub(super) fn note_motion(&mut self, s: usize, old: &SimdBox, exact: &SimdBox) -> Vec3A {
        let d = displacement(old, exact, self.store.stamp[s], self.now);
        let speed = speed_of(d);
        self.store.speed[s] = speed;
        self.motion.note(speed, exact.extent().max_element());
        self.store.stamp[s] = self.now;
        d
    }

    /// In the incremental regime: keeps the fat box if it still holds `exact` (true: the
    /// caller then classifies the slot quiet or loud), else gives the slot a new one stretched
    /// along its `motion` per step, which its structure holds from now on (false).
    #[inline]
    pub(super) fn refresh_fat(&mut self, slot: u32, exact: &SimdBox, motion: Vec3A) -> bool {
        let still_in = self
            .regime
            .as_ref()
            .is_some_and(|r| r.held[slot as usize].contains(exact));
        if still_in {
            self.mark(slot, flag::MOVED);
            true
        } else {
            self.hold_moving(slot, motion);
            self.mark(slot, flag::MOVED | flag::ESCAPED);
            false
        }
    }

    /// Gives `slot` a new held box (in the incremental regime a fat box around its exact
    /// box, else the exact box) and writes it to the slot's structure.
    #[inline]
    pub(super) fn hold(&mut self, slot: u32) {
        self.hold_held(slot, Vec3A::ZERO);
    }

    /// Gives `slot` a new fat box stretched along its `motion` per step (see
    /// [`BroadPhase::held_shape`]) and writes it to the slot's structure.
    #[inline]
    pub(super) fn hold_moving(&mut self, slot: u32, motion: Vec3A) {
        self.hold_held(slot, motion);
    }

    /// [`BroadPhase::hold`] and [`BroadPhase::hold_moving`]: the held shape of
    /// [`BroadPhase::held_shape`], written to the store and the slot's structure.
    #[inline]
    fn hold_held(&mut self, slot: u32, motion: Vec3A) {
        let s = slot as usize;
        let held = self.held_shape(slot, motion);
        let fat = if let Some(r) = &mut self.regime {
            r.held[s] = held.aabb;
            true
        } else {
            false
        };
        let key = self.store.key(slot);
        // The key is live: the structures hold every live proxy under its key.
        let placed = match self.store.shape[s] {
            Shape::Sphere { .. } => self.octree.update_checked(key, held.center, held.radius),
            Shape::Body { kind, .. } => {
                if kind == BodyKind::Dynamic && fat {
                    self.dynamic_escapes += 1;
                }
                self.tree_mut(kind).update_box(key, &held.aabb)
            }
        };
        debug_assert!(placed.is_ok(), "a live proxy missing from its structure");
    }

    /// Sets `bits` on a slot and lists it where a bit is new.
    #[inline]
    pub(super) fn mark(&mut self, slot: u32, bits: u8) {
        let f = &mut self.store.flags[slot as usize];
        let new = bits & !*f;
        *f |= bits;
        if new & flag::MOVED != 0 {
            self.movers.push(slot);
        }
        if new & flag::ESCAPED != 0 {
            self.escaped.push(slot);
        }
    }

    /// The box pairs are computed on: [`grown`] by `Config::margin`.
    #[inline]
    pub(super) fn exact_box(&self, shape: &Shape) -> SimdBox {
        grown(*shape, self.config.margin).aabb
    }

    /// What the structure of the applied `slot` holds outside the incremental regime: its
    /// shape [`grown`] by `Config::margin`, whose box is the exact one.
    #[inline]
    pub(super) fn exact_shape(&self, slot: u32) -> Held {
        grown(self.store.shape[slot as usize], self.config.margin)
    }

    /// What `slot`'s structure should hold: outside the incremental regime its exact box, in
    /// it one grown by a skin sized by the slot's speed. A sphere is held as a sphere of the
    /// same centre and a larger radius, whose box contains the exact one (rounding is
    /// monotone).
    ///
    /// With a `motion` per step (non-zero only for a proxy that just left its fat box) whose
    /// speed outgrows the smallest skin, the fat box is the one swept over
    /// [`PREDICT_STEPS`] of that motion instead, grown on every side by
    /// [`PREDICT_SIDE_STEPS`] of the speed; a sphere is held as the sphere around that sweep
    /// (centred half-way along it, its radius grown by half the sweep's length). Where
    /// rounding would leave the exact box outside it, the centred box is held.
    #[inline]
    pub(super) fn held_shape(&self, slot: u32, motion: Vec3A) -> Held {
        let s = slot as usize;
        let Some(r) = &self.regime else {
            return self.exact_shape(slot);
        };
        let exact = r.exact[s];
        let skin = if self.config.skin > 0.0 {
            self.config.skin
        } else {
            let resting = self.now.wrapping_sub(self.store.stamp[s]) > 1;
            let speed = if resting { 0.0 } else { self.store.speed[s] };
            let size = exact.extent().max_element();
            let j = jitter(slot, self.now);
            if motion != Vec3A::ZERO && outgrows_min_skin(speed, size) {
                let sweep = motion * PREDICT_STEPS;
                if let Some(held) = self.predicted(s, &exact, size, sweep, j, speed) {
                    return held;
                }
            }
            skin_for(speed, size) * j
        };
        // The exact shape, [`grown`] by the skin (the exact box is the one last applied).
        let exact_shape = match self.store.shape[s] {
            Shape::Sphere { center, radius } => Shape::Sphere {
                center,
                radius: grown_radius(radius, self.config.margin),
            },
            Shape::Body { kind, .. } => Shape::Body {
                aabb: exact.aabb(),
                kind,
            },
        };
        grown(exact_shape, skin)
    }

    /// [`BroadPhase::held_shape`]'s box swept along `sweep` (times `jitter`) for slot `s` of
    /// exact box `exact` (largest extent `size`) and `speed`, or `None` where it does not
    /// contain `exact` (rounding, overflow).
    #[inline]
    fn predicted(
        &self,
        s: usize,
        exact: &SimdBox,
        size: f32,
        sweep: Vec3A,
        jitter: f32,
        speed: f32,
    ) -> Option<Held> {
        // Capped before the jitter, so that capped sweeps keep spread lengths (equal ones
        // would bring their proxies back in the same later step).
        let len = sweep.length();
        let longest = size * MAX_PREDICT * 0.5;
        let sweep = if len > longest {
            sweep * (longest / len)
        } else {
            sweep
        } * jitter;
        let side = clamp_skin(speed * PREDICT_SIDE_STEPS, size);
        let held = match self.store.shape[s] {
            Shape::Sphere { center, radius } => {
                let r = grown_radius(radius, self.config.margin);
                let half = sweep * 0.5;
                grown_sphere((Vec3A::from(center) + half).into(), r, half.length() + side)
            }
            Shape::Body { .. } => {
                let swept = SimdBox {
                    min: exact.min.min(exact.min + sweep) - Vec3A::splat(side),
                    max: exact.max.max(exact.max + sweep) + Vec3A::splat(side),
                };
                Held {
                    aabb: swept,
                    radius: 0.0,
                    center: Vec3::ZERO,
                }
            }
        };
        (held.aabb.contains(exact) && held.aabb.min.is_finite() && held.aabb.max.is_finite())
            .then_some(held)
    }
}

/// What a structure holds for a proxy: its box, and for a sphere the radius that box is
/// `center ± radius` of.
#[derive(Clone, Copy, Debug)]
pub(super) struct Held {
    pub(super) aabb: SimdBox,
    pub(super) radius: f32,
    /// For a sphere, the centre the box is `center ± radius` around.
    pub(super) center: Vec3,
}

/// The grown-box rule: `shape` grown by `by`, as a structure holds it. A sphere keeps its
/// centre and grows its radius ([`grown_radius`]); a body's box grows on every side, and a face
/// that overflows stays at `±f32::MAX` (which overlaps exactly what `±∞` would). The box pairs
/// are computed on is the shape grown by `Config::margin`, a fat box that one grown again by
/// the skin.
#[inline]
pub(super) fn grown(shape: Shape, by: f32) -> Held {
    match shape {
        Shape::Sphere { center, radius } => grown_sphere(center, radius, by),
        Shape::Body { aabb, .. } if by == 0.0 => Held {
            aabb: SimdBox::new(&aabb),
            radius: 0.0,
            center: Vec3::ZERO,
        },
        Shape::Body { aabb, .. } => {
            let g = aabb.grown(by);
            let finite = Aabb {
                min: g.min.max(Vec3::splat(-f32::MAX)),
                max: g.max.min(Vec3::splat(f32::MAX)),
            };
            Held {
                aabb: SimdBox::new(&finite),
                radius: 0.0,
                center: Vec3::ZERO,
            }
        }
    }
}

/// [`grown`] for a sphere: the update path passes centre and radius as values, since a `Shape`
/// built for the call costs instructions on that path.
#[inline]
pub(super) fn grown_sphere(center: Vec3, radius: f32, by: f32) -> Held {
    let radius = grown_radius(radius, by);
    Held {
        aabb: SimdBox::from_center_radius(center, radius),
        radius,
        center,
    }
}

/// A sphere's radius grown by `by`. A sum that overflows stays at `f32::MAX`: huge finite
/// radii stay finite, and the octree places such a sphere in its root.
#[inline]
fn grown_radius(radius: f32, by: f32) -> f32 {
    (radius + by).min(f32::MAX)
}

#[cfg(test)]
mod tests {
    use crate::broadphase::{BodyKind, BroadPhase, Config, Passes};
    use crate::{Aabb, Vec3};

    /// A world of spheres stepped by the full pass keeps no exact boxes in the store (the
    /// octree's records hold them), yet measures each sphere's motion from the box it was last
    /// applied at; the first body makes the store keep exact boxes, and its motion is measured
    /// from its own.
    #[test]
    fn the_full_pass_keeps_no_exact_boxes_of_spheres_and_still_measures_motion() {
        let mut bp = BroadPhase::new(Config {
            passes: Passes::Full,
            ..Config::default()
        });
        let slot = |k| crate::pair::slot(k) as usize;
        let sphere = bp.insert_sphere(Vec3::ZERO, 0.5).unwrap();
        bp.step();
        // Steps of 0.25 and 0.5 m along x and y: exact in `f32`.
        let at = |d: f32| Vec3::new(0.25 * d, 0.0, 0.0);
        for step in 1..4 {
            bp.update_sphere(sphere, at(step as f32), 0.5).unwrap();
            bp.step();
            bp.validate();
            assert_eq!(bp.store.exact.capacity(), 0);
            assert_eq!(bp.store.speed[slot(sphere)], 0.25, "step {step}");
        }
        let body = bp
            .insert_body(
                Aabb::new(Vec3::splat(3.0), Vec3::splat(4.0)),
                BodyKind::Dynamic,
            )
            .unwrap();
        bp.update_sphere(sphere, at(4.0), 0.5).unwrap();
        bp.step();
        for step in 5..9 {
            bp.update_sphere(sphere, at(step as f32), 0.5).unwrap();
            let o = Vec3::new(3.0, 3.0 + 0.5 * (step - 4) as f32, 3.0);
            bp.update_body(body, Aabb::new(o, o + Vec3::ONE)).unwrap();
            bp.step();
            bp.validate();
            assert_eq!(bp.store.speed[slot(sphere)], 0.25, "step {step}");
            assert_eq!(bp.store.speed[slot(body)], 0.5, "step {step}");
        }
    }

    /// Entering the incremental regime fills every exact box from the shapes, also after the
    /// full pass ran between two stays in it (`validate` compares each with its shape's).
    #[test]
    fn every_entry_into_the_incremental_regime_fills_the_exact_boxes() {
        let mut bp = BroadPhase::new(Config::default());
        let keys: Vec<_> = (0..400)
            .map(|i| {
                let c = Vec3::new((i % 20) as f32, (i / 20) as f32, 0.0) * 0.9;
                bp.insert_sphere(c, 0.5).unwrap()
            })
            .collect();
        let mut entries = 0;
        let mut was_incremental = false;
        for step in 0..40u32 {
            // At rest for ten steps, then everyone far away and back for ten.
            let jump = (step / 10) % 2 == 1;
            for (i, &k) in keys.iter().enumerate() {
                let c = Vec3::new((i % 20) as f32, (i / 20) as f32, 0.0) * 0.9;
                let off = if jump {
                    Vec3::splat(if step % 2 == 0 { 50.0 } else { 0.0 })
                } else {
                    Vec3::ZERO
                };
                bp.update_sphere(k, c + off, 0.5).unwrap();
            }
            bp.step();
            bp.validate();
            entries += usize::from(bp.regime.is_some() && !was_incremental);
            was_incremental = bp.regime.is_some();
        }
        assert!(
            entries >= 2,
            "entered the incremental regime {entries} times"
        );
    }
}
