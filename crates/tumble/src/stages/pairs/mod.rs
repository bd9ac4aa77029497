//! Pair cache: the talk's "persistent pairs". Each step the broadphase hands over the sorted keys
//! of this step's pairs; the cache diffs them against last step's in one linear merge and
//! reports which pairs were added and which removed. Pairs that stay keep their value (a contact
//! manifold, say), which is what lets the solver warm start from last step's impulses.
//!
//! Invariants:
//! - A pair key packs two body indices as `(low << 32) | high` with `low < high` (see
//!   [`pair_key`]), so sorting keys sorts pairs by their first body, then their second.
//! - [`PairCache::keys`] is sorted ascending with no duplicates, and `values()[i]` belongs to
//!   `keys()[i]`.
//! - After [`PairCache::update`], [`PairCache::added`] and [`PairCache::removed`] hold exactly
//!   that update's differences, each sorted ascending; a kept pair's value is the one it had
//!   before, an added pair's is `T::default()`.
//! - Buffers are swapped, never rebuilt: once they have grown to the largest pair count seen,
//!   an update allocates nothing.

pub mod gpu;

use rayon::prelude::*;

use crate::pipeline::parallel::copy_in_parallel;

/// The key of the unordered pair {a, b}: the lower index in the high 32 bits. `a != b`.
#[inline]
pub fn pair_key(a: u32, b: u32) -> u64 {
    debug_assert_ne!(a, b, "a body does not pair with itself");
    let (low, high) = if a < b { (a, b) } else { (b, a) };
    (u64::from(low) << 32) | u64::from(high)
}

/// The two bodies of a pair key, lower index first.
#[inline]
pub fn pair_bodies(key: u64) -> (u32, u32) {
    ((key >> 32) as u32, key as u32)
}

/// Sorted pair keys with one persistent `T` per pair; see the module documentation.
#[derive(Clone, Debug, Default)]
pub struct PairCache<T> {
    keys: Vec<u64>,
    values: Vec<T>,
    /// The buffers the next update writes into, then swaps with `keys` and `values`.
    next_keys: Vec<u64>,
    next_values: Vec<T>,
    added: Vec<u64>,
    removed: Vec<u64>,
    /// How many pairs the last update added and removed: the lengths of `added` and
    /// `removed`, or what [`Self::adopt_key_count`] was told.
    changes: (usize, usize),
    /// Bumped by every method that may change keys or values, so that a copy of the cache
    /// elsewhere (the GPU step's) can tell whether it is still the same.
    version: u64,
    /// The pair count while the keys are elsewhere ([`Self::adopt_key_count`]): `keys` is then
    /// stale until [`Self::fetched_keys`].
    elsewhere: Option<usize>,
}

impl<T: Default> PairCache<T> {
    pub fn new() -> Self {
        Self::default()
    }

    /// Replaces the cached pairs with `new_keys`, which must be sorted ascending and unique (as
    /// the broadphase returns them; panics otherwise). One merge pass over the old and new
    /// keys: kept pairs move their value over, added pairs get `T::default()`, removed pairs
    /// drop theirs.
    pub fn update(&mut self, new_keys: &[u64]) {
        assert!(
            new_keys.windows(2).all(|window| window[0] < window[1]),
            "pair keys must be sorted ascending and unique"
        );
        self.assert_keys_here();
        self.version += 1;
        self.next_keys.clear();
        self.next_values.clear();
        self.added.clear();
        self.removed.clear();

        let mut old_keys = self.keys.iter().copied().peekable();
        // Draining keeps the old value buffer's capacity for the update after this one.
        let mut old_values = self.values.drain(..);
        for &key in new_keys {
            // Old keys below `key` are absent from the new set.
            while let Some(&old_key) = old_keys.peek()
                && old_key < key
            {
                self.removed.push(old_key);
                old_keys.next();
                old_values.next();
            }
            let value = if old_keys.peek() == Some(&key) {
                old_keys.next();
                old_values
                    .next()
                    .expect("the cache holds one value per key")
            } else {
                self.added.push(key);
                T::default()
            };
            self.next_keys.push(key);
            self.next_values.push(value);
        }
        self.removed.extend(old_keys);
        drop(old_values);

        std::mem::swap(&mut self.keys, &mut self.next_keys);
        std::mem::swap(&mut self.values, &mut self.next_values);
        self.changes = (self.added.len(), self.removed.len());
    }

