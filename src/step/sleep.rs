//! Resting systems (SPEC 2.6): bodies that stay slow for `sleep_after`
//! seconds stop being integrated, tested and solved, a system at a time,
//! and wake, with their whole system, when something touches them or a
//! force window on one of them opens or closes.

use super::executor::Segment;
use super::region::Region;
use super::touching::Touching;
use crate::body::{Activity, BodyId, BodyKind};
use crate::contact::island;
use nalgebra::Vector3;
use std::collections::HashMap;

/// Resting-system thresholds: a system whose bodies all stay this slow for
/// `sleep_after` seconds stops being integrated, tested and solved.
pub const SLEEP_LINEAR: f64 = 5e-3;
pub const SLEEP_ANGULAR: f64 = 5e-2;

impl Region<'_> {
    fn wake_group(&mut self, group: u32) -> Vec<usize> {
        let mut woken = Vec::new();
        for i in 0..self.bodies.len() {
            if self.bodies[i].activity == Activity::Sleeping && self.sleep_group[i] == group {
                self.bodies[i].activity = Activity::Awake;
                self.sleep_timer[i] = 0.0;
                woken.push(i);
            }
        }
        if !woken.is_empty() {
            self.counters.wakes += 1;
        }
        woken
    }

    /// Wakes resting systems touched during an impact; they join it at τ.
    pub(crate) fn wake_touched(
        &mut self,
        touching: &[Touching],
        seg: &mut [Segment],
        tau: f64,
        t0: f64,
    ) -> Vec<usize> {
        let mut woken = Vec::new();
        for t in touching.iter().filter(|t| t.touches()) {
            for id in [t.a, t.b] {
                let i = id.index();
                if self.bodies[i].activity == Activity::Sleeping {
                    let g = self.sleep_group[i];
                    woken.extend(self.wake_group(g));
                }
            }
        }
        for &i in &woken {
            seg[i].time = tau;
            let (f, t) = self.external(i, t0 + tau);
            seg[i].force = f;
            seg[i].torque = t;
        }
        woken.sort_unstable();
        woken
    }

    /// A moving body touching a resting system at the end of a step wakes it
    /// for the next step.
    pub(crate) fn wake_touched_at_end(&mut self, touching: &[Touching]) {
        let groups: Vec<u32> = touching
            .iter()
            .filter(|t| t.touches())
            .flat_map(|t| {
                let (a, b) = (t.a.index(), t.b.index());
                let mut g = Vec::new();
                if self.bodies[a].activity == Activity::Sleeping && self.moving(b) {
                    g.push(self.sleep_group[a]);
                }
                if self.bodies[b].activity == Activity::Sleeping && self.moving(a) {
                    g.push(self.sleep_group[b]);
                }
                g
            })
            .collect();
        for g in groups {
            self.wake_group(g);
        }
    }

    /// Wakes the resting systems whose force windows open or close at the
    /// step's start `t0` (within the step before it).
    pub(crate) fn wake_for_forces(&mut self, t0: f64, h: f64) {
        let groups: Vec<u32> = self
            .st
            .forces
            .iter()
            .filter(|w| {
                let changes = |x: f64| x > t0 - h && x <= t0;
                changes(w.start) || changes(w.end)
            })
            .filter_map(|w| self.ids.binary_search(&w.body.0).ok())
            .filter(|&i| self.bodies[i].activity == Activity::Sleeping)
            .map(|i| self.sleep_group[i])
            .collect();
        for g in groups {
            self.wake_group(g);
        }
    }

    /// Resting systems and falls (SPEC 2.6).
    pub(crate) fn update_rest_and_falls(&mut self, touching: &[Touching], h: f64) {
        let fall_z = self.st.settings.fall_z;
        for i in 0..self.bodies.len() {
            let b = &self.bodies[i];
            if b.is_dynamic() && b.activity == Activity::Awake && b.state.position.z < fall_z {
                self.bodies[i].activity = Activity::Fallen;
                self.counters.bodies_fallen += 1;
            }
        }
        if !self.st.step_settings.sleep_enabled {
            return;
        }
        let n = self.bodies.len();
        for i in 0..n {
            let b = &self.bodies[i];
            if b.is_dynamic() && b.activity == Activity::Awake {
                let w = b.angular_velocity(self.object(i));
                if b.state.velocity.norm() < SLEEP_LINEAR && w.norm() < SLEEP_ANGULAR {
                    self.sleep_timer[i] += h;
                } else {
                    self.sleep_timer[i] = 0.0;
                }
            }
        }
        // A system sleeps only as a whole, and never while it touches a moving driven body.
        let links: Vec<(BodyId, BodyId)> = touching
            .iter()
            .filter(|t| t.touches())
            .map(|t| (t.a, t.b))
            .collect();
        let mut sets = island::DisjointSets::new(n);
        let mut blocked = vec![false; n];
        for &(a, b) in &links {
            let (ia, ib) = (a.index(), b.index());
            let dyn_a = self.bodies[ia].is_dynamic();
            let dyn_b = self.bodies[ib].is_dynamic();
            if dyn_a && dyn_b {
                sets.union(a.0, b.0);
            }
            if matches!(self.bodies[ia].kind, BodyKind::Driven { .. }) {
                blocked[ib] = true;
            }
            if matches!(self.bodies[ib].kind, BodyKind::Driven { .. }) {
                blocked[ia] = true;
            }
        }
        let mut ready: HashMap<u32, bool> = HashMap::new();
        for (i, &held) in blocked.iter().enumerate() {
            let b = &self.bodies[i];
            if !(b.is_dynamic() && b.activity == Activity::Awake) {
                continue;
            }
            let root = sets.find(i as u32);
            let ok = self.sleep_timer[i] >= self.st.step_settings.sleep_after && !held;
            let e = ready.entry(root).or_insert(true);
            *e &= ok;
        }
        for i in 0..n {
            let b = &self.bodies[i];
            if !(b.is_dynamic() && b.activity == Activity::Awake) {
                continue;
            }
            let root = sets.find(i as u32);
            if ready.get(&root) == Some(&true) {
                let body = &mut self.bodies[i];
                body.activity = Activity::Sleeping;
                body.state.velocity = Vector3::zeros();
                body.state.angular_momentum = Vector3::zeros();
                self.sleep_group[i] = root;
            }
        }
    }
}
