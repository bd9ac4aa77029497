//! An order-keeping parallel filter for the step's host passes over every pair: the rows the
//! host keeps of the pairs whose contacts stayed on the device ([`filter_map_ordered`]).

use rayon::prelude::*;

/// Indices a task takes at a time: large enough that a pass over a few thousand pairs stays
/// on one thread, small enough that a few hundred thousand spread over every core.
const CHUNK: usize = 8192;

/// `out` = the `Some` results of `f` over `0..count`, in index order, as the sequential
/// `(0..count).filter_map(f)` gives them, computed on rayon's threads: a first pass counts
/// each chunk's results, a second writes each chunk's at its offset. `chunk_counts` is
/// scratch, kept from call to call. `f` runs twice per index, so it should be cheap and pure.
pub(crate) fn filter_map_ordered<T: Copy + Default + Send>(
    count: usize,
    f: impl Fn(usize) -> Option<T> + Sync,
    chunk_counts: &mut Vec<usize>,
    out: &mut Vec<T>,
) {
    if count <= CHUNK {
        // One chunk: on this thread, without waking the pool (tens of microseconds).
        out.clear();
        out.extend((0..count).filter_map(f));
        return;
    }
    let chunks = count.div_ceil(CHUNK);
    let range = |chunk: usize| chunk * CHUNK..((chunk + 1) * CHUNK).min(count);
    chunk_counts.clear();
    chunk_counts.resize(chunks, 0);
    chunk_counts
        .par_iter_mut()
        .enumerate()
        .for_each(|(chunk, n)| *n = range(chunk).filter(|&i| f(i).is_some()).count());
    out.clear();
    out.resize(chunk_counts.iter().sum(), T::default());
    let f = &f;
    rayon::scope(|scope| {
        let mut rest = &mut out[..];
        for (chunk, &n) in chunk_counts.iter().enumerate() {
            let (head, tail) = rest.split_at_mut(n);
            rest = tail;
            scope.spawn(move |_| {
                for (slot, value) in head.iter_mut().zip(range(chunk).filter_map(f)) {
                    *slot = value;
                }
            });
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_sequential_order_at_every_size() {
        let keep = |i: usize| (i.wrapping_mul(2_654_435_761) % 7 < 3).then_some(i as u32 * 3);
        let (mut counts, mut out) = (Vec::new(), vec![99u32; 5]);
        for count in [0, 1, CHUNK - 1, CHUNK, CHUNK + 1, 5 * CHUNK + 17] {
            filter_map_ordered(count, keep, &mut counts, &mut out);
            let expected: Vec<u32> = (0..count).filter_map(keep).collect();
            assert_eq!(out, expected, "{count} indices");
        }
        // Nothing kept, everything kept.
        filter_map_ordered(3 * CHUNK, |_| None::<u32>, &mut counts, &mut out);
        assert!(out.is_empty());
        filter_map_ordered(3 * CHUNK, |i| Some(i as u32), &mut counts, &mut out);
        assert!(out.iter().enumerate().all(|(i, &v)| i as u32 == v));
    }
}
