//! Serde snapshots of a [`BroadPhase`] (feature `serde`).
//!
//! A snapshot holds only what decides the broadphase's future output:
//! - the [`Config`];
//! - every slot's version, with each live slot's shape and groups, and the free and quarantined
//!   slot lists in order: together they decide the keys of later inserts (an insert takes the
//!   last free slot) and which keys are refused;
//! - the previous step's pairs, as slot pairs: they decide the next step's `added` / `removed`;
//! - the step clock.
//!
//! Everything else is derived and rebuilt on load: every live proxy is inserted into its
//! structure as if it had just been inserted, so the next step runs a full pass. Its lists
//! equal the original's, since a step's pairs depend only on the shapes, the groups and the
//! margin, and its events only on the previous step's pairs; later keys match since the slot
//! lists do. Fat boxes, candidates, speed estimates and the trees' layouts are not saved: they
//! change what a step costs, never what it returns.
//!
//! A snapshot is input. It is checked whole before anything is built, and an inconsistent one
//! is a deserialisation error that says what is wrong; one that passes the checks is a
//! broadphase whose invariants hold.

use super::store::{Kind, MAX_SLOTS, flag};
use super::{BodyKind, BroadPhase, CollisionGroups, Config, Passes, Shape};
use crate::geom::{check_aabb, check_sphere};
use crate::octree::Placement;
use crate::pair::Pair;
use crate::{Aabb, Vec3};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// The format this version writes and reads: a snapshot of any other is refused.
const FORMAT: u32 = 1;

/// A broadphase as saved.
#[derive(Serialize, Deserialize)]
#[serde(rename = "BroadPhase", deny_unknown_fields)]
struct Snapshot {
    /// [`FORMAT`].
    format: u32,
    #[serde(with = "ConfigDef")]
    config: Config,
    /// Steps taken.
    now: u32,
    /// Every slot, by index.
    slots: Vec<Slot>,
    /// Free slots in reuse order: the last is taken first.
    free: Vec<u32>,
    /// Slots freed since the last step, in order: they join `free` after the next step.
    quarantine: Vec<u32>,
    /// The previous step's pairs as `(lower slot, higher slot)`, strictly increasing.
    pairs: Vec<(u32, u32)>,
}

/// One slot. A live slot's version is odd, a free slot's even; `groups` is `None` for
/// [`CollisionGroups::ALL`].
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
enum Slot {
    /// A free slot (in the free list, in the quarantine, or retired): its version.
    Free(u32),
    Sphere {
        version: u32,
        center: [f32; 3],
        radius: f32,
        groups: Option<Groups>,
    },
    Dynamic {
        version: u32,
        min: [f32; 3],
        max: [f32; 3],
        groups: Option<Groups>,
    },
    Static {
        version: u32,
        min: [f32; 3],
        max: [f32; 3],
        groups: Option<Groups>,
    },
}

#[derive(Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Groups {
    memberships: u32,
    filter: u32,
}

#[derive(Serialize, Deserialize)]
#[serde(remote = "Config", deny_unknown_fields)]
struct ConfigDef {
    #[serde(with = "opt_aabb")]
    bounds: Option<Aabb>,
    #[serde(with = "PlacementDef")]
    octree_placement: Placement,
    margin: f32,
    rebuild_threshold: f32,
    skin: f32,
    #[serde(with = "PassesDef")]
    passes: Passes,
}

#[derive(Serialize, Deserialize)]
#[serde(remote = "Placement")]
enum PlacementDef {
    Strict,
    Loose,
}

#[derive(Serialize, Deserialize)]
#[serde(remote = "Passes")]
enum PassesDef {
    Adaptive,
    Full,
    Incremental,
}

/// An optional `Aabb` as `null` or `{ min, max }`.
mod opt_aabb {
    use crate::{Aabb, Vec3};
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Wire {
        #[serde(with = "super::vec3")]
        min: Vec3,
        #[serde(with = "super::vec3")]
        max: Vec3,
    }

