//! [`GpuVec`]: a typed, growable storage buffer.
//!
//! Capacity doubles when it must grow, so a stage that sizes its buffers before the step loop
//! never reallocates inside it; `len` says how many elements are meaningful. Growing replaces
//! the `wgpu::Buffer`, so bind groups built on the old one must be rebuilt: drivers compare
//! [`GpuVec::buffer`] handles (they are `Eq + Hash`) to notice.
//!
//! A vector is bound whole by most kernels, so its buffer stays within one storage binding
//! (the adapter's `max_storage_buffer_binding_size`: 128 MiB on Mesa's CPU drivers). One made
//! [`GpuVec::windowed`] may grow to the largest buffer the adapter allows; the primitives that
//! take it (fill, copy, scan, reduce, compaction, radix sort) bind it a [`Window`] at a time.
//!
//! Uploads go through the queue (`write_buffer`, whose staging memory wgpu pools and reuses);
//! downloads copy into a `MAP_READ` staging buffer that the vector keeps and reuses.

use std::marker::PhantomData;

use crate::gpu::context::{GpuContext, GpuError};
use crate::pipeline::parallel::copy_in_parallel;

/// Elements allocated for an empty vector: a binding must not be empty.
const MIN_CAPACITY_BYTES: u64 = 16;

#[derive(Debug)]
pub struct GpuVec<T: bytemuck::Pod> {
    label: &'static str,
    buffer: wgpu::Buffer,
    /// May pass one binding ([`GpuVec::windowed`]).
    windowed: bool,
    len: usize,
    capacity: usize,
    staging: Option<wgpu::Buffer>,
    /// Elements the last [`GpuVec::encode_download`] copies into `staging`.
    staged: usize,
    element: PhantomData<T>,
}

impl<T: bytemuck::Pod> GpuVec<T> {
    /// Copies must move whole 4-byte words (wgpu's `COPY_BUFFER_ALIGNMENT`) and WGSL arrays
    /// hold 4-byte scalars, so elements are multiples of 4 bytes.
    const ELEMENT_OK: () = assert!(
        size_of::<T>().is_multiple_of(4) && size_of::<T>() > 0,
        "GpuVec elements are multiples of 4 bytes"
    );

    /// An empty vector with room for `capacity` elements, within one storage binding.
    pub fn with_capacity(
        context: &GpuContext,
        label: &'static str,
        capacity: usize,
    ) -> Result<Self, GpuError> {
        Self::new(context, label, capacity, false)
    }

    /// An empty vector with room for `capacity` elements that may grow past one storage
    /// binding, up to the adapter's largest buffer: for the primitives, which bind it by
    /// [`windows`]. Binding it whole ([`GpuVec::binding`], [`GpuVec::whole`]) is valid only
    /// while it fits one binding.
    pub fn windowed(
        context: &GpuContext,
        label: &'static str,
        capacity: usize,
    ) -> Result<Self, GpuError> {
        Self::new(context, label, capacity, true)
    }

    fn new(
        context: &GpuContext,
        label: &'static str,
        capacity: usize,
        windowed: bool,
    ) -> Result<Self, GpuError> {
        let () = Self::ELEMENT_OK;
        let capacity = capacity.max(Self::min_capacity());
        let buffer = create(context, label, Self::bytes(capacity), windowed)?;
        Ok(Self {
            label,
            buffer,
            windowed,
            len: 0,
            capacity,
            staging: None,
            staged: 0,
            element: PhantomData,
        })
    }

    /// A vector holding a copy of `data`.
    pub fn from_slice(
        context: &GpuContext,
        label: &'static str,
        data: &[T],
    ) -> Result<Self, GpuError> {
        let mut vector = Self::with_capacity(context, label, data.len())?;
        vector.upload(context, data)?;
        Ok(vector)
    }

    fn min_capacity() -> usize {
        (MIN_CAPACITY_BYTES as usize).div_ceil(size_of::<T>())
    }

    fn bytes(elements: usize) -> u64 {
        (elements * size_of::<T>()) as u64
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// The first `len` elements as a binding (the whole buffer when empty, since a binding
    /// cannot be empty; kernels bound-check against their own counts).
    pub fn binding(&self) -> wgpu::BufferBinding<'_> {
        wgpu::BufferBinding {
            buffer: &self.buffer,
            offset: 0,
            size: wgpu::BufferSize::new(Self::bytes(self.len.max(Self::min_capacity()))),
        }
    }

