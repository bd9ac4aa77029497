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
//! Islands are found afresh every step by union-find over that step's contacts (Box2D v2
//! builds them each step too; v3 keeps them persistent, which saves the rebuild at the price
//! of splitting logic). They depend on the contacts and masses, not on the velocities: a step
//! whose solver runs on the device links them while the device solves, and only the rest
//! times wait for the solved velocities. Deterministic: the union-find (on every core)
//! links the higher root under the lower, so each island's root is its lowest body in any
//! order of the edges, and the ids go to the islands in the order of their lowest bodies: the
//! islands and their ids do not depend on threads.

use std::sync::atomic::{AtomicU32, Ordering};

use rayon::prelude::*;

use crate::dynamics::body::{BodyMass, BodyVelocity};
use crate::pipeline::parallel::{FilterParts, filter_map_ordered};

/// Bodies per rayon task of [`Islands::update_timers`]; a world of at most this many bodies
/// updates them on the calling thread.
const MIN_BODIES_PER_TASK: usize = 8192;

/// Edges per rayon task of [`Islands::fall_asleep`].
const MIN_EDGES_PER_TASK: usize = 8192;

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
#[derive(Debug, Default)]
pub struct Islands {
    states: Vec<SleepState>,
    /// Bit `b % 32` of word `b / 32` is set while body b sleeps: `states` as the device's
    /// wake test reads it ([`Self::asleep_bits`]).
    asleep_bits: Vec<u32>,
    /// Changes of `asleep_bits` so far: the device uploads them again only after one.
    asleep_version: u64,
    /// Members of each sleeping island with the masses they had awake; an empty list is a
    /// free island id.
    sleeping: Vec<Vec<(u32, BodyMass)>>,
    free_ids: Vec<u32>,
    // Scratch of [`Islands::fall_asleep`], by body: union-find parents (atomic: the edges are
    // joined on every core), the last call (`stamp`) in which something held the island each
    // root stands for awake, the sleeping island each root's bodies go to (set when the walk
    // reaches the root, before its other bodies); the rested bodies that fall asleep.
    parent: Vec<AtomicU32>,
    held: Vec<AtomicU32>,
    stamp: u32,
    island_of_root: Vec<u32>,
    rested: Vec<u32>,
    rested_parts: FilterParts<u32>,
    /// Whether `parent` holds this step's links ([`Islands::unlink_all`]).
    linked: bool,
    /// Changes of the timers made here ([`Self::timers_version`]).
    timers_version: u64,
    /// Whether the device moved the timers since the host last had them
    /// ([`Self::timers_on_device`]); the largest rest time of an awake body there at its
    /// last step; the bodies whose timer the host set since, which the device's do not have
    /// (sorted), and the largest rest time the host gave an awake body since (set, or woken).
    on_device: bool,
    device_max: f32,
    set_since: Vec<u32>,
    host_max: f32,
}

impl Islands {
    /// Makes room for `count` body slots; new slots are awake with no rest time.
    pub fn resize(&mut self, count: usize) {
        for body in count..self.states.len() {
            self.set_asleep_bit(body as u32, false);
        }
        let old = self.states.len();
        self.states.resize(count, SleepState::default());
        self.asleep_bits.resize(count.div_ceil(32), 0);
        self.timers_set(old as u32..count as u32, 0.0);
    }

    /// Which bodies sleep, a bit each (bit `b % 32` of word `b / 32`), and a version that
    /// changes whenever a bit does.
    pub fn asleep_bits(&self) -> (&[u32], u64) {
        (&self.asleep_bits, self.asleep_version)
    }

    fn set_asleep_bit(&mut self, body: u32, asleep: bool) {
        set_bit(&mut self.asleep_bits, body, asleep);
        self.asleep_version += 1;
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
        self.timers_set(body..body + 1, timer);
    }

    /// The body starts resting afresh (it was moved, dragged or added).
    pub fn reset_timer(&mut self, body: u32) {
        self.set_timer(body, 0.0);
    }

    /// The host set the timers of `bodies` to `timer`.
    fn timers_set(&mut self, bodies: std::ops::Range<u32>, timer: f32) {
        if bodies.is_empty() {
            return;
        }
        if self.on_device {
            // Kept sorted (bodies come in order as they are added): `holds_timer` searches it.
            for body in bodies {
                if let Err(place) = self.set_since.binary_search(&body) {
                    self.set_since.insert(place, body);
                }
            }
            self.host_max = self.host_max.max(timer);
        } else {
            self.timers_version += 1;
        }
    }