    pub(super) fn serialize<S: Serializer>(
        v: &Option<Aabb>,
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        v.map(|b| Wire {
            min: b.min,
            max: b.max,
        })
        .serialize(serializer)
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Aabb>, D::Error> {
        Ok(Option::<Wire>::deserialize(d)?.map(|w| Aabb::new(w.min, w.max)))
    }
}

/// A `Vec3` as `[x, y, z]`.
mod vec3 {
    use crate::Vec3;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub(super) fn serialize<S: Serializer>(v: &Vec3, serializer: S) -> Result<S::Ok, S::Error> {
        v.to_array().serialize(serializer)
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<Vec3, D::Error> {
        <[f32; 3]>::deserialize(deserializer).map(Vec3::from_array)
    }
}

/// A slot's part in the key state, as the checks find it.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Role {
    Live,
    /// In the free list.
    Free,
    Quarantined,
    /// Free and in neither list: retired (its version space is spent), or an error.
    Unlisted,
}

/// Saves the state that decides the broadphase's future output: the config, the step clock,
/// every slot's version, the live proxies' shapes and groups, the free and quarantined slot
/// lists and the previous step's pairs (see the crate docs' "Features"). Derived state (the
/// octree, the BVHs, fat boxes, candidates) is not saved.
impl Serialize for BroadPhase {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        Snapshot::of(self).serialize(serializer)
    }
}

/// Restores a saved broadphase, which then continues bit-identically: the same later
/// operations give the same keys and the same `pairs`, `added` and `removed`. The snapshot is
/// checked whole first; a damaged or inconsistent one gives an error that says what is wrong,
/// never a panic or a broadphase whose invariants fail.
impl<'de> Deserialize<'de> for BroadPhase {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        Snapshot::deserialize(deserializer)?
            .restore()
            .map_err(|e| D::Error::custom(format_args!("invalid broadleaf snapshot: {e}")))
    }
}

impl Snapshot {
    fn of(bp: &BroadPhase) -> Self {
        let st = &bp.store;
        let groups = |s: usize| {
            let g = st.group(s);
            (g != CollisionGroups::ALL).then_some(Groups {
                memberships: g.memberships,
                filter: g.filter,
            })
        };
        let slots = (0..st.slots())
            .map(|s| {
                let version = st.version[s];
                if st.kind[s] == Kind::Free {
                    return Slot::Free(version);
                }
                match st.shape[s] {
                    Shape::Sphere { center, radius } => Slot::Sphere {
                        version,
                        center: center.to_array(),
                        radius,
                        groups: groups(s),
                    },
                    Shape::Body { aabb, kind } => {
                        let (min, max, groups) =
                            (aabb.min.to_array(), aabb.max.to_array(), groups(s));
                        match kind {
                            BodyKind::Dynamic => Slot::Dynamic {
                                version,
                                min,
                                max,
                                groups,
                            },
                            BodyKind::Static => Slot::Static {
                                version,
                                min,
                                max,
                                groups,
                            },
                        }
                    }
                }
            })
            .collect();
        let (free, quarantine) = st.free_lists();
        Snapshot {
            format: FORMAT,
            config: bp.config,
            now: bp.now,
            slots,
            free: free.to_vec(),
            quarantine: quarantine.to_vec(),
            pairs: bp
                .pairs
                .iter()
                .map(|p| (crate::pair::slot(p.a), crate::pair::slot(p.b)))
                .collect(),
        }
    }