    /// The whole allocation as a binding.
    pub fn whole(&self) -> wgpu::BufferBinding<'_> {
        self.buffer.as_entire_buffer_binding()
    }

    /// Makes room for `capacity` elements, doubling, but never past the largest buffer it may
    /// have when `capacity` fits in one; keeps the first `len` elements (through a copy
    /// submitted now, so call it between steps, not while an encoder writing this vector is
    /// open). Returns whether the buffer was replaced.
    pub fn reserve(&mut self, context: &GpuContext, capacity: usize) -> Result<bool, GpuError> {
        if capacity <= self.capacity {
            return Ok(false);
        }
        // Doubling a vector past half the limit would fail where the elements asked for fit.
        let most = (buffer_limit(context, self.windowed) / size_of::<T>() as u64) as usize;
        let new_capacity = capacity.max((self.capacity * 2).min(most));
        let buffer = create(
            context,
            self.label,
            Self::bytes(new_capacity),
            self.windowed,
        )?;
        if self.len > 0 {
            let mut encoder =
                context
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                        label: Some("grow"),
                    });
            encoder.copy_buffer_to_buffer(&self.buffer, 0, &buffer, 0, Self::bytes(self.len));
            context.queue.submit([encoder.finish()]);
        }
        self.buffer = buffer;
        self.capacity = new_capacity;
        Ok(true)
    }

    /// Sets the number of meaningful elements, growing if needed (new elements are
    /// unspecified until a kernel writes them).
    pub fn resize(&mut self, context: &GpuContext, len: usize) -> Result<bool, GpuError> {
        let grown = self.reserve(context, len)?;
        self.len = len;
        Ok(grown)
    }

    /// Replaces the contents with `data` (the write lands at the next submission, before its
    /// command buffers run).
    pub fn upload(&mut self, context: &GpuContext, data: &[T]) -> Result<(), GpuError> {
        if data.len() > self.capacity {
            // The old contents are about to be overwritten: no need to copy them.
            self.len = 0;
        }
        self.resize(context, data.len())?;
        if !data.is_empty() {
            context
                .queue
                .write_buffer(&self.buffer, 0, bytemuck::cast_slice(data));
        }
        Ok(())
    }

    /// Copies the `len` elements back to the host. Submits pending queue writes and waits.
    pub fn download(&mut self, context: &GpuContext) -> Result<Vec<T>, GpuError> {
        let mut out = Vec::new();
        self.download_into(context, &mut out)?;
        Ok(out)
    }

    /// Like [`download`](Self::download), into a vector the caller reuses.
    pub fn download_into(
        &mut self,
        context: &GpuContext,
        out: &mut Vec<T>,
    ) -> Result<(), GpuError> {
        let mut encoder = context
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("download"),
            });
        self.encode_download(context, &mut encoder);
        context.queue.submit([encoder.finish()]);
        self.read_download(context, out)
    }

    /// Copies the `len` elements back to the host now, through a staging buffer of its own:
    /// for readers that hold the vector shared (the world's on-demand reads between steps).
    pub fn read(&self, context: &GpuContext) -> Result<Vec<T>, GpuError> {
        let mut out = Vec::with_capacity(self.len);
        if self.len == 0 {
            return Ok(out);
        }
        let bytes = Self::bytes(self.len);
        // Not counted by `resources_made`: no recorded command refers to it, so a read between
        // steps keeps the commands recorded ahead.
        let staging = context.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(self.label),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = context
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some(self.label),
            });
        encoder.copy_buffer_to_buffer(&self.buffer, 0, &staging, 0, bytes);
        context.queue.submit([encoder.finish()]);
        read_mapped(context, &staging, bytes, self.label, |bytes| {
            out.extend_from_slice(bytemuck::cast_slice(bytes));
        })?;
        Ok(out)
    }

    /// Records the copy of the `len` elements into the vector's staging buffer at the end of
    /// `encoder`, so that a stage's kernels and its read-backs are one submission and one
    /// wait; once it is submitted, [`read_download`](Self::read_download) hands them over.
    pub fn encode_download(&mut self, context: &GpuContext, encoder: &mut wgpu::CommandEncoder) {
        self.encode_download_prefix(context, encoder, self.len);
    }

    /// [`encode_download`](Self::encode_download) of the first `len` elements only (at most
    /// the vector's length): a stage that knows about how many of its elements are live copies
    /// those, not the slack past them.
    pub fn encode_download_prefix(
        &mut self,
        context: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        len: usize,
    ) {
        assert!(
            len <= self.len,
            "a prefix of {len} of {} elements",
            self.len
        );
        self.staged = len;
        if len == 0 {
            return;
        }
        let bytes = Self::bytes(len);
        if self
            .staging
            .as_ref()
            .is_some_and(|staging| staging.size() < bytes)
        {
            // Too small since the vector grew: replaced below, at the new capacity.
            self.staging = None;
        }
        let size = Self::bytes(self.capacity);
        let staging = self.staging.get_or_insert_with(|| {
            context.create_buffer(&wgpu::BufferDescriptor {
                label: Some(self.label),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        encoder.copy_buffer_to_buffer(&self.buffer, 0, staging, 0, bytes);
    }

    /// The elements that the last [`encode_download`](Self::encode_download) copied, into
    /// `out`, after its submission: waits for it (which costs nothing when the submission's
    /// wait came first).
    pub fn read_download(&self, context: &GpuContext, out: &mut Vec<T>) -> Result<(), GpuError> {
        // Only the tail changes length: a vector read into every step is written once.
        out.resize(self.staged, T::zeroed());
        self.read_staged(context, |items| copy_in_parallel(out, items))
    }

    /// [`read_download`](Self::read_download) into a slice of the downloaded length, with no
    /// vector between: the bodies' state comes back straight into the world's arrays.
    pub fn read_download_to(&self, context: &GpuContext, out: &mut [T]) -> Result<(), GpuError> {
        if out.len() != self.staged {
            return Err(GpuError::Readback {
                what: self.label,
                reason: format!("{} elements downloaded into {}", self.staged, out.len()),
            });
        }
        self.read_staged(context, |items| copy_in_parallel(out, items))
    }

    /// Hands the elements the last [`encode_download`](Self::encode_download) staged to
    /// `read` (none when it staged none).
    fn read_staged(&self, context: &GpuContext, read: impl FnOnce(&[T])) -> Result<(), GpuError> {
        let Some(staging) = self.staging.as_ref().filter(|_| self.staged > 0) else {
            read(&[]);
            return Ok(());
        };
        read_mapped(
            context,
            staging,
            Self::bytes(self.staged),
            self.label,
            |bytes| read(bytemuck::cast_slice(bytes)),
        )
    }
}

/// How long a read-back waits for its map callback after the device went idle.
const MAP_CALLBACK_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// Maps the first `bytes` of `staging` for reading, hands them to `read`, unmaps.
pub(crate) fn read_mapped(
    context: &GpuContext,
    staging: &wgpu::Buffer,
    bytes: u64,
    what: &'static str,
    read: impl FnOnce(&[u8]),
) -> Result<(), GpuError> {
    let (sender, receiver) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, 0..bytes, move |result| {
        // The receiver outlives the wait below; a failed send means nobody is listening.
        let _ = sender.send(result);
    });
    context.wait()?;
    // The callback runs inside a poll of the device: ours above, or, when another thread
    // shares the device, that thread's, which may still be running it when ours returns.
    match receiver.recv_timeout(MAP_CALLBACK_TIMEOUT) {
        Ok(Ok(())) => {}
        Ok(Err(error)) => {
            return Err(GpuError::Readback {
                what,
                reason: error.to_string(),
            });
        }
        Err(_) => {
            return Err(GpuError::Readback {
                what,
                reason: "the map callback did not run".to_owned(),
            });
        }
    }
    {
        let view = staging
            .slice(0..bytes)
            .get_mapped_range()
            .map_err(|error| GpuError::Readback {
                what,
                reason: error.to_string(),
            })?;
        read(&view);
    }
    staging.unmap();
    Ok(())
}

/// A storage buffer usable as copy source and destination, checked against the adapter's
/// limits (one binding, or one buffer when `windowed`) so an oversized request is an error
/// rather than a validation panic.
/// The largest buffer a vector may have: one storage binding, or for a windowed vector the
/// adapter's largest buffer.
fn buffer_limit(context: &GpuContext, windowed: bool) -> u64 {
    let limits = context.device.limits();
    if windowed {
        limits.max_buffer_size
    } else {
        limits
            .max_buffer_size
            .min(limits.max_storage_buffer_binding_size)
    }
}

fn create(
    context: &GpuContext,
    label: &'static str,
    bytes: u64,
    windowed: bool,
) -> Result<wgpu::Buffer, GpuError> {
    let limit = buffer_limit(context, windowed);
    if bytes > limit {
        return Err(GpuError::BufferTooLarge {
            what: label,
            needed: bytes,
            limit,
        });
    }
    Ok(context.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(MIN_CAPACITY_BYTES),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    }))
}

