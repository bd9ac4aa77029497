//! Islands and sleeping. A body resting for [`TIME_TO_SLEEP`] goes to sleep with everything it
//! touches: the *island*, the connected set of awake dynamic bodies joined by contacts with
//! points or by joints (static bodies join nothing: a pile on the ground is one island, two
//! piles are two). A sleeping island costs nothing in the solver and its bodies move to the
//! broadphase's fixed tree — the talk's "objects can move from one tree to the other".
//!
//! While asleep, a body is static to the step: its inverse mass and inertia are zero (kept
//! here and given back on waking), its velocity is zero, so every stage treats it as it treats
//! the ground with no special case. An island wakes as a whole when an awake body touches one
//! of its bodies or is joined to one, or when the user moves, drags or removes one of them.
//!
//! Islands are found afresh at the end of every step by union-find over that step's
//! contacts (Box2D v2 builds them each step too; v3 keeps them persistent, which saves the
//! rebuild at the price of splitting logic). Deterministic: the union-find links the higher
//! index under the lower and visits edges in pair-key order, so the islands and the ids they
//! get do not depend on threads.

use rayon::prelude::*;

use crate::dynamics::body::{BodyMass, BodyVelocity};
use crate::pipeline::parallel::filter_map_ordered;

/// Bodies per rayon task of [`Islands::update_timers`]; a world of at most this many bodies
/// updates them on the calling thread.
const MIN_BODIES_PER_TASK: usize = 8192;

/// A body whose fastest point moves slower than this (m/s) is resting (Box2D's 5 cm/s).
pub const SLEEP_SPEED: f32 = 0.05;

/// Resting time after which an island may sleep (s): Box2D's half second.
pub const TIME_TO_SLEEP: f32 = 0.5;

/// [`SleepState::island`] of an awake body.
pub const AWAKE: u32 = u32::MAX;

/// Per body: how long it has rested, and its sleeping island.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SleepState {
    /// Seconds the body has moved slower than [`SLEEP_SPEED`] without a break.
    pub timer: f32,
    /// The sleeping island it belongs to, or [`AWAKE`].
    pub island: u32,
}

impl Default for SleepState {
    fn default() -> Self {
        Self {
            timer: 0.0,
            island: AWAKE,
        }
    }
}

impl SleepState {
    pub fn is_asleep(&self) -> bool {
        self.island != AWAKE
    }
}

/// The sleep state of every body slot and the members of every sleeping island.
#[derive(Clone, Debug, Default)]
pub struct Islands {
    states: Vec<SleepState>,
    /// Members of each sleeping island with the masses they had awake; an empty list is a
    /// free island id.
    sleeping: Vec<Vec<(u32, BodyMass)>>,
    free_ids: Vec<u32>,
    // Scratch of [`Islands::fall_asleep`], by body: union-find parents, whether the island
    // each root stands for stays awake, the sleeping island each root's bodies go to (only
    // the rested bodies' entries are set and read); the rested bodies, and the parallel
    // filter's counts.
    parent: Vec<u32>,
    held: Vec<bool>,
    island_of_root: Vec<u32>,
    rested: Vec<u32>,
    chunk_counts: Vec<usize>,
}

impl Islands {
    /// Makes room for `count` body slots; new slots are awake with no rest time.
    pub fn resize(&mut self, count: usize) {
        self.states.resize(count, SleepState::default());
    }

    pub fn state(&self, body: u32) -> SleepState {
        self.states[body as usize]
    }

    /// Bodies asleep now.
    pub fn sleeping_count(&self) -> usize {
        self.sleeping.iter().map(Vec::len).sum()
    }

    /// Sets the rest time of `body` (s), as a dumped state had it.
    pub fn set_timer(&mut self, body: u32, timer: f32) {
        self.states[body as usize].timer = timer;
    }

    /// The body starts resting afresh (it was moved, dragged or added).
    pub fn reset_timer(&mut self, body: u32) {
        self.states[body as usize].timer = 0.0;
    }

