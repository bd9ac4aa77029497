//! [`GpuVec`]: a typed, growable storage buffer.
//!
//! Capacity doubles when it must grow, so a stage that sizes its buffers before the step loop
//! never reallocates inside it; `len` says how many elements are meaningful. Growing replaces
//! the `wgpu::Buffer`, so bind groups built on the old one must be rebuilt: drivers compare
//! [`GpuVec::buffer`] handles (they are `Eq + Hash`) to notice.
//!
//! Uploads go through the queue (`write_buffer`, whose staging memory wgpu pools and reuses);
//! downloads copy into a `MAP_READ` staging buffer that the vector keeps and reuses.

use std::marker::PhantomData;

use crate::gpu::context::{GpuContext, GpuError};

/// Elements allocated for an empty vector: a binding must not be empty.
const MIN_CAPACITY_BYTES: u64 = 16;

#[derive(Debug)]
pub struct GpuVec<T: bytemuck::Pod> {
    label: &'static str,
    buffer: wgpu::Buffer,
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

    /// An empty vector with room for `capacity` elements.
    pub fn with_capacity(
        context: &GpuContext,
        label: &'static str,
        capacity: usize,
    ) -> Result<Self, GpuError> {
        let () = Self::ELEMENT_OK;
        let capacity = capacity.max(Self::min_capacity());
        let buffer = create(context, label, Self::bytes(capacity))?;
        Ok(Self {
            label,
            buffer,
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

    /// Makes room for `capacity` elements, doubling; keeps the first `len` elements (through a
    /// copy submitted now, so call it between steps, not while an encoder writing this vector is
    /// open). Returns whether the buffer was replaced.
    pub fn reserve(&mut self, context: &GpuContext, capacity: usize) -> Result<bool, GpuError> {
        if capacity <= self.capacity {
            return Ok(false);
        }
        let new_capacity = capacity.max(self.capacity * 2);
        let buffer = create(context, self.label, Self::bytes(new_capacity))?;
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

    /// Records the copy of the `len` elements into the vector's staging buffer at the end of
    /// `encoder`, so that a stage's kernels and its read-backs are one submission and one
    /// wait; once it is submitted, [`read_download`](Self::read_download) hands them over.
    pub fn encode_download(&mut self, context: &GpuContext, encoder: &mut wgpu::CommandEncoder) {
        self.staged = self.len;
        if self.len == 0 {
            return;
        }
        let bytes = Self::bytes(self.len);
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
            context.device.create_buffer(&wgpu::BufferDescriptor {
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
        out.clear();
        let Some(staging) = self.staging.as_ref().filter(|_| self.staged > 0) else {
            return Ok(());
        };
        read_mapped(
            context,
            staging,
            Self::bytes(self.staged),
            self.label,
            |bytes| {
                out.extend_from_slice(bytemuck::cast_slice(bytes));
            },
        )
    }
}

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
    match receiver.try_recv() {
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
/// limits so an oversized request is an error rather than a validation panic.
fn create(context: &GpuContext, label: &'static str, bytes: u64) -> Result<wgpu::Buffer, GpuError> {
    let limits = context.device.limits();
    let limit = limits
        .max_buffer_size
        .min(limits.max_storage_buffer_binding_size);
    if bytes > limit {
        return Err(GpuError::BufferTooLarge {
            what: label,
            needed: bytes,
            limit,
        });
    }
    Ok(context.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(MIN_CAPACITY_BYTES),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    }))
}