/// Elements `first..first + len` of a buffer, bound as one storage binding: the array a kernel
/// sees. A buffer within one binding is one window.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    pub first: usize,
    pub len: usize,
}

impl Window {
    /// This window of `buffer`, whose elements are `element_bytes` each, as a binding.
    pub fn binding(self, buffer: &wgpu::Buffer, element_bytes: usize) -> wgpu::BufferBinding<'_> {
        wgpu::BufferBinding {
            buffer,
            offset: (self.first * element_bytes) as u64,
            size: wgpu::BufferSize::new((self.len.max(1) * element_bytes) as u64),
        }
    }

    /// The element after the window.
    pub fn end(self) -> usize {
        self.first + self.len
    }
}

/// `count` elements of `element_bytes` each, split into the fewest windows that each fit one
/// storage binding of `context`: every window but the last holds a multiple of `granule`
/// elements (a kernel's tile, so no tile straddles two windows) and starts at an offset the
/// adapter can bind. None for no elements.
pub fn windows(
    context: &GpuContext,
    count: usize,
    element_bytes: usize,
    granule: usize,
) -> Result<Vec<Window>, GpuError> {
    windows_at_most(context, count, element_bytes, granule, usize::MAX)
}

/// Like [`windows`], with at most `max_len` elements a window (but at least one granule).
pub fn windows_at_most(
    context: &GpuContext,
    count: usize,
    element_bytes: usize,
    granule: usize,
    max_len: usize,
) -> Result<Vec<Window>, GpuError> {
    let limits = context.device.limits();
    split(
        count,
        element_bytes as u64,
        granule as u64,
        max_len as u64,
        limits.max_storage_buffer_binding_size,
        u64::from(limits.min_storage_buffer_offset_alignment),
    )
}

