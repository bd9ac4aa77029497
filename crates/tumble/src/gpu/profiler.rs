//! GPU stage timings in the same report as CPU scopes.
//!
//! Each measured stage is its own compute pass whose beginning and end write a timestamp
//! ([`GpuProfiler::pass_timestamps`]). After the frame's passes the queries are resolved into
//! a buffer ([`GpuProfiler::resolve`]); after submission [`GpuProfiler::collect`] reads them
//! back, converts ticks to milliseconds with the queue's timestamp period and records each span
//! into the [`Profiler`] as [`SpanKind::Gpu`]. Host↔device copies are timed on the host and
//! recorded as [`SpanKind::Copy`] ([`record_copy`]).
//!
//! Without timestamp queries (llvmpipe on GL) every call is a no-op and passes get no
//! timestamp writes: the report then simply has no GPU lines.

use crate::gpu::buffer::read_mapped;
use crate::gpu::context::{GpuContext, GpuError};
use crate::profile::{Profiler, SpanKind};

/// Scope names from the report's root to a span, e.g. `&["particles", "sort"]`.
pub type SpanPath = &'static [&'static str];

#[derive(Debug)]
pub struct GpuProfiler {
    queries: Option<Queries>,
    /// Spans begun this frame, in query order (span k uses queries 2k and 2k + 1).
    spans: Vec<SpanPath>,
    /// Resolved timestamps of the last collected frame, reused.
    ticks: Vec<u64>,
}

#[derive(Debug)]
struct Queries {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    readback: wgpu::Buffer,
    /// Spans that fit in the query set.
    capacity: usize,
    /// Nanoseconds per tick.
    period_ns: f64,
}

impl GpuProfiler {
    /// A profiler for up to `max_spans` measured passes per frame; a no-op when the adapter
    /// has no timestamp queries.
    pub fn new(context: &GpuContext, max_spans: usize) -> Self {
        let queries = context.has_timestamps().then(|| {
            let count = (2 * max_spans.max(1)) as u32;
            let bytes = u64::from(count) * 8;
            let buffer = |label, usage| {
                context.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: bytes,
                    usage,
                    mapped_at_creation: false,
                })
            };
            Queries {
                set: context.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("gpu profiler"),
                    ty: wgpu::QueryType::Timestamp,
                    count,
                }),
                resolved: buffer(
                    "timestamps resolved",
                    wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                ),
                readback: buffer(
                    "timestamps readback",
                    wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                ),
                capacity: max_spans.max(1),
                period_ns: f64::from(context.queue.get_timestamp_period()),
            }
        });
        Self {
            queries,
            spans: Vec::with_capacity(max_spans),
            ticks: Vec::with_capacity(2 * max_spans),
        }
    }

    /// Whether spans are measured (the adapter has timestamp queries).
    pub fn is_active(&self) -> bool {
        self.queries.is_some()
    }

    /// Timestamp writes for a pass measured as `path`, or `None` (no queries, or more spans
    /// this frame than the profiler was made for).
    pub fn pass_timestamps(
        &mut self,
        path: SpanPath,
    ) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let queries = self.queries.as_ref()?;
        if self.spans.len() >= queries.capacity {
            return None;
        }
        let first = 2 * self.spans.len() as u32;
        self.spans.push(path);
        Some(wgpu::ComputePassTimestampWrites {
            query_set: &queries.set,
            beginning_of_pass_write_index: Some(first),
            end_of_pass_write_index: Some(first + 1),
        })
    }

    /// Resolves this frame's queries; encode after the measured passes.
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        let Some(queries) = &self.queries else {
            return;
        };
        if self.spans.is_empty() {
            return;
        }
        let count = 2 * self.spans.len() as u32;
        encoder.resolve_query_set(&queries.set, 0..count, &queries.resolved, 0);
        encoder.copy_buffer_to_buffer(
            &queries.resolved,
            0,
            &queries.readback,
            0,
            u64::from(count) * 8,
        );
    }

    /// Reads the resolved timestamps (waits for the GPU) and records each span into
    /// `profiler`. Call after submitting the frame that [`resolve`](Self::resolve)d.
    pub fn collect(
        &mut self,
        context: &GpuContext,
        profiler: &mut Profiler,
    ) -> Result<(), GpuError> {
        let Some(queries) = &self.queries else {
            return Ok(());
        };
        if self.spans.is_empty() {
            return Ok(());
        }
        let bytes = 16 * self.spans.len() as u64;
        let ticks = &mut self.ticks;
        ticks.clear();
        read_mapped(context, &queries.readback, bytes, "timestamps", |data| {
            ticks.extend_from_slice(bytemuck::cast_slice(data));
        })?;
        for (span, pair) in self.spans.iter().zip(self.ticks.chunks_exact(2)) {
            let ms = pair[1].saturating_sub(pair[0]) as f64 * queries.period_ns * 1e-6;
            profiler.record(span, SpanKind::Gpu, ms);
        }
        self.spans.clear();
        Ok(())
    }
}

/// Records a host↔device copy of `ms` milliseconds (timed on the host around the copy and
/// its wait) at `path`.
pub fn record_copy(profiler: &mut Profiler, path: SpanPath, ms: f64) {
    profiler.record(path, SpanKind::Copy, ms);
}