    /// Adds `dt` to the rest time of each awake dynamic body slower than [`SLEEP_SPEED`] at
    /// every point within `bounding_radius(body)` of its centre, and resets the others.
    /// Returns whether any awake body has now rested [`TIME_TO_SLEEP`]: an island sleeps only
    /// when all its bodies have, so until one has, [`Self::fall_asleep`] would find nothing to
    /// put to sleep, and the caller can skip it (and the union-find over every body and
    /// contact: a falling scene does).
    pub fn update_timers(
        &mut self,
        velocities: &[BodyVelocity],
        masses: &[BodyMass],
        bounding_radius: impl Fn(usize) -> f32 + Sync,
        dt: f32,
    ) -> bool {
        let update = |(i, state): (usize, &mut SleepState)| {
            if state.is_asleep() || masses[i].inverse_mass == 0.0 {
                return false;
            }
            let velocity = &velocities[i];
            let linear = velocity.linear.length();
            // The angular term is ≥ 0 and rounding is monotone, so a body whose centre
            // alone moves at SLEEP_SPEED is not resting: a falling body needs no bounding
            // radius.
            let resting = linear < SLEEP_SPEED
                && linear + bounding_radius(i) * velocity.angular.length() < SLEEP_SPEED;
            state.timer = if resting { state.timer + dt } else { 0.0 };
            state.timer >= TIME_TO_SLEEP
        };
        // A small world stays on this thread: waking the pool costs more than the pass.
        if self.states.len() <= MIN_BODIES_PER_TASK {
            let mut any_rested = false;
            for body in self.states.iter_mut().enumerate() {
                // Every body's timer, not only up to the first that rested.
                any_rested |= update(body);
            }
            return any_rested;
        }
        // Body by body, on every core.
        self.states
            .par_iter_mut()
            .enumerate()
            .with_min_len(MIN_BODIES_PER_TASK)
            .map(update)
            .reduce(|| false, |a, b| a || b)
    }

    /// Whether the edge between bodies `a` and `b` can matter to [`Self::fall_asleep`]: both
    /// awake and dynamic, and at least one rested (two rested bodies join, a rested body and
    /// an unrested one hold the island awake). The other edges [`Self::fall_asleep`] skips, so
    /// a caller may filter them out first, on every core.
    pub fn may_join(&self, a: u32, b: u32, masses: &[BodyMass]) -> bool {
        let awake = |i: u32| masses[i as usize].inverse_mass > 0.0;
        let rested = |i: u32| self.states[i as usize].timer >= TIME_TO_SLEEP;
        awake(a) && awake(b) && (rested(a) || rested(b))
    }