    /// A number that changes whenever the host changes a timer: the device takes the host's
    /// timers again after it does.
    pub fn timers_version(&self) -> u64 {
        self.timers_version
    }

    /// Whether the host's timers are every body's (not [`Self::timers_on_device`], or the
    /// device's were adopted since).
    pub fn holds_timers(&self) -> bool {
        !self.on_device
    }

    /// Whether the device moved the rest timers since the host last had them
    /// ([`Self::timers_moved_on_device`]): until it adopts them
    /// ([`Self::adopt_device_timers`]), the host's are stale but for the bodies it set since
    /// ([`Self::set_on_host`]).
    pub fn timers_on_device(&self) -> bool {
        self.on_device
    }

    /// Whether the host's timer of `body` is its newest: the host holds every timer, or set
    /// this one since the device moved them.
    pub fn holds_timer(&self, body: u32) -> bool {
        !self.on_device || self.set_since.binary_search(&body).is_ok()
    }

    /// Whether the host set a timer since the device moved them.
    pub fn set_on_host(&self) -> bool {
        !self.set_since.is_empty()
    }

    /// Every body's rest time, for the device (the host must hold them: [`Self::holds_timers`]).
    pub fn timers(&self) -> Vec<f32> {
        self.states.iter().map(|state| state.timer).collect()
    }

    /// A step moved the rest timers on the device, the largest of an awake body's to
    /// `max_timer`: the host's are stale from now on, until [`Self::adopt_device_timers`].
    pub fn timers_moved_on_device(&mut self, max_timer: f32) {
        debug_assert!(
            self.set_since.is_empty(),
            "timers set on the host were lost"
        );
        self.on_device = true;
        self.device_max = max_timer;
        self.host_max = 0.0;
    }

    /// The device's timers, one per body it had, become the host's, but for those the host
    /// set since they moved there (bodies added since among them). Returns false, and takes
    /// nothing, when a body has neither.
    pub fn adopt_device_timers(&mut self, timers: &[f32]) -> bool {
        let set = std::mem::take(&mut self.set_since);
        let unset = |body: usize| set.binary_search(&(body as u32)).is_err();
        if (timers.len()..self.states.len()).any(unset) {
            self.set_since = set;
            return false;
        }
        for (body, (state, &timer)) in self.states.iter_mut().zip(timers).enumerate() {
            if unset(body) {
                state.timer = timer;
            }
        }
        if !set.is_empty() {
            // The device lacks the host's: it takes them all again.
            self.timers_version += 1;
        }
        self.set_since = set;
        self.set_since.clear();
        self.on_device = false;
        true
    }

