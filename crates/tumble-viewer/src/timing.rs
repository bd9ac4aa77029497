//! GPU time per pass of a frame: each pass the renderer records writes a timestamp at its
//! beginning and end (the pass's `timestamp_writes`); the frame's queries are resolved into a
//! buffer at the end of its encoder, and read back once the frame is done. On an adapter
//! without timestamp queries (llvmpipe on GL) there is no timer at all.

use crate::error::ViewError;
use crate::headless::map_and_wait;

/// Passes one frame can have: pose, shadow, depth pre-pass, meshes, ground, overlay.
const MAX_PASSES: u32 = 8;

pub(crate) struct PassTimer {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    readback: wgpu::Buffer,
    /// The passes begun this frame, in query order (pass k writes queries 2k and 2k + 1).
    names: Vec<&'static str>,
    /// Nanoseconds per tick.
    period_ns: f64,
}

impl PassTimer {
    /// A timer, or `None` where the device has no timestamp queries.
    pub(crate) fn new(device: &wgpu::Device, queue: &wgpu::Queue) -> Option<Self> {
        if !device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            return None;
        }
        let bytes = u64::from(2 * MAX_PASSES) * 8;
        let buffer = |label, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes,
                usage,
                mapped_at_creation: false,
            })
        };
        Some(Self {
            queries: device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * MAX_PASSES,
            }),
            resolved: buffer(
                "pass timestamps resolved",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            readback: buffer(
                "pass timestamps readback",
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
            names: Vec::new(),
            period_ns: f64::from(queue.get_timestamp_period()),
        })
    }

    /// Forgets the last frame's passes.
    pub(crate) fn start_frame(&mut self) {
        self.names.clear();
    }

    /// The first of the two queries of a pass named `name`.
    fn begin(&mut self, name: &'static str) -> u32 {
        debug_assert!(
            self.names.len() < MAX_PASSES as usize,
            "{name}: too many passes"
        );
        self.names.push(name);
        2 * (self.names.len() as u32 - 1)
    }

    pub(crate) fn render_pass(
        &mut self,
        name: &'static str,
    ) -> wgpu::RenderPassTimestampWrites<'_> {
        let first = self.begin(name);
        wgpu::RenderPassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(first),
            end_of_pass_write_index: Some(first + 1),
        }
    }

    pub(crate) fn compute_pass(
        &mut self,
        name: &'static str,
    ) -> wgpu::ComputePassTimestampWrites<'_> {
        let first = self.begin(name);
        wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(first),
            end_of_pass_write_index: Some(first + 1),
        }
    }

    /// Resolves the frame's queries; encode after its last pass.
    pub(crate) fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        if self.names.is_empty() {
            return;
        }
        let count = 2 * self.names.len() as u32;
        encoder.resolve_query_set(&self.queries, 0..count, &self.resolved, 0);
        encoder.copy_buffer_to_buffer(&self.resolved, 0, &self.readback, 0, u64::from(count) * 8);
    }

    /// Each pass's GPU time (ms), in the order they were recorded; waits for the frame that
    /// [`resolve`](Self::resolve)d them to finish.
    pub(crate) fn read(
        &self,
        device: &wgpu::Device,
    ) -> Result<Vec<(&'static str, f64)>, ViewError> {
        if self.names.is_empty() {
            return Ok(Vec::new());
        }
        let slice = self.readback.slice(..16 * self.names.len() as u64);
        map_and_wait(device, &slice)?;
        let times = {
            let mapped = slice
                .get_mapped_range()
                .map_err(|e| ViewError::Readback(e.to_string()))?;
            let ticks: &[u64] = bytemuck::cast_slice(&mapped);
            self.names
                .iter()
                .zip(ticks.chunks_exact(2))
                .map(|(&name, pair)| {
                    let ticks = pair[1].saturating_sub(pair[0]);
                    (name, ticks as f64 * self.period_ns * 1e-6)
                })
                .collect()
        };
        self.readback.unmap();
        Ok(times)
    }
}