    /// [`Self::update`] for a cache whose values live elsewhere (the GPU step's contacts): the
    /// same keys and added / removed lists, but the values are only resized to the keys, their
    /// contents unspecified until the caller writes every one. Moves no value.
    pub fn update_keys(&mut self, new_keys: &[u64]) {
        assert!(
            sorted_unique(new_keys),
            "pair keys must be sorted ascending and unique"
        );
        self.version += 1;
        if self.elsewhere.take().is_some() {
            // Last step's keys are not here to diff against: every pair counts as added.
            self.keys.clear();
        }
        diff_sorted(&self.keys, new_keys, &mut self.added, &mut self.removed);
        // Megabytes in a large pile (30 MB at 500k bodies): on every core.
        self.keys.resize(new_keys.len(), 0);
        copy_in_parallel(&mut self.keys, new_keys);
        self.values.resize_with(new_keys.len(), T::default);
        self.changes = (self.added.len(), self.removed.len());
    }

    /// [`Self::update_keys`] for keys diffed and kept elsewhere (the GPU step's device, which
    /// counts the changes, `(added, removed)`, and would copy 30 MB of keys for a pile of 500k
    /// bodies): the cache holds `len` pairs, the values resized to them, but not their keys
    /// until [`Self::fetched_keys`] hands them over. Until then [`Self::keys`] and what reads
    /// the keys panic: the caller fetches them first ([`Self::has_keys`]). [`Self::added`] and
    /// [`Self::removed`] are empty; [`Self::changes`] gives the counts. With no change the
    /// keys are the cache's, here if they were.
    pub fn adopt_key_count(&mut self, len: usize, changes: (usize, usize)) {
        self.version += 1;
        self.added.clear();
        self.removed.clear();
        self.changes = changes;
        if changes == (0, 0) && self.len() == len {
            // The same keys: those here, if they are.
            return;
        }
        self.elsewhere = Some(len);
        self.values.resize_with(len, T::default);
    }

    /// Whether the keys are here ([`Self::adopt_key_count`] leaves them elsewhere).
    pub fn has_keys(&self) -> bool {
        self.elsewhere.is_none()
    }

    /// The keys that [`Self::adopt_key_count`] left elsewhere, fetched: one per pair, sorted
    /// ascending and unique (checked in debug builds). Changes no pair, so not the version.
    pub fn fetched_keys(&mut self, keys: Vec<u64>) {
        assert_eq!(
            Some(keys.len()),
            self.elsewhere,
            "the fetched keys are the pairs' held elsewhere"
        );
        debug_assert!(
            sorted_unique(&keys),
            "pair keys must be sorted ascending and unique"
        );
        self.elsewhere = None;
        self.keys = keys;
    }

    fn assert_keys_here(&self) {
        assert!(
            self.elsewhere.is_none(),
            "the pair keys are elsewhere (adopt_key_count): fetch them first"
        );
    }

    /// This step's pair keys, sorted ascending. Panics while they are elsewhere
    /// ([`Self::adopt_key_count`]).
    pub fn keys(&self) -> &[u64] {
        self.assert_keys_here();
        &self.keys
    }

    /// One value per key, in the order of [`Self::keys`].
    pub fn values(&self) -> &[T] {
        &self.values
    }

    pub fn values_mut(&mut self) -> &mut [T] {
        self.version += 1;
        &mut self.values
    }

    /// Keys and values together, the values writable (the narrowphase reads one, writes the
    /// other).
    pub fn keys_and_values_mut(&mut self) -> (&[u64], &mut [T]) {
        self.assert_keys_here();
        self.version += 1;
        (&self.keys, &mut self.values)
    }

    /// Changes when keys or values may have changed (see the field).
    pub fn version(&self) -> u64 {
        self.version
    }