    /// Finds the islands of the awake dynamic bodies joined by `edges` (body pairs of contacts
    /// with points and of joints; pairs with a static body are ignored) and puts to sleep each
    /// island whose bodies have all rested [`TIME_TO_SLEEP`], unless it holds `keep_awake`:
    /// their masses and velocities become zero. Appends the bodies put to sleep to `asleep`.
    ///
    /// Only the rested bodies are joined: an island sleeps when all its bodies rested, so it
    /// is a component of the rested bodies with no edge to an awake body that has not rested,
    /// and such an edge keeps the rested component awake. In a scene still settling, most
    /// edges then cost a test rather than a union.
    pub fn fall_asleep(
        &mut self,
        edges: impl Iterator<Item = (u32, u32)>,
        masses: &mut [BodyMass],
        velocities: &mut [BodyVelocity],
        keep_awake: Option<u32>,
        asleep: &mut Vec<u32>,
    ) {
        let count = self.states.len();
        let states = &self.states;
        let awake = |i: usize| masses[i].inverse_mass > 0.0;
        let rested = |i: usize| awake(i) && states[i].timer >= TIME_TO_SLEEP;
        // Only rested bodies are joined, held or put to sleep: the passes below walk them (in
        // index order), not every body, and set only their entries of the scratch.
        let rested_bodies = &mut self.rested;
        let is_rested = |i: usize| rested(i).then_some(i as u32);
        filter_map_ordered(count, is_rested, &mut self.chunk_counts, rested_bodies);
        let (parent, held) = (&mut self.parent, &mut self.held);
        parent.resize(count, 0);
        held.resize(count, false);
        self.island_of_root.resize(count, AWAKE);
        for &i in rested_bodies.iter() {
            parent[i as usize] = i;
            held[i as usize] = false;
            self.island_of_root[i as usize] = AWAKE;
        }
        // By body, then by root: whether the island stays awake.
        for (a, b) in edges {
            let (a, b) = (a as usize, b as usize);
            if !(awake(a) && awake(b)) {
                continue;
            }
            match (rested(a), rested(b)) {
                (true, true) => {
                    let (ra, rb) = (find(parent, a as u32), find(parent, b as u32));
                    // The lower index is the root: islands do not depend on edge order.
                    let (low, high) = (ra.min(rb), ra.max(rb));
                    parent[high as usize] = low;
                }
                (true, false) => held[a] = true,
                (false, true) => held[b] = true,
                (false, false) => {}
            }
        }
        if let Some(body) = keep_awake.filter(|&body| rested(body as usize)) {
            held[body as usize] = true;
        }
        for &i in rested_bodies.iter() {
            if held[i as usize] {
                let root = find(parent, i) as usize;
                held[root] = true;
            }
        }
        // Island ids in the order of their lowest body, members in index order.
        let first_new = asleep.len();
        let island_of_root = &mut self.island_of_root;
        for &i in rested_bodies.iter() {
            let root = find(parent, i) as usize;
            if held[root] {
                continue;
            }
            if island_of_root[root] == AWAKE {
                island_of_root[root] = new_island(&mut self.sleeping, &mut self.free_ids);
            }
            let island = island_of_root[root];
            self.sleeping[island as usize].push((i, masses[i as usize]));
            self.states[i as usize].island = island;
            asleep.push(i);
        }
        for &body in &asleep[first_new..] {
            masses[body as usize] = BodyMass::default();
            velocities[body as usize] = BodyVelocity::default();
        }
    }

    /// Puts `bodies` to sleep as one island (a dumped state being loaded); the bodies must be
    /// awake and dynamic.
    pub fn restore_island(
        &mut self,
        bodies: &[u32],
        masses: &mut [BodyMass],
        velocities: &mut [BodyVelocity],
    ) {
        let island = new_island(&mut self.sleeping, &mut self.free_ids);
        for &body in bodies {
            let i = body as usize;
            self.sleeping[island as usize].push((body, masses[i]));
            self.states[i].island = island;
            masses[i] = BodyMass::default();
            velocities[i] = BodyVelocity::default();
        }
    }

    /// Wakes the island of `body` if it sleeps: its bodies get their masses back (velocities
    /// stay zero) and keep their rest times. Appends the woken bodies to `woken`.
    pub fn wake(&mut self, body: u32, masses: &mut [BodyMass], woken: &mut Vec<u32>) {
        let island = self.states[body as usize].island;
        if island == AWAKE {
            return;
        }
        for (member, mass) in self.sleeping[island as usize].drain(..) {
            masses[member as usize] = mass;
            self.states[member as usize].island = AWAKE;
            woken.push(member);
        }
        self.free_ids.push(island);
    }

    /// Wakes every sleeping island.
    pub fn wake_all(&mut self, masses: &mut [BodyMass], woken: &mut Vec<u32>) {
        for island in 0..self.sleeping.len() {
            if let Some(&(body, _)) = self.sleeping[island].first() {
                self.wake(body, masses, woken);
            }
        }
    }
}

/// A free sleeping-island id: a reused one, or a new empty member list.
fn new_island(sleeping: &mut Vec<Vec<(u32, BodyMass)>>, free_ids: &mut Vec<u32>) -> u32 {
    free_ids.pop().unwrap_or_else(|| {
        sleeping.push(Vec::new());
        (sleeping.len() - 1) as u32
    })
}

