//! The step's host passes over every pair or body on every core: an order-keeping filter
//! ([`filter_map_ordered`]) and a copy ([`copy_in_parallel`]).

use rayon::prelude::*;

/// Indices a task takes at a time: large enough that a pass over a few thousand pairs stays
/// on one thread, small enough that a few hundred thousand spread over every core.
const CHUNK: usize = 8192;

/// Each chunk's results of [`filter_map_ordered`], kept from call to call so that a pass
/// allocates nothing once they have grown.
#[derive(Debug)]
pub(crate) struct FilterParts<T>(Vec<Vec<T>>);

impl<T> Default for FilterParts<T> {
    fn default() -> Self {
        Self(Vec::new())
    }
}

/// `out` = the `Some` results of `f` over `0..count`, in index order, as the sequential
/// `(0..count).filter_map(f)` gives them, computed on rayon's threads: each chunk's results
/// are gathered in `parts`, then copied to their place. `f` runs once per index (it is
/// usually a few loads from scattered arrays, which cost more than the copy).
pub(crate) fn filter_map_ordered<T: Copy + Default + Send + Sync>(
    count: usize,
    f: impl Fn(usize) -> Option<T> + Sync,
    parts: &mut FilterParts<T>,
    out: &mut Vec<T>,
) {
    out.clear();
    if count <= CHUNK {
        // One chunk: on this thread, without waking the pool (tens of microseconds).
        out.extend((0..count).filter_map(f));
        return;
    }
    let range = |chunk: usize| chunk * CHUNK..((chunk + 1) * CHUNK).min(count);
    // Parts past this call's chunks keep their memory for a larger call.
    let chunks = count.div_ceil(CHUNK);
    if parts.0.len() < chunks {
        parts.0.resize_with(chunks, Vec::new);
    }
    let parts = &mut parts.0[..chunks];
    parts.par_iter_mut().enumerate().for_each(|(chunk, part)| {
        part.clear();
        part.extend(range(chunk).filter_map(&f));
    });
    out.resize(parts.iter().map(Vec::len).sum(), T::default());
    copy_parts(out, parts);
}

/// Copies `parts` one after another into `out`, as long as all of them, halves on two
/// threads (rayon's join: no allocation).
fn copy_parts<T: Copy + Send + Sync>(out: &mut [T], parts: &[Vec<T>]) {
    match parts {
        [] => {}
        [part] => out.copy_from_slice(part),
        _ => {
            let (left, right) = parts.split_at(parts.len() / 2);
            let (to_left, to_right) = out.split_at_mut(left.iter().map(Vec::len).sum());
            rayon::join(|| copy_parts(to_left, left), || copy_parts(to_right, right));
        }
    }
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
        let (mut parts, mut out) = (FilterParts::default(), vec![99u32; 5]);
        for count in [0, 1, CHUNK - 1, CHUNK, CHUNK + 1, 5 * CHUNK + 17] {
            filter_map_ordered(count, keep, &mut parts, &mut out);
            let expected: Vec<u32> = (0..count).filter_map(keep).collect();
            assert_eq!(out, expected, "{count} indices");
        }
        // Nothing kept, everything kept.
        filter_map_ordered(3 * CHUNK, |_| None::<u32>, &mut parts, &mut out);
        assert!(out.is_empty());
        filter_map_ordered(3 * CHUNK, |i| Some(i as u32), &mut parts, &mut out);
        assert!(out.iter().enumerate().all(|(i, &v)| i as u32 == v));
    }
}