    /// Sets the value of `key`, adding the pair if it is not cached (keeps the keys sorted).
    /// For restoring saved state between steps; a step's pairs come from [`Self::update`].
    pub fn insert(&mut self, key: u64, value: T) {
        self.assert_keys_here();
        self.version += 1;
        match self.keys.binary_search(&key) {
            Ok(index) => self.values[index] = value,
            Err(index) => {
                self.keys.insert(index, key);
                self.values.insert(index, value);
            }
        }
    }

    /// Keys that the last update added, sorted ascending.
    pub fn added(&self) -> &[u64] {
        &self.added
    }

    /// Keys that the last update removed, sorted ascending.
    pub fn removed(&self) -> &[u64] {
        &self.removed
    }

    /// How many pairs the last update added and removed.
    pub fn changes(&self) -> (usize, usize) {
        self.changes
    }

    pub fn len(&self) -> usize {
        self.elsewhere.unwrap_or(self.keys.len())
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Keys a task of [`diff_sorted`] and [`sorted_unique`] takes: a few thousand pairs stay on
/// one thread, a few hundred thousand spread over every core.
const CHUNK: usize = 8192;

/// Whether `keys` ascend strictly, on every core for many keys.
fn sorted_unique(keys: &[u64]) -> bool {
    if keys.len() <= CHUNK {
        return keys.windows(2).all(|window| window[0] < window[1]);
    }
    keys.par_windows(2)
        .with_min_len(CHUNK)
        .all(|window| window[0] < window[1])
}

/// `added` = the keys of `new` not in `old`, `removed` = those of `old` not in `new`, both
/// ascending; `old` and `new` ascend strictly. For many keys, chunks of `new` are merged with
/// their stretch of `old` on every core: chunk c meets the old keys from the first one not
/// below its first key (the first chunk: from the start) to the first one not below the next
/// chunk's first key (the last chunk: to the end), so a key and its equal meet in one chunk.
fn diff_sorted(old: &[u64], new: &[u64], added: &mut Vec<u64>, removed: &mut Vec<u64>) {
    added.clear();
    removed.clear();
    if new.len() <= CHUNK {
        merge_diff(old, new, added, removed);
        return;
    }
    let chunks = new.len().div_ceil(CHUNK);
    let bound = |chunk: usize| match chunk {
        0 => 0,
        _ if chunk == chunks => old.len(),
        _ => old.partition_point(|&key| key < new[chunk * CHUNK]),
    };
    let parts: Vec<(Vec<u64>, Vec<u64>)> = (0..chunks)
        .into_par_iter()
        .map(|chunk| {
            let (mut added, mut removed) = (Vec::new(), Vec::new());
            let new = &new[chunk * CHUNK..((chunk + 1) * CHUNK).min(new.len())];
            merge_diff(
                &old[bound(chunk)..bound(chunk + 1)],
                new,
                &mut added,
                &mut removed,
            );
            (added, removed)
        })
        .collect();
    for (chunk_added, chunk_removed) in parts {
        added.extend_from_slice(&chunk_added);
        removed.extend_from_slice(&chunk_removed);
    }
}

/// [`diff_sorted`] on one thread, appending.
fn merge_diff(old: &[u64], new: &[u64], added: &mut Vec<u64>, removed: &mut Vec<u64>) {
    let mut old_keys = old.iter().copied().peekable();
    for &key in new {
        while let Some(&old_key) = old_keys.peek()
            && old_key < key
        {
            removed.push(old_key);
            old_keys.next();
        }
        if old_keys.peek() == Some(&key) {
            old_keys.next();
        } else {
            added.push(key);
        }
    }
    removed.extend(old_keys);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The diff on every core is the one-thread merge, for sets at the chunks' edges, with
    /// old keys before, between and after the new ones.
    #[test]
    fn chunked_diff_is_the_merge() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for (old_count, new_count) in [
            (0, CHUNK + 1),
            (CHUNK + 1, 0),
            (CHUNK, CHUNK),
            (3 * CHUNK + 7, 2 * CHUNK + 1),
            (50_000, 70_001),
        ] {
            // Keys from a range about twice the sets: about half of each set in the other.
            let range = 2 * (old_count + new_count) as u64 + 1;
            let mut keyset = |count: usize| {
                let mut keys: Vec<u64> = (0..count).map(|_| next() % range).collect();
                keys.sort_unstable();
                keys.dedup();
                keys
            };
            let (old, new) = (keyset(old_count), keyset(new_count));
            let (mut added, mut removed) = (Vec::new(), Vec::new());
            diff_sorted(&old, &new, &mut added, &mut removed);
            let (mut merged_added, mut merged_removed) = (Vec::new(), Vec::new());
            merge_diff(&old, &new, &mut merged_added, &mut merged_removed);
            assert_eq!(added, merged_added, "{old_count} old, {new_count} new");
            assert_eq!(removed, merged_removed, "{old_count} old, {new_count} new");
            if old.len() > CHUNK && new.len() > CHUNK {
                // Both lists non-trivial: the chunks did split a real merge.
                assert!(!added.is_empty() && !removed.is_empty());
            }
        }
    }

    #[test]
    fn insert_keeps_keys_sorted_and_update_keeps_inserted_values() {
        let mut cache = PairCache::<u32>::new();
        cache.insert(pair_key(2, 3), 23);
        cache.insert(pair_key(0, 1), 1);
        cache.insert(pair_key(2, 3), 32);
        assert_eq!(cache.keys(), [pair_key(0, 1), pair_key(2, 3)]);
        cache.update(&[pair_key(2, 3)]);
        assert_eq!(cache.values(), [32]);
    }

    /// Keys left elsewhere: the count and changes are the cache's at once, the keys once
    /// fetched; no key is read in between, and a cache diffed against keys it does not have
    /// counts every pair as added.
    #[test]
    fn keys_left_elsewhere_come_back_when_fetched() {
        let mut cache = PairCache::<u32>::new();
        cache.update(&[1, 4, 9]);
        let version = cache.version();
        cache.adopt_key_count(4, (2, 1));
        assert!(!cache.has_keys());
        assert_eq!(
            (cache.len(), cache.changes(), cache.values().len()),
            (4, (2, 1), 4)
        );
        assert!(cache.version() > version);
        let fetched = cache.version();
        cache.fetched_keys(vec![0, 4, 5, 9]);
        assert!(cache.has_keys());
        assert_eq!(cache.keys(), [0, 4, 5, 9]);
        assert_eq!(cache.version(), fetched, "fetching changes no pair");
        // No change: the keys here stay.
        cache.adopt_key_count(4, (0, 0));
        assert_eq!(cache.keys(), [0, 4, 5, 9]);
        cache.adopt_key_count(2, (0, 2));
        assert_eq!(cache.len(), 2);
        cache.update_keys(&[3, 4]);
        assert_eq!((cache.added(), cache.removed()), (&[3, 4][..], &[][..]));
        assert!(cache.has_keys());
    }

    #[test]
    #[should_panic(expected = "fetch them first")]
    fn keys_left_elsewhere_are_not_read() {
        let mut cache = PairCache::<u32>::new();
        cache.adopt_key_count(3, (3, 0));
        let _ = cache.keys();
    }

    #[test]
    #[should_panic(expected = "the fetched keys are the pairs' held elsewhere")]
    fn fetched_keys_are_one_per_pair() {
        let mut cache = PairCache::<u32>::new();
        cache.adopt_key_count(3, (3, 0));
        cache.fetched_keys(vec![1, 2]);
    }

    #[test]
    fn update_keys_gives_the_keys_and_changes_of_update() {
        let steps: [&[u64]; 4] = [&[1, 4, 9], &[0, 4, 5, 9, 12], &[], &[3, 4]];
        let (mut full, mut keys_only) = (PairCache::<u32>::new(), PairCache::<u32>::new());
        for keys in steps {
            full.update(keys);
            keys_only.update_keys(keys);
            assert_eq!(keys_only.keys(), full.keys());
            assert_eq!(keys_only.added(), full.added());
            assert_eq!(keys_only.removed(), full.removed());
            assert_eq!(keys_only.values().len(), keys.len());
        }
        let version = keys_only.version();
        keys_only.update_keys(&[3, 4]);
        assert_ne!(keys_only.version(), version);
    }

    /// Adopted counts are the cache's, with the changes it was told and its values resized,
    /// and the fetched keys are those of the diff that counted them.
    #[test]
    fn adopted_key_counts_keep_the_changes_they_are_told() {
        let steps: [&[u64]; 4] = [&[1, 4, 9], &[0, 4, 5, 9, 12], &[], &[3, 4]];
        let (mut full, mut adopted) = (PairCache::<u32>::new(), PairCache::<u32>::new());
        for keys in steps {
            full.update(keys);
            let version = adopted.version();
            adopted.adopt_key_count(keys.len(), full.changes());
            assert_eq!(adopted.changes(), full.changes());
            assert!(adopted.added().is_empty() && adopted.removed().is_empty());
            assert_eq!(adopted.values().len(), keys.len());
            assert_ne!(adopted.version(), version);
            adopted.fetched_keys(keys.to_vec());
            assert_eq!(adopted.keys(), full.keys());
        }
        assert_eq!(full.changes(), (2, 0));
    }

    /// No pair added or removed: the cache keeps its keys and values, and still moves its
    /// version.
    #[test]
    fn adopting_no_change_keeps_the_keys_and_values() {
        let mut cache = PairCache::<u32>::new();
        cache.update(&[1, 4, 9]);
        cache.values_mut().copy_from_slice(&[10, 40, 90]);
        let version = cache.version();
        cache.adopt_key_count(3, (0, 0));
        assert_eq!(
            (cache.keys(), cache.values()),
            (&[1, 4, 9][..], &[10, 40, 90][..])
        );
        assert_eq!(cache.changes(), (0, 0));
        assert_ne!(cache.version(), version);
    }

    #[test]
    fn every_change_moves_the_version_and_reads_do_not() {
        let mut cache = PairCache::<u32>::new();
        let mut seen = vec![cache.version()];
        let mut changed = |cache: &PairCache<u32>| {
            assert!(!seen.contains(&cache.version()), "{seen:?}");
            seen.push(cache.version());
        };
        cache.insert(pair_key(0, 1), 1);
        changed(&cache);
        cache.update(&[pair_key(0, 1), pair_key(1, 2)]);
        changed(&cache);
        cache.values_mut()[0] = 5;
        changed(&cache);
        cache.keys_and_values_mut().1[1] = 6;
        changed(&cache);
        let version = cache.version();
        let _ = (cache.keys(), cache.values(), cache.added(), cache.len());
        assert_eq!(cache.version(), version);
    }

    /// The talk's particles A..F as body indices 0..5.
    fn key(pair: &str) -> u64 {
        let bodies: Vec<u32> = pair
            .bytes()
            .map(|letter| u32::from(letter - b'A'))
            .collect();
        pair_key(bodies[0], bodies[1])
    }

    fn sorted_keys(pairs: &[&str]) -> Vec<u64> {
        let mut keys: Vec<u64> = pairs.iter().map(|pair| key(pair)).collect();
        keys.sort_unstable();
        keys
    }

    #[test]
    fn pair_key_orders_and_round_trips() {
        assert_eq!(pair_key(3, 9), pair_key(9, 3));
        assert_eq!(pair_key(3, 9), (3 << 32) | 9);
        assert_eq!(pair_bodies(pair_key(9, 3)), (3, 9));
        assert_eq!(pair_bodies(pair_key(u32::MAX, 0)), (0, u32::MAX));
        assert!(pair_key(1, u32::MAX) < pair_key(2, 3));
    }

    /// The "Persistent Pairs" slide: before and after columns and their differences.
    ///
    /// The slide's differences column also lists "B,C removed", but B,C is in its after
    /// column too; the set difference of the two columns has A,B as the only removal, and that
    /// is what a cache must report.
    #[test]
    fn talk_example() {
        let before = sorted_keys(&["DF", "BC", "BE", "CE", "AD", "AF", "AB", "AC", "AE"]);
        let after = sorted_keys(&["DF", "BC", "BE", "CE", "AD", "AF", "AC", "AE", "CF", "CD"]);

        let mut cache = PairCache::<u32>::new();
        cache.update(&before);
        assert_eq!(cache.added(), before);
        assert!(cache.removed().is_empty());
        // Tag every pair with a value derived from its key, to see which values survive.
        for (value, &key) in cache.values_mut().iter_mut().zip(&before) {
            *value = key as u32 + 100;
        }

        cache.update(&after);
        assert_eq!(cache.keys(), after);
        assert_eq!(cache.added(), sorted_keys(&["CF", "CD"]));
        assert_eq!(cache.removed(), sorted_keys(&["AB"]));
        for (&value, &key) in cache.values().iter().zip(cache.keys()) {
            let expected = if cache.added().contains(&key) {
                0
            } else {
                key as u32 + 100
            };
            assert_eq!(value, expected, "value of pair {:?}", pair_bodies(key));
        }

        // With B,C dropped as well, the cache reports the slide's differences column.
        let after_without_bc = sorted_keys(&["DF", "BE", "CE", "AD", "AF", "AC", "AE", "CF", "CD"]);
        cache.update(&before);
        cache.update(&after_without_bc);
        assert_eq!(cache.added(), sorted_keys(&["CF", "CD"]));
        assert_eq!(cache.removed(), sorted_keys(&["AB", "BC"]));
    }

    #[test]
    fn empty_full_empty() {
        let mut cache = PairCache::<Vec<u8>>::new();
        cache.update(&[]);
        assert!(cache.is_empty() && cache.added().is_empty() && cache.removed().is_empty());

        let full: Vec<u64> = (0..50).map(|body| pair_key(body, body + 1)).collect();
        cache.update(&full);
        assert_eq!((cache.keys(), cache.added()), (&full[..], &full[..]));
        assert!(cache.removed().is_empty());
        assert_eq!(cache.len(), 50);
        cache.values_mut()[7].push(42);

        // The same keys again: nothing added or removed, values kept.
        cache.update(&full);
        assert!(cache.added().is_empty() && cache.removed().is_empty());
        assert_eq!(cache.values()[7], [42]);

        cache.update(&[]);
        assert!(cache.is_empty() && cache.values().is_empty());
        assert_eq!(cache.removed(), full);
        assert!(cache.added().is_empty());
    }

    #[test]
    fn interleaved_changes_and_no_growth_after_warm_up() {
        // Even keys first, then every multiple of 3: adds and removes interleave in the merge.
        let evens: Vec<u64> = (0..300u32)
            .step_by(2)
            .map(|body| pair_key(body, 1000))
            .collect();
        let threes: Vec<u64> = (0..300u32)
            .step_by(3)
            .map(|body| pair_key(body, 1000))
            .collect();
        let mut cache = PairCache::<u64>::new();
        cache.update(&evens);
        for (value, &key) in cache.values_mut().iter_mut().zip(&evens) {
            *value = key;
        }
        cache.update(&threes);
        assert_eq!(cache.keys(), threes);
        let expected_added: Vec<u64> = threes
            .iter()
            .copied()
            .filter(|key| !evens.contains(key))
            .collect();
        let expected_removed: Vec<u64> = evens
            .iter()
            .copied()
            .filter(|key| !threes.contains(key))
            .collect();
        assert_eq!(cache.added(), expected_added);
        assert_eq!(cache.removed(), expected_removed);
        for (&value, &key) in cache.values().iter().zip(cache.keys()) {
            // Multiples of 6 were kept and carry their key; the others are new.
            let body = pair_bodies(key).0;
            assert_eq!(value, if body.is_multiple_of(2) { key } else { 0 });
        }

        // Both buffers have seen the largest set: later updates reuse them in place.
        cache.update(&evens);
        let capacities = |cache: &PairCache<u64>| {
            [
                cache.keys.capacity(),
                cache.values.capacity(),
                cache.next_keys.capacity(),
                cache.next_values.capacity(),
            ]
        };
        let warmed = capacities(&cache);
        for _ in 0..4 {
            cache.update(&threes);
            cache.update(&evens);
            assert_eq!(capacities(&cache), warmed);
        }
    }

    #[test]
    #[should_panic(expected = "sorted ascending and unique")]
    fn unsorted_keys_are_refused() {
        PairCache::<u32>::new().update(&[pair_key(2, 3), pair_key(0, 1)]);
    }
}
