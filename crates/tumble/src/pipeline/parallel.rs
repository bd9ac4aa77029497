//! The step's host passes over every pair or body on every core: an order-keeping filter
//! ([`filter_map_ordered`]) and a copy ([`copy_in_parallel`]).

use rayon::prelude::*;

/// Indices a task takes at a time: large enough that a pass over a few thousand pairs stays
/// on one thread, small enough that a few hundred thousand spread over every core.
const CHUNK: usize = 8192;

/// `out` = the `Some` results of `f` over `0..count`, in index order, as the sequential
/// `(0..count).filter_map(f)` gives them, computed on rayon's threads: each chunk's results
/// are gathered on its own, then copied to their place. `f` runs once per index (it is
/// usually a few loads from scattered arrays, which cost more than the copy).
pub(crate) fn filter_map_ordered<T: Copy + Default + Send + Sync>(
    count: usize,
    f: impl Fn(usize) -> Option<T> + Sync,
    out: &mut Vec<T>,
) {
    out.clear();
    if count <= CHUNK {
        // One chunk: on this thread, without waking the pool (tens of microseconds).
        out.extend((0..count).filter_map(f));
        return;
    }
    let range = |chunk: usize| chunk * CHUNK..((chunk + 1) * CHUNK).min(count);
    let parts: Vec<Vec<T>> = (0..count.div_ceil(CHUNK))
        .into_par_iter()
        .map(|chunk| range(chunk).filter_map(&f).collect())
        .collect();
    out.resize(parts.iter().map(Vec::len).sum(), T::default());
    let mut places = Vec::with_capacity(parts.len());
    let mut rest = &mut out[..];
    for part in &parts {
        let (head, tail) = rest.split_at_mut(part.len());
        places.push(head);
        rest = tail;
    }
    places
        .into_par_iter()
        .zip(&parts)
        .for_each(|(place, part)| place.copy_from_slice(part));
}

/// Bytes a task of [`copy_in_parallel`] copies: megabytes (a read-back of a large world's
/// bodies, its pair keys) spread over the cores, a few kilobytes stay on this thread.
const COPY_CHUNK_BYTES: usize = 1 << 18;

/// `destination.copy_from_slice(source)`, on every core for large arrays: one thread copies
/// (from mapped memory above all) at a fraction of the bandwidth several reach.
pub(crate) fn copy_in_parallel<T: bytemuck::Pod>(destination: &mut [T], source: &[T]) {
    let destination: &mut [u8] = bytemuck::cast_slice_mut(destination);
    let source: &[u8] = bytemuck::cast_slice(source);
    if source.len() <= COPY_CHUNK_BYTES {
        destination.copy_from_slice(source);
        return;
    }
    destination
        .par_chunks_mut(COPY_CHUNK_BYTES)
        .zip(source.par_chunks(COPY_CHUNK_BYTES))
        .for_each(|(to, from)| to.copy_from_slice(from));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_sequential_order_at_every_size() {
        let keep = |i: usize| (i.wrapping_mul(2_654_435_761) % 7 < 3).then_some(i as u32 * 3);
        let mut out = vec![99u32; 5];
        for count in [0, 1, CHUNK - 1, CHUNK, CHUNK + 1, 5 * CHUNK + 17] {
            filter_map_ordered(count, keep, &mut out);
            let expected: Vec<u32> = (0..count).filter_map(keep).collect();
            assert_eq!(out, expected, "{count} indices");
        }
        // Nothing kept, everything kept.
        filter_map_ordered(3 * CHUNK, |_| None::<u32>, &mut out);
        assert!(out.is_empty());
        filter_map_ordered(3 * CHUNK, |i| Some(i as u32), &mut out);
        assert!(out.iter().enumerate().all(|(i, &v)| i as u32 == v));
    }
}