    /// Checks the snapshot whole, then builds the broadphase it describes.
    fn restore(self) -> Result<BroadPhase, String> {
        let roles = self.check()?;
        let mut bp = BroadPhase::try_new(self.config).map_err(|e| format!("config: {e}"))?;
        bp.now = self.now;
        let n = self.slots.len();
        let st = &mut bp.store;
        st.version.reserve_exact(n);
        st.kind.reserve_exact(n);
        st.flags.reserve_exact(n);
        st.shape.reserve_exact(n);
        st.speed.reserve_exact(n);
        st.stamp.reserve_exact(n);
        let mut live = 0;
        // The slots with groups other than `ALL`, set once every slot is in.
        let mut grouped = Vec::new();
        for (s, slot) in self.slots.iter().enumerate() {
            let (version, kind, shape, groups) = slot.parts();
            if kind != Kind::Free {
                live += 1;
            }
            if groups != CollisionGroups::ALL {
                bp.any_groups = true;
                grouped.push((s, groups));
            }
            let st = &mut bp.store;
            st.version.push(version);
            st.kind.push(kind);
            st.flags
                .push(if kind == Kind::Free { flag::GONE } else { 0 });
            st.shape.push(shape);
            st.speed.push(0.0);
            st.stamp.push(self.now);
        }
        for (s, groups) in grouped {
            bp.store.set_group(s, groups);
        }
        bp.removals = self.quarantine.len();
        bp.store.set_free_lists(self.free, self.quarantine, live);
        // Every live proxy enters its structure as `BroadPhase::insert` puts a new one there
        // (a new broadphase is outside the incremental regime: under its key, with its exact
        // box).
        for (s, role) in roles.iter().enumerate() {
            if *role == Role::Live {
                bp.place(s as u32);
            }
        }
        let st = &bp.store;
        let pairs = &self.pairs;
        bp.pairs
            .refill(pairs.len(), super::packed::null_pair(), |list| {
                list.extend(pairs.iter().map(|&(lo, hi)| Pair {
                    a: st.key(lo),
                    b: st.key(hi),
                }));
            });
        Ok(bp)
    }

    /// Every rule of the key state and the pair list, and each slot's part in the key state;
    /// the config is checked by `BroadPhase::try_new`.
    fn check(&self) -> Result<Vec<Role>, String> {
        if self.format != FORMAT {
            return Err(format!(
                "format {} (this version of broadleaf reads format {FORMAT})",
                self.format
            ));
        }
        self.config.validate().map_err(|e| format!("config: {e}"))?;
        let n = self.slots.len();
        if n > MAX_SLOTS as usize {
            return Err(format!(
                "{n} slots, more than the {MAX_SLOTS} a broadphase holds"
            ));
        }
        let mut roles = self.slot_roles()?;
        self.list_roles(&mut roles)?;
        self.check_pairs(&roles)?;
        Ok(roles)
    }

    /// Each slot's part as the slots say (live, or free and not listed yet), every live slot's
    /// version and shape checked.
    fn slot_roles(&self) -> Result<Vec<Role>, String> {
        let n = self.slots.len();
        let mut roles = Vec::with_capacity(n);
        for (s, slot) in self.slots.iter().enumerate() {
            let (version, shape) = match *slot {
                Slot::Free(version) => {
                    if version & 1 == 1 {
                        return Err(format!(
                            "slot {s} is free but its version {version} is odd (live)"
                        ));
                    }
                    roles.push(Role::Unlisted);
                    continue;
                }
                Slot::Sphere {
                    version,
                    center,
                    radius,
                    ..
                } => (version, check_sphere(Vec3::from_array(center), radius)),
                Slot::Dynamic {
                    version, min, max, ..
                }
                | Slot::Static {
                    version, min, max, ..
                } => (version, check_aabb(&aabb(min, max))),
            };
            // A slot is reused only while its version is below `u32::MAX - 2`, so a live
            // version is odd and at most `u32::MAX - 2`.
            if version & 1 == 0 || version > u32::MAX - 2 {
                return Err(format!(
                    "slot {s} is live but its version {version} is not an odd number below {}",
                    u32::MAX - 1
                ));
            }
            shape.map_err(|e| format!("slot {s}: {e}"))?;
            roles.push(Role::Live);
        }
        Ok(roles)
    }

