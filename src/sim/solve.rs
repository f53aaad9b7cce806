//! The contact solver: warm-started sequential impulses with friction, rolling resistance and
//! restitution, then split-impulse position correction.

use super::World;
use crate::{Pair, Vec3};

/// "No sphere": the other side of a sphere–box contact.
pub(super) const NONE: u32 = u32::MAX;

/// One contact point between sphere `i` and sphere `j` (or a static box when `j == NONE`).
#[derive(Clone, Copy, Debug)]
pub(super) struct Contact {
    pub(super) pair: Pair,
    pub(super) i: u32,
    pub(super) j: u32,
    /// Unit normal from `j` (or the box) towards `i`.
    pub(super) normal: Vec3,
    /// Gap along the normal at the start of the step; negative when overlapping.
    pub(super) separation: f32,
    /// Radius of `i`, and of `j` (0 for a box): the lever arms of the tangent impulse.
    pub(super) radius_i: f32,
    pub(super) radius_j: f32,
    /// `1 / (1/m_i + 1/m_j)`: the normal impulse does not spin a sphere.
    pub(super) normal_mass: f32,
    /// `1 / (1/m_i + r_i²/I_i + 1/m_j + r_j²/I_j)`, the same along every tangent of a sphere.
    pub(super) tangent_mass: f32,
    /// `1 / (1/I_i + 1/I_j)`.
    pub(super) rolling_mass: f32,
    pub(super) friction: f32,
    /// `rolling_resistance · reduced radius`: the rolling impulse limit per unit normal impulse.
    pub(super) rolling_arm: f32,
    pub(super) restitution: f32,
    /// The normal relative velocity the solve aims for (see `World::prepare`).
    pub(super) target: f32,
    pub(super) normal_impulse: f32,
    pub(super) tangent_impulse: Vec3,
    pub(super) rolling_impulse: Vec3,
    pub(super) pseudo_impulse: f32,
}

impl World {
    /// The velocity of `i`'s surface point at the contact relative to `j`'s (or to the static
    /// box): `(v_i − r_i·ω_i×n) − (v_j + r_j·ω_j×n)`.
    fn contact_velocity(&self, c: &Contact) -> Vec3 {
        let (i, n) = (c.i as usize, c.normal);
        let vi = self.velocities[i] - c.radius_i * self.angular_velocities[i].cross(n);
        if c.j == NONE {
            vi
        } else {
            let j = c.j as usize;
            vi - (self.velocities[j] + c.radius_j * self.angular_velocities[j].cross(n))
        }
    }

    /// The spin of `i` relative to `j` (or to the static box).
    fn relative_spin(&self, c: &Contact) -> Vec3 {
        let wi = self.angular_velocities[c.i as usize];
        if c.j == NONE {
            wi
        } else {
            wi - self.angular_velocities[c.j as usize]
        }
    }

    /// Applies the linear impulse `p` at the contact to `i` and `−p` to `j`, with the torques
    /// of their lever arms `−r_i·n` and `+r_j·n`.
    fn apply_impulse(&mut self, c: &Contact, p: Vec3) {
        let (i, arm) = (c.i as usize, c.normal.cross(p));
        self.velocities[i] += p * self.inv_masses[i];
        self.angular_velocities[i] -= arm * (c.radius_i * self.inv_inertias[i]);
        if c.j != NONE {
            let j = c.j as usize;
            self.velocities[j] -= p * self.inv_masses[j];
            self.angular_velocities[j] -= arm * (c.radius_j * self.inv_inertias[j]);
        }
    }

    /// Applies the angular impulse `l` to `i` and `−l` to `j`.
    fn apply_spin(&mut self, c: &Contact, l: Vec3) {
        let i = c.i as usize;
        self.angular_velocities[i] += l * self.inv_inertias[i];
        if c.j != NONE {
            let j = c.j as usize;
            self.angular_velocities[j] -= l * self.inv_inertias[j];
        }
    }

    /// Sets every contact's target normal velocity from its approach speed (before any
    /// impulse), then applies the warm-start impulses.
    ///
    /// The target: an impact faster than `restitution_threshold` that closes the gap within
    /// this step separates at `e·|approach|`; otherwise a contact with gap `s > 0` may close at
    /// most `s/dt`, and a touching one must not approach.
    pub(super) fn prepare(&mut self, dt: f32) {
        let threshold = self.config.restitution_threshold;
        for k in 0..self.contacts.len() {
            let c = self.contacts[k];
            let approach = self.contact_velocity(&c).dot(c.normal);
            let hits = approach < -threshold && approach * dt <= -c.separation;
            self.contacts[k].target = if hits && c.restitution > 0.0 {
                -c.restitution * approach
            } else if c.separation > 0.0 {
                -c.separation / dt
            } else {
                0.0
            };
        }
        for k in 0..self.contacts.len() {
            let c = self.contacts[k];
            self.apply_impulse(&c, c.normal * c.normal_impulse + c.tangent_impulse);
            self.apply_spin(&c, c.rolling_impulse);
        }
    }