/// Root of `body` in the union-find forest, halving paths on the way.
fn find(parent: &mut [u32], mut body: u32) -> u32 {
    while parent[body as usize] != body {
        let grandparent = parent[parent[body as usize] as usize];
        parent[body as usize] = grandparent;
        body = grandparent;
    }
    body
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec3;

    fn dynamic() -> BodyMass {
        BodyMass {
            inverse_inertia: Vec3::ONE,
            inverse_mass: 1.0,
        }
    }

    /// Joining only the rested bodies puts to sleep exactly the islands that a union over
    /// every awake edge finds with all their bodies rested, with the same ids, on random
    /// graphs (static bodies, the held body, bodies just short of the time to sleep).
    #[test]
    fn islands_of_rested_bodies_are_the_islands_that_rested() {
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move |n: u32| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed % n as u64) as u32
        };
        let (mut slept, mut rested_awake) = (0, 0);
        for round in 0..200 {
            let count = 1 + next(60) as usize;
            let mut masses: Vec<BodyMass> = (0..count)
                .map(|_| {
                    if next(8) == 0 {
                        BodyMass::default()
                    } else {
                        dynamic()
                    }
                })
                .collect();
            let timers: Vec<f32> = (0..count)
                .map(|_| {
                    if next(4) == 0 {
                        0.3
                    } else {
                        TIME_TO_SLEEP + 0.1
                    }
                })
                .collect();
            let edges: Vec<(u32, u32)> = (0..next(2 * count as u32 + 1))
                .map(|_| (next(count as u32), next(count as u32)))
                .collect();
            let keep_awake = (next(3) == 0).then(|| next(count as u32));
            // The oracle: every awake edge joined, an island sleeps when its least rested body
            // rested long enough and it holds no held body.
            let mut parent: Vec<u32> = (0..count as u32).collect();
            let awake = |i: u32| masses[i as usize].inverse_mass > 0.0;
            for &(a, b) in &edges {
                if awake(a) && awake(b) {
                    let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                    parent[ra.max(rb) as usize] = ra.min(rb);
                }
            }
            let mut rest = vec![f32::INFINITY; count];
            for i in 0..count as u32 {
                if awake(i) {
                    let root = find(&mut parent, i) as usize;
                    rest[root] = rest[root].min(timers[i as usize]);
                }
            }
            if let Some(body) = keep_awake {
                let root = find(&mut parent, body) as usize;
                rest[root] = 0.0;
            }
            let mut expected: Vec<(u32, u32)> = Vec::new();
            let mut roots: Vec<u32> = Vec::new();
            for i in 0..count as u32 {
                let root = find(&mut parent, i);
                if awake(i) && rest[root as usize] >= TIME_TO_SLEEP {
                    let island = roots.iter().position(|&r| r == root).unwrap_or_else(|| {
                        roots.push(root);
                        roots.len() - 1
                    });
                    expected.push((i, island as u32));
                }
            }

            let mut islands = Islands::default();
            islands.resize(count);
            for (i, &timer) in timers.iter().enumerate() {
                islands.set_timer(i as u32, timer);
            }
            let mut velocities = vec![BodyVelocity::default(); count];
            let mut asleep = Vec::new();
            // Odd rounds pass only the edges `may_join` keeps, as the step does: the same
            // islands.
            let kept: Vec<(u32, u32)> = edges
                .iter()
                .copied()
                .filter(|&(a, b)| round % 2 == 0 || islands.may_join(a, b, &masses))
                .collect();
            islands.fall_asleep(
                kept.into_iter(),
                &mut masses,
                &mut velocities,
                keep_awake,
                &mut asleep,
            );
            let found: Vec<(u32, u32)> = asleep
                .iter()
                .map(|&body| (body, islands.state(body).island))
                .collect();
            assert_eq!(
                found, expected,
                "round {round}: {count} bodies, edges {edges:?}"
            );
            slept += found.len();
            rested_awake += (0..count)
                .filter(|&i| masses[i].inverse_mass > 0.0 && timers[i] >= TIME_TO_SLEEP)
                .count();
        }
        // Both outcomes are common: rested bodies put to sleep, and rested bodies kept awake
        // by their island.
        assert!(
            slept > 500 && rested_awake > 500,
            "{slept} slept, {rested_awake} kept"
        );
    }

    #[test]
    fn touching_bodies_sleep_together_once_all_rested() {
        // Bodies 0-1-2 touch, 3 is alone, 4 is static.
        let mut masses = vec![
            dynamic(),
            dynamic(),
            dynamic(),
            dynamic(),
            BodyMass::default(),
        ];
        let mut velocities = vec![BodyVelocity::default(); 5];
        velocities[2].linear = Vec3::X; // still moving: its island stays awake
        let mut islands = Islands::default();
        islands.resize(5);
        let edges = [(1, 2), (0, 1), (3, 4)];
        let mut asleep = Vec::new();
        for _ in 0..40 {
            islands.update_timers(&velocities, &masses, |_| 1.0, 1.0 / 60.0);
            islands.fall_asleep(
                edges.iter().copied(),
                &mut masses,
                &mut velocities,
                None,
                &mut asleep,
            );
        }
        // Body 3 rested 0.5 s after 30 steps and slept alone (the static body joins nothing).
        assert_eq!(asleep, [3]);
        assert!(islands.state(3).is_asleep() && masses[3] == BodyMass::default());
        // Body 2 stops: the chain sleeps half a second later, as one island.
        velocities[2].linear = Vec3::ZERO;
        for _ in 0..31 {
            islands.update_timers(&velocities, &masses, |_| 1.0, 1.0 / 60.0);
            islands.fall_asleep(
                edges.iter().copied(),
                &mut masses,
                &mut velocities,
                None,
                &mut asleep,
            );
        }
        assert_eq!(asleep, [3, 0, 1, 2]);
        let island = islands.state(0).island;
        assert!(islands.state(1).island == island && islands.state(2).island == island);
        assert_ne!(islands.state(3).island, island);
        // Waking one wakes the island, with its masses back, and not the other island.
        let mut woken = Vec::new();
        islands.wake(2, &mut masses, &mut woken);
        assert_eq!(woken, [0, 1, 2]);
        assert!(masses[..3].iter().all(|m| *m == dynamic()));
        assert!(islands.state(3).is_asleep());
        assert_eq!(islands.sleeping_count(), 1);
    }

    #[test]
    fn update_timers_says_when_an_island_may_fall_asleep() {
        // Body 0 rests; body 1 spins in place, its centre still, so it never rests.
        let mut masses = vec![dynamic(), dynamic()];
        let mut velocities = vec![BodyVelocity::default(); 2];
        velocities[1].angular = Vec3::Y;
        let mut islands = Islands::default();
        islands.resize(2);
        let mut asleep = Vec::new();
        // Steps of 1/8 s: body 0's rest time reaches TIME_TO_SLEEP exactly, at the fourth.
        for step in 1..=4 {
            let any_rested = islands.update_timers(&velocities, &masses, |_| 1.0, 0.125);
            assert_eq!(any_rested, step == 4, "step {step}");
            islands.fall_asleep(
                std::iter::empty(),
                &mut masses,
                &mut velocities,
                None,
                &mut asleep,
            );
            assert_eq!(asleep.is_empty(), !any_rested, "step {step}");
        }
        assert_eq!(asleep, [0]);
        assert_eq!(islands.state(1).timer, 0.0);
    }

    #[test]
    fn the_dragged_body_keeps_its_island_awake() {
        let mut masses = vec![dynamic(), dynamic()];
        let mut velocities = vec![BodyVelocity::default(); 2];
        let mut islands = Islands::default();
        islands.resize(2);
        let mut asleep = Vec::new();
        for _ in 0..60 {
            islands.update_timers(&velocities, &masses, |_| 1.0, 1.0 / 60.0);
            islands.fall_asleep(
                [(0, 1)].into_iter(),
                &mut masses,
                &mut velocities,
                Some(1),
                &mut asleep,
            );
        }
        assert!(asleep.is_empty());
    }
}