    /// Adds `dt` to the rest time of each awake dynamic body slower than [`SLEEP_SPEED`] at
    /// every point within `bounding_radius(body)` of its centre, and resets the others.
    /// Returns whether any awake body has now rested [`TIME_TO_SLEEP`]: an island sleeps only
    /// when all its bodies have, so until one has, [`Self::fall_asleep`] would find nothing to
    /// put to sleep, and the caller can skip it (and the links, when they are still to be
    /// made: a falling scene does).
    pub fn update_timers(
        &mut self,
        velocities: &[BodyVelocity],
        masses: &[BodyMass],
        bounding_radius: impl Fn(usize) -> f32 + Sync,
        dt: f32,
    ) -> bool {
        debug_assert!(!self.on_device, "the host's timers are stale");
        self.timers_version += 1;
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

    /// Starts this step's islands: every body on its own, until [`Self::link`] joins them.
    pub fn unlink_all(&mut self) {
        let parents = self.start_links().par_iter_mut().enumerate();
        parents
            .with_min_len(MIN_BODIES_PER_TASK)
            .for_each(|(i, parent)| *parent.get_mut() = i as u32);
    }

    /// The parents of this step's links, one per body, for the caller to set.
    fn start_links(&mut self) -> &mut [AtomicU32] {
        let count = self.states.len();
        if self.parent.len() < count {
            self.parent.resize_with(count, || AtomicU32::new(0));
            self.held.resize_with(count, || AtomicU32::new(0));
        }
        self.linked = true;
        &mut self.parent[..count]
    }

    /// Joins the islands of the awake dynamic bodies that `edges` connect (body pairs of
    /// contacts with points and of joints; an edge to a static or sleeping body joins
    /// nothing: a pile on the ground is one island, two piles are two), on every core. Any
    /// number of calls after [`Self::unlink_all`], before [`Self::fall_asleep`]; the masses
    /// must be those `fall_asleep` gets. The islands do not depend on the velocities: a step
    /// links its contacts while the device solves.
    pub fn link(&mut self, edges: &[(u32, u32)], masses: &[BodyMass]) {
        debug_assert!(self.linked, "link after unlink_all");
        let parent = &self.parent[..];
        let awake = |i: u32| masses[i as usize].inverse_mass > 0.0;
        edges
            .par_iter()
            .with_min_len(MIN_EDGES_PER_TASK)
            .filter(|&&(a, b)| awake(a) && awake(b))
            .for_each(|&(a, b)| join(parent, a, b));
        if edges.is_empty() {
            return;
        }
        // Every body straight under its root: `fall_asleep` then finds roots in one or two
        // loads, and the contacts' links, made while the device solves, leave it nothing else.
        (0..self.states.len() as u32)
            .into_par_iter()
            .with_min_len(MIN_BODIES_PER_TASK)
            .for_each(|body| parent[body as usize].store(root(parent, body), Ordering::Relaxed));
    }

    /// This step's islands as the device linked them
    /// ([`GpuIslandLinks`](super::island_gpu::GpuIslandLinks)): each body's root, its island's
    /// lowest body, as [`Self::unlink_all`] and [`Self::link`] of the same edges leave it. Any
    /// number of [`Self::link`]s may follow (the joints'). Returns false, and links nothing,
    /// when `roots` is not one per body.
    pub fn adopt_links(&mut self, roots: &[u32]) -> bool {
        if roots.len() != self.states.len() {
            return false;
        }
        let parents = self.start_links().par_iter_mut().zip(roots);
        parents
            .with_min_len(MIN_BODIES_PER_TASK)
            .for_each(|(parent, &root)| *parent.get_mut() = root);
        true
    }

    /// Whether an awake dynamic body may rest [`TIME_TO_SLEEP`] by the end of a step of `dt`
    /// ([`Self::update_timers`] adds at most `dt`, rounded as here): until one may, no island
    /// can fall asleep, and the step need not link its islands.
    pub fn may_rest(&self, masses: &[BodyMass], dt: f32) -> bool {
        if self.on_device {
            // An awake body's time is at most the device's largest or one the host gave
            // since, and f32 addition is monotone: the same answer as the pass below, or yes
            // where a body that rested most fell asleep or was set to 0 since.
            return self.device_max.max(self.host_max) + dt >= TIME_TO_SLEEP;
        }
        let may_rest = |(state, mass): (&SleepState, &BodyMass)| {
            !state.is_asleep() && mass.inverse_mass != 0.0 && state.timer + dt >= TIME_TO_SLEEP
        };
        let states = self.states.par_iter().zip(masses);
        states.with_min_len(MIN_BODIES_PER_TASK).any(may_rest)
    }

    /// Each body's root in the union-find forest of the last links (for the device's test).
    #[cfg(test)]
    pub(crate) fn roots(&self) -> Vec<u32> {
        let parent = &self.parent[..self.states.len()];
        (0..parent.len() as u32)
            .map(|body| root(parent, body))
            .collect()
    }

    /// Puts to sleep each island of the last [`Self::unlink_all`] and [`Self::link`]s whose
    /// bodies have all rested [`TIME_TO_SLEEP`], unless it holds `keep_awake`: their masses
    /// and velocities become zero. Appends the bodies put to sleep to `asleep`. The next
    /// step's islands start from [`Self::unlink_all`] again.
    ///
    /// Only the rested bodies can sleep, and an island holding an awake body that has not
    /// rested stays awake: a pass stamps the roots of the others with this call's number, a
    /// second lists the rested bodies whose root it did not stamp (in index order), and only
    /// those are walked. On the 20k pile of `dev-s16-host-work.txt` this took 0.17–0.20 ms a
    /// step on the development machine, against 0.30–0.32 for the five passes before it (a
    /// list of the rested bodies, their roots, the roots' flags cleared, the others' set, a
    /// check that all are held).
    pub fn fall_asleep(
        &mut self,
        masses: &mut [BodyMass],
        velocities: &mut [BodyVelocity],
        keep_awake: Option<u32>,
        asleep: &mut Vec<u32>,
    ) {
        assert!(
            self.linked,
            "fall_asleep needs this step's links (unlink_all, link)"
        );
        debug_assert!(!self.on_device, "the host's timers are stale");
        self.linked = false;
        let count = self.states.len();
        let Self {
            states,
            sleeping,
            free_ids,
            parent,
            held,
            island_of_root,
            rested: rested_bodies,
            stamp,
            rested_parts,
            asleep_bits,
            asleep_version,
            ..
        } = self;
        let awake_masses: &[BodyMass] = masses;
        let awake = |i: usize| awake_masses[i].inverse_mass > 0.0;
        let rested = |i: usize| awake(i) && states[i].timer >= TIME_TO_SLEEP;
        // An awake body that has not rested holds its island, and so does `keep_awake`: its
        // root is stamped with this call's number, so no pass clears the last call's stamps.
        *stamp = stamp.wrapping_add(1);
        if *stamp == 0 {
            held.iter_mut().for_each(|held| *held.get_mut() = 0);
            *stamp = 1;
        }
        let (parent, held, stamp) = (&parent[..], &held[..], *stamp);
        (0..count)
            .into_par_iter()
            .with_min_len(MIN_BODIES_PER_TASK)
            .filter(|&i| awake(i) && !rested(i))
            .chain(keep_awake.map(|body| body as usize))
            .for_each(|i| held[root(parent, i as u32) as usize].store(stamp, Ordering::Relaxed));
        // The rested bodies of islands nothing holds, in index order. A settled pile is mostly
        // rested bodies that something still moving holds: this is usually empty, and the walk
        // below, the one sequential pass, only runs for an island that sleeps.
        let is_held =
            |i: usize| held[root(parent, i as u32) as usize].load(Ordering::Relaxed) == stamp;
        let sleeps = |i: usize| (rested(i) && !is_held(i)).then_some(i as u32);
        filter_map_ordered(count, sleeps, rested_parts, rested_bodies);
        if rested_bodies.is_empty() {
            return;
        }
        island_of_root.resize(count, AWAKE);
        // Island ids in the order of their lowest body, members in index order. An island
        // that sleeps has every body rested, its root (its lowest body) first of them.
        let first_new = asleep.len();
        for &i in rested_bodies.iter() {
            let root = root(parent, i) as usize;
            if i as usize == root {
                island_of_root[root] = new_island(sleeping, free_ids);
            }
            let island = island_of_root[root];
            sleeping[island as usize].push((i, masses[i as usize]));
            states[i as usize].island = island;
            set_bit(asleep_bits, i, true);
            asleep.push(i);
        }
        if asleep.len() > first_new {
            *asleep_version += 1;
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
            self.set_asleep_bit(body, true);
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
            // A sleeping body's timer does not move on the device: the host's is its own.
            self.host_max = self.host_max.max(self.states[member as usize].timer);
            masses[member as usize] = mass;
            self.states[member as usize].island = AWAKE;
            set_bit(&mut self.asleep_bits, member, false);
            woken.push(member);
        }
        self.asleep_version += 1;
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

/// Sets or clears bit `body` of `bits` (see [`Islands::asleep_bits`]).
fn set_bit(bits: &mut [u32], body: u32, value: bool) {
    let (word, bit) = ((body / 32) as usize, 1 << (body % 32));
    if value {
        bits[word] |= bit;
    } else {
        bits[word] &= !bit;
    }
}

/// A free sleeping-island id: a reused one, or a new empty member list.
fn new_island(sleeping: &mut Vec<Vec<(u32, BodyMass)>>, free_ids: &mut Vec<u32>) -> u32 {
    free_ids.pop().unwrap_or_else(|| {
        sleeping.push(Vec::new());
        (sleeping.len() - 1) as u32
    })
}

/// Root of `body` in the union-find forest: the lowest body of its tree. Halves the path on
/// the way. Parents only ever move to lower bodies of the same tree (a halving, or a root
/// linked under a lower root), so a parent read while another thread changes it is still an
/// ancestor, and the walk ends at a root.
fn root(parent: &[AtomicU32], mut body: u32) -> u32 {
    loop {
        let up = parent[body as usize].load(Ordering::Relaxed);
        if up == body {
            return body;
        }
        let grandparent = parent[up as usize].load(Ordering::Relaxed);
        if grandparent != up {
            // Fails when another thread moved the parent already: either is an ancestor.
            let _ = parent[body as usize].compare_exchange(
                up,
                grandparent,
                Ordering::Relaxed,
                Ordering::Relaxed,
            );
        }
        body = grandparent;
    }
}

/// Joins the trees of `a` and `b`, the higher root linked under the lower. A root that
/// another thread linked first is no longer one: the link is retried from the new roots.
fn join(parent: &[AtomicU32], a: u32, b: u32) {
    let (mut a, mut b) = (a, b);
    loop {
        let (root_a, root_b) = (root(parent, a), root(parent, b));
        if root_a == root_b {
            return;
        }
        let (low, high) = (root_a.min(root_b), root_a.max(root_b));
        let linked =
            parent[high as usize].compare_exchange(high, low, Ordering::Relaxed, Ordering::Relaxed);
        if linked.is_ok() {
            return;
        }
        (a, b) = (root_a, root_b);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The oracle's union-find root, halving paths.
    fn find(parent: &mut [u32], mut body: u32) -> u32 {
        while parent[body as usize] != body {
            let grandparent = parent[parent[body as usize] as usize];
            parent[body as usize] = grandparent;
            body = grandparent;
        }
        body
    }
    use crate::math::Vec3;

    /// One step's islands from `edges`, then their sleep.
    fn sleep(
        islands: &mut Islands,
        edges: &[(u32, u32)],
        masses: &mut [BodyMass],
        velocities: &mut [BodyVelocity],
        keep_awake: Option<u32>,
        asleep: &mut Vec<u32>,
    ) {
        islands.unlink_all();
        islands.link(edges, masses);
        islands.fall_asleep(masses, velocities, keep_awake, asleep);
    }

    /// [`Islands::asleep_bits`] holds each body's state, and no bit past the bodies.
    fn assert_bits_follow_states(islands: &Islands) {
        let (bits, _) = islands.asleep_bits();
        assert_eq!(bits.len(), islands.states.len().div_ceil(32));
        for body in 0..bits.len() * 32 {
            let bit = bits[body / 32] & (1 << (body % 32)) != 0;
            let asleep = islands.states.get(body).is_some_and(SleepState::is_asleep);
            assert_eq!(bit, asleep, "body {body}");
        }
    }

    fn dynamic() -> BodyMass {
        BodyMass {
            inverse_inertia: Vec3::ONE,
            inverse_mass: 1.0,
        }
    }

    /// The holds stamped by one call hold nothing at the next, also across the stamp's wrap:
    /// two islands held by a body short of rest, then, all rested, both asleep.
    #[test]
    fn holds_of_an_earlier_call_hold_nothing() {
        for first_stamp in [0, u32::MAX - 1, u32::MAX] {
            let mut islands = Islands::default();
            islands.resize(4);
            islands.stamp = first_stamp;
            let mut masses = vec![dynamic(); 4];
            let mut velocities = vec![BodyVelocity::default(); 4];
            let edges = [(0, 1), (2, 3)];
            for body in 0..4 {
                let timer = if body % 2 == 1 { 0.1 } else { TIME_TO_SLEEP };
                islands.set_timer(body, timer);
            }
            let mut asleep = Vec::new();
            sleep(
                &mut islands,
                &edges,
                &mut masses,
                &mut velocities,
                None,
                &mut asleep,
            );
            assert!(asleep.is_empty(), "held: {asleep:?}");
            for body in 0..4 {
                islands.set_timer(body, TIME_TO_SLEEP);
            }
            sleep(
                &mut islands,
                &edges,
                &mut masses,
                &mut velocities,
                None,
                &mut asleep,
            );
            assert_eq!(asleep, [0, 1, 2, 3], "from stamp {first_stamp}");
            assert_ne!(islands.stamp, 0);
        }
    }

    /// The islands linked on every core put to sleep exactly the islands that a sequential
    /// union over every awake edge finds with all their bodies rested, with the same ids, on
    /// random graphs (static bodies, the held body, bodies just short of the time to sleep).
    #[test]
    fn linked_islands_sleep_when_all_their_bodies_rested() {
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move |n: u32| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed % n as u64) as u32
        };
        let (mut slept, mut rested_awake) = (0, 0);
        for round in 0..200 {
            // Every 50th graph is large, its edges joined on every core: chains of nearby
            // bodies, mostly rested, so that many islands sleep and many are held.
            let big = round % 50 == 49;
            let count = if big {
                20_000 + next(20_000) as usize
            } else {
                1 + next(60) as usize
            };
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
                    if next(if big { 64 } else { 4 }) == 0 {
                        0.3
                    } else {
                        TIME_TO_SLEEP + 0.1
                    }
                })
                .collect();
            let edges: Vec<(u32, u32)> = if big {
                (0..count as u32 * 3 / 4)
                    .map(|_| {
                        let a = next(count as u32);
                        (a, (a + 1 + next(4)).min(count as u32 - 1))
                    })
                    .collect()
            } else {
                (0..next(2 * count as u32 + 1))
                    .map(|_| (next(count as u32), next(count as u32)))
                    .collect()
            };
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
            let (mut island_of_root, mut islands_found) = (vec![AWAKE; count], 0);
            for i in 0..count as u32 {
                let root = find(&mut parent, i) as usize;
                if awake(i) && rest[root] >= TIME_TO_SLEEP {
                    if island_of_root[root] == AWAKE {
                        island_of_root[root] = islands_found;
                        islands_found += 1;
                    }
                    expected.push((i, island_of_root[root]));
                }
            }

            let mut islands = Islands::default();
            islands.resize(count);
            for (i, &timer) in timers.iter().enumerate() {
                islands.set_timer(i as u32, timer);
            }
            let mut velocities = vec![BodyVelocity::default(); count];
            let mut asleep = Vec::new();
            // Odd rounds link the edges in two calls, as the step links its contacts and then
            // its joints: the same islands.
            islands.unlink_all();
            let split = if round % 2 == 0 { 0 } else { edges.len() / 3 };
            islands.link(&edges[..split], &masses);
            islands.link(&edges[split..], &masses);
            islands.fall_asleep(&mut masses, &mut velocities, keep_awake, &mut asleep);
            assert_bits_follow_states(&islands);
            let found: Vec<(u32, u32)> = asleep
                .iter()
                .map(|&body| (body, islands.state(body).island))
                .collect();
            // (The large graphs' edges are too many to print.)
            let shown = if big { &edges[..0] } else { &edges[..] };
            assert_eq!(
                found, expected,
                "round {round}: {count} bodies, edges {shown:?}"
            );
            let kept_awake = (0..count)
                .filter(|&i| masses[i].inverse_mass > 0.0 && timers[i] >= TIME_TO_SLEEP)
                .count();
            if big {
                assert!(found.len() > 1000 && kept_awake > 1000, "round {round}");
            }
            slept += found.len();
            rested_awake += kept_awake;
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
            sleep(
                &mut islands,
                &edges,
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
            sleep(
                &mut islands,
                &edges,
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
        assert_bits_follow_states(&islands);
        // Waking one wakes the island, with its masses back, and not the other island.
        let version = islands.asleep_bits().1;
        let mut woken = Vec::new();
        islands.wake(2, &mut masses, &mut woken);
        assert_eq!(woken, [0, 1, 2]);
        assert_bits_follow_states(&islands);
        assert_ne!(islands.asleep_bits().1, version);
        assert!(masses[..3].iter().all(|m| *m == dynamic()));
        assert!(islands.state(3).is_asleep());
        assert_eq!(islands.sleeping_count(), 1);
        // Fewer slots clear the bits past them; a slot added again is awake.
        islands.resize(3);
        assert_bits_follow_states(&islands);
        islands.resize(5);
        assert_bits_follow_states(&islands);
        assert!(!islands.state(3).is_asleep());
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
            sleep(
                &mut islands,
                &[],
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
            sleep(
                &mut islands,
                &[(0, 1)],
                &mut masses,
                &mut velocities,
                Some(1),
                &mut asleep,
            );
        }
        assert!(asleep.is_empty());
    }
}