    /// The free list's and the quarantine's part in `roles`: each names a free slot once, with
    /// a version it may have there, and every free slot whose version is not spent is in one.
    fn list_roles(&self, roles: &mut [Role]) -> Result<(), String> {
        let n = self.slots.len();
        for (list, name, role) in [
            (&self.free, "free list", Role::Free),
            (&self.quarantine, "quarantine", Role::Quarantined),
        ] {
            for &slot in list {
                let s = slot as usize;
                let version = match self.slots.get(s) {
                    Some(Slot::Free(version)) => *version,
                    Some(_) => return Err(format!("slot {slot} is in the {name} but live")),
                    None => {
                        return Err(format!(
                            "slot {slot} is in the {name} but there are {n} slots"
                        ));
                    }
                };
                if roles[s] != Role::Unlisted {
                    return Err(format!(
                        "slot {slot} is listed twice in the free list and the quarantine"
                    ));
                }
                // `Store::release_quarantine` retires a slot whose version reached
                // `u32::MAX - 2`; one in the quarantine was live, so its version is at least 2.
                if role == Role::Free && version >= u32::MAX - 2 {
                    return Err(format!(
                        "slot {slot} is in the free list but its version {version} is spent"
                    ));
                }
                if role == Role::Quarantined && version == 0 {
                    return Err(format!(
                        "slot {slot} is quarantined but has never been live (version 0)"
                    ));
                }
                roles[s] = role;
            }
        }
        for (s, slot) in self.slots.iter().enumerate() {
            if let Slot::Free(version) = *slot
                && roles[s] == Role::Unlisted
                && version < u32::MAX - 2
            {
                return Err(format!(
                    "slot {s} is free but in neither the free list nor the quarantine"
                ));
            }
        }
        Ok(())
    }

    /// The pair list: strictly increasing pairs of two slots, each live or quarantined, not
    /// both static.
    fn check_pairs(&self, roles: &[Role]) -> Result<(), String> {
        let n = self.slots.len();
        let mut last = None;
        for &(lo, hi) in &self.pairs {
            if lo >= hi || hi as usize >= n {
                return Err(format!(
                    "pair ({lo}, {hi}) is not two slots in increasing order below {n}"
                ));
            }
            if last.is_some_and(|l| l >= (lo, hi)) {
                return Err(format!("pairs not strictly increasing at ({lo}, {hi})"));
            }
            last = Some((lo, hi));
            for s in [lo, hi] {
                if !matches!(roles[s as usize], Role::Live | Role::Quarantined) {
                    return Err(format!(
                        "pair ({lo}, {hi}) names slot {s}, which is neither live nor quarantined"
                    ));
                }
            }
            if matches!(self.slots[lo as usize], Slot::Static { .. })
                && matches!(self.slots[hi as usize], Slot::Static { .. })
            {
                return Err(format!("pair ({lo}, {hi}) is two static bodies"));
            }
        }
        Ok(())
    }
}

impl Slot {
    /// The slot's version, kind, shape (a zero sphere for a free slot) and groups
    /// ([`CollisionGroups::ALL`] where none were saved).
    fn parts(&self) -> (u32, Kind, Shape, CollisionGroups) {
        let (version, kind, shape, groups) = match *self {
            Slot::Free(version) => {
                let nothing = Shape::Sphere {
                    center: Vec3::ZERO,
                    radius: 0.0,
                };
                (version, Kind::Free, nothing, None)
            }
            Slot::Sphere {
                version,
                center,
                radius,
                groups,
            } => {
                let center = Vec3::from_array(center);
                (
                    version,
                    Kind::Sphere,
                    Shape::Sphere { center, radius },
                    groups,
                )
            }
            Slot::Dynamic {
                version,
                min,
                max,
                groups,
            } => (
                version,
                Kind::Dynamic,
                body(min, max, BodyKind::Dynamic),
                groups,
            ),
            Slot::Static {
                version,
                min,
                max,
                groups,
            } => (
                version,
                Kind::Static,
                body(min, max, BodyKind::Static),
                groups,
            ),
        };
        let groups = groups.map_or(CollisionGroups::ALL, |g| CollisionGroups {
            memberships: g.memberships,
            filter: g.filter,
        });
        (version, kind, shape, groups)
    }
}

/// The box of corners `min` and `max`.
fn aabb(min: [f32; 3], max: [f32; 3]) -> Aabb {
    Aabb {
        min: Vec3::from_array(min),
        max: Vec3::from_array(max),
    }
}

/// The shape of a body from its corners.
fn body(min: [f32; 3], max: [f32; 3], kind: BodyKind) -> Shape {
    Shape::Body {
        aabb: aabb(min, max),
        kind,
    }
}