    /// One sequential-impulse pass: per contact, rolling resistance and friction within the
    /// limits set by the current normal impulse, then the normal impulse towards the
    /// contact's target velocity. Impulses are accumulated and clamped as totals (Catto 2005).
    pub(super) fn solve_velocities(&mut self) {
        for k in 0..self.contacts.len() {
            let mut c = self.contacts[k];

            let max_roll = c.rolling_arm * c.normal_impulse;
            let mut roll = c.rolling_impulse - self.relative_spin(&c) * c.rolling_mass;
            let len = roll.length();
            if len > max_roll {
                roll *= max_roll / len;
            }
            self.apply_spin(&c, roll - c.rolling_impulse);
            c.rolling_impulse = roll;

            let vr = self.contact_velocity(&c);
            let vt = vr - c.normal * vr.dot(c.normal);
            let max_t = c.friction * c.normal_impulse;
            let mut t = c.tangent_impulse - vt * c.tangent_mass;
            let len = t.length();
            if len > max_t {
                t *= max_t / len;
            }
            self.apply_impulse(&c, t - c.tangent_impulse);
            c.tangent_impulse = t;

            let vn = self.contact_velocity(&c).dot(c.normal);
            let n = (c.normal_impulse + c.normal_mass * (c.target - vn)).max(0.0);
            self.apply_impulse(&c, c.normal * (n - c.normal_impulse));
            c.normal_impulse = n;
            self.contacts[k] = c;
        }
    }

    /// Split impulses: pseudo-velocities that push overlapping contacts apart by
    /// `position_correction` of their overlap beyond `slop` this step, never faster than
    /// `max_correction_speed`. They move positions once and are then discarded.
    pub(super) fn solve_positions(&mut self, dt: f32) {
        self.pseudo.fill(Vec3::ZERO);
        let cfg = self.config;
        for _ in 0..cfg.position_iterations {
            for c in &mut self.contacts {
                let excess = -c.separation - cfg.slop;
                if excess <= 0.0 {
                    continue;
                }
                let target = (cfg.position_correction * excess / dt).min(cfg.max_correction_speed);
                let pi = self.pseudo[c.i as usize];
                let rel = if c.j == NONE {
                    pi
                } else {
                    pi - self.pseudo[c.j as usize]
                };
                let p = (c.pseudo_impulse + c.normal_mass * (target - rel.dot(c.normal))).max(0.0);
                let dp = c.normal * (p - c.pseudo_impulse);
                self.pseudo[c.i as usize] += dp * self.inv_masses[c.i as usize];
                if c.j != NONE {
                    self.pseudo[c.j as usize] -= dp * self.inv_masses[c.j as usize];
                }
                c.pseudo_impulse = p;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Material, WorldConfig};
    use super::*;
    use crate::Aabb;

    #[test]
    fn a_dropped_sphere_bounces_and_comes_to_rest_on_the_floor() {
        let mut world = World::new(WorldConfig::default()).unwrap();
        let floor = Aabb::new(Vec3::new(-5.0, -1.0, -5.0), Vec3::new(5.0, 0.0, 5.0));
        world.add_box(floor, Material::default()).unwrap();
        world
            .add_sphere(
                Vec3::new(0.0, 3.0, 0.0),
                Vec3::ZERO,
                0.5,
                1.0,
                Material::default(),
            )
            .unwrap();
        let mut highest_after_bounce = 0.0f32;
        let mut bounced = false;
        for _ in 0..600 {
            world.step(1.0 / 60.0).unwrap();
            let (y, vy) = (world.positions()[0].y, world.velocities()[0].y);
            assert!(y > 0.5 - 0.05, "sank into the floor: y = {y}");
            bounced |= vy > 0.5;
            if bounced {
                highest_after_bounce = highest_after_bounce.max(y);
            }
        }
        assert!(bounced, "restitution 0.3 from 3 m must bounce");
        assert!(highest_after_bounce < 3.0 * 0.3f32.powi(2) * 2.0 + 0.5);
        assert!((world.positions()[0].y - 0.5).abs() < 0.01);
        assert!(world.kinetic_energy() < 1e-6);
    }

    #[test]
    fn a_fast_sphere_does_not_tunnel_through_a_thin_wall() {
        let mut world = World::new(WorldConfig {
            gravity: Vec3::ZERO,
            ..WorldConfig::default()
        })
        .unwrap();
        let wall = Aabb::new(Vec3::new(1.0, -5.0, -5.0), Vec3::new(1.1, 5.0, 5.0));
        world.add_box(wall, Material::default()).unwrap();
        // 200 m/s at 60 Hz: 3.3 m per step, thirty times the wall's thickness.
        world
            .add_sphere(
                Vec3::ZERO,
                Vec3::new(200.0, 0.0, 0.0),
                0.1,
                1.0,
                Material::default(),
            )
            .unwrap();
        for _ in 0..30 {
            world.step(1.0 / 60.0).unwrap();
            assert!(world.positions()[0].x < 1.0, "{}", world.positions()[0].x);
        }
        assert!(world.velocities()[0].x < 0.0, "it bounced back");
    }
}