/// [`windows_at_most`] for a binding limit and an offset alignment, in bytes.
fn split(
    count: usize,
    element_bytes: u64,
    granule: u64,
    max_len: u64,
    binding: u64,
    alignment: u64,
) -> Result<Vec<Window>, GpuError> {
    // Grow the granule until a window of whole granules starts on an aligned offset.
    let mut granule = granule.max(1);
    while !(granule * element_bytes).is_multiple_of(alignment) {
        granule *= 2;
    }
    let granules = binding / (granule * element_bytes);
    if granules == 0 {
        return Err(GpuError::BufferTooLarge {
            what: "one tile of a windowed kernel",
            needed: granule * element_bytes,
            limit: binding,
        });
    }
    let window = (granules.min((max_len / granule).max(1)) * granule) as usize;
    Ok((0..count.div_ceil(window))
        .map(|index| {
            let first = index * window;
            Window {
                first,
                len: window.min(count - first),
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Windows tile `0..count` in order, each fits the binding, starts aligned and, but the
    /// last, holds whole granules.
    fn check(count: usize, element: u64, granule: u64, max_len: u64, binding: u64) {
        let windows = split(count, element, granule, max_len, binding, 256).unwrap();
        let mut next = 0;
        for (index, window) in windows.iter().enumerate() {
            assert_eq!(window.first, next);
            assert!(window.len > 0);
            assert!(window.len as u64 * element <= binding);
            assert!((window.first as u64 * element).is_multiple_of(256));
            if index + 1 < windows.len() {
                assert!((window.len as u64).is_multiple_of(granule));
                assert!(window.len as u64 <= max_len.max(granule));
            }
            next = window.end();
        }
        assert_eq!(next, count);
    }

    #[test]
    fn windows_tile_the_array_within_the_limits() {
        for count in [0, 1, 255, 256, 257, 65_537, 1_000_003] {
            check(count, 4, 3840, u64::MAX, 128 << 20);
            check(count, 4, 3840, 128 * 3840, 128 << 20);
            check(count, 8, 4096, u64::MAX, 256 << 10);
            check(count, 4, 1, u64::MAX, 1 << 10);
            // A granule of 3 u32 is 12 bytes: doubled until windows start aligned.
            check(count, 4, 3, u64::MAX, 4 << 10);
        }
        assert_eq!(
            split(10, 4, 256, u64::MAX, 128 << 20, 256).unwrap().len(),
            1
        );
        assert!(
            split(0, 4, 256, u64::MAX, 128 << 20, 256)
                .unwrap()
                .is_empty()
        );
    }

    #[test]
    fn a_tile_larger_than_a_binding_is_an_error() {
        let error = split(100, 4, 3840, u64::MAX, 1 << 10, 256).unwrap_err();
        assert!(matches!(error, GpuError::BufferTooLarge { .. }), "{error}");
    }
}
