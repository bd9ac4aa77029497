//! GPU stage timings in the same report as CPU scopes.
//!
//! Each measured stage is its own compute pass whose beginning and end write a timestamp
//! ([`GpuProfiler::pass_timestamps`]). After the frame's passes the queries are resolved into
//! a buffer ([`GpuProfiler::resolve`]); after submission [`GpuProfiler::collect`] reads them
//! back, converts ticks to milliseconds with the queue's timestamp period and records each span
//! into the [`Profiler`] as [`SpanKind::Gpu`]. Host↔device copies are timed on the host and
//! recorded as [`SpanKind::Copy`] ([`record_copy`]).
//!
//! Passes are timed only while their device's context asks for it
//! ([`GpuContext::set_gpu_timing`]: `tumble run --profile` and the viewer do); otherwise, and
//! without timestamp queries (llvmpipe on GL), every call is a no-op and passes get no
//! timestamp writes: the report then simply has no GPU lines.
//!
//! With `TUMBLE_PROFILE_DISPATCHES=1` in the environment, and an adapter that writes timestamps
//! inside passes, each dispatch of the passes encoded through [`GpuProfiler::timing_dispatches`]
//! is timed too ([`DispatchTimer`]): the report gets a line `dispatches`, the kernels' time
//! dispatch by dispatch, with a line per kernel (its time per frame and dispatches per frame).
//! The timestamps between dispatches cost time of their own, so the stage lines of such a
//! profile read a little high; it is a tool for finding which kernel takes the time.

use std::cell::RefCell;

use crate::gpu::buffer::read_mapped;
use crate::gpu::context::{GpuContext, GpuError};
use crate::profile::{Profiler, SpanKind};

/// Scope names from the report's root to a span, e.g. `&["particles", "sort"]`.
pub type SpanPath = &'static [&'static str];

#[derive(Debug)]
pub struct GpuProfiler {
    queries: Option<Queries>,
    /// The context's switch ([`GpuContext::set_gpu_timing`]).
    context: GpuContext,
    /// Each dispatch's timestamps, when they are asked for (see the module docs).
    dispatches: Option<DispatchTimer>,
    /// Spans begun this frame, in query order (span k uses queries 2k and 2k + 1).
    spans: Vec<SpanPath>,
}

#[derive(Debug)]
struct Queries {
    timestamps: Timestamps,
    /// Spans that fit in the query set.
    capacity: usize,
}

/// A timestamp query set read in pairs (a span's beginning and end), with the buffers that
/// bring it back: the pass profiler's and the dispatch timer's.
#[derive(Debug)]
struct Timestamps {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    readback: wgpu::Buffer,
    /// Nanoseconds per tick.
    period_ns: f64,
    /// The last read's ticks, then its durations, reused.
    ticks: Vec<u64>,
    ms: Vec<f64>,
}

impl Timestamps {
    /// Room for `pairs` spans; `label` names the query set and its buffers.
    fn new(context: &GpuContext, label: &str, pairs: u32) -> Self {
        let bytes = u64::from(2 * pairs) * 8;
        let buffer = |what: &str, usage| {
            context.create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("{label} {what}")),
                size: bytes,
                usage,
                mapped_at_creation: false,
            })
        };
        Self {
            set: context.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some(label),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * pairs,
            }),
            resolved: buffer(
                "resolved",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            readback: buffer(
                "readback",
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
            period_ns: f64::from(context.queue.get_timestamp_period()),
            ticks: Vec::new(),
            ms: Vec::new(),
        }
    }

    /// Encodes the resolve and copy of the first `pairs` spans (none: nothing).
    fn resolve(&self, encoder: &mut wgpu::CommandEncoder, pairs: usize) {
        if pairs == 0 {
            return;
        }
        let count = 2 * pairs as u32;
        encoder.resolve_query_set(&self.set, 0..count, &self.resolved, 0);
        encoder.copy_buffer_to_buffer(&self.resolved, 0, &self.readback, 0, u64::from(count) * 8);
    }

    /// Reads the first `pairs` spans back (waits for the GPU): their durations (ms).
    fn read(&mut self, context: &GpuContext, pairs: usize) -> Result<&[f64], GpuError> {
        let ticks = &mut self.ticks;
        ticks.clear();
        read_mapped(
            context,
            &self.readback,
            16 * pairs as u64,
            "timestamps",
            |data| {
                ticks.extend_from_slice(bytemuck::cast_slice(data));
            },
        )?;
        let period_ns = self.period_ns;
        self.ms.clear();
        self.ms.extend(
            self.ticks
                .chunks_exact(2)
                .map(|pair| pair[1].saturating_sub(pair[0]) as f64 * period_ns * 1e-6),
        );
        Ok(&self.ms)
    }
}

impl GpuProfiler {
    /// A profiler for up to `max_spans` measured passes per frame; a no-op when the adapter
    /// has no timestamp queries.
    pub fn new(context: &GpuContext, max_spans: usize) -> Self {
        let queries = context.has_timestamps().then(|| Queries {
            timestamps: Timestamps::new(context, "gpu profiler", max_spans.max(1) as u32),
            capacity: max_spans.max(1),
        });
        let mut profiler = Self {
            queries,
            context: context.clone(),
            dispatches: None,
            spans: Vec::with_capacity(max_spans),
        };
        if std::env::var("TUMBLE_PROFILE_DISPATCHES").is_ok_and(|value| value == "1") {
            profiler.time_each_dispatch(context);
        }
        profiler
    }

    /// From now on, time each dispatch encoded through [`Self::timing_dispatches`] (see the
    /// module docs). False, and nothing changes, when the adapter cannot write timestamps
    /// inside a pass.
    pub fn time_each_dispatch(&mut self, context: &GpuContext) -> bool {
        if !context.has_pass_timestamps() {
            return false;
        }
        self.dispatches
            .get_or_insert_with(|| DispatchTimer::new(context));
        true
    }

    /// Runs `encode`, which encodes dispatches into a pass, with each dispatch timed when
    /// dispatches are timed (see the module docs).
    pub fn timing_dispatches<R>(&mut self, encode: impl FnOnce() -> R) -> R {
        let Some(timer) = self.dispatches.take() else {
            return encode();
        };
        ACTIVE.with_borrow_mut(|active| *active = Some(timer));
        let result = encode();
        self.dispatches = ACTIVE.with_borrow_mut(Option::take);
        result
    }

    /// Whether spans are measured: asked for, and the adapter has timestamp queries.
    pub fn is_active(&self) -> bool {
        self.queries.is_some() && self.context.times_gpu()
    }

    /// Whether each dispatch is timed ([`Self::time_each_dispatch`]).
    pub fn times_dispatches(&self) -> bool {
        self.dispatches.is_some()
    }

    /// Forgets the spans begun since the last [`Self::collect`]: their passes were recorded
    /// into commands that will not be submitted.
    pub fn discard(&mut self) {
        self.spans.clear();
    }

    /// Timestamp writes for a pass measured as `path`, or `None` (no queries, or more spans
    /// this frame than the profiler was made for).
    pub fn pass_timestamps(
        &mut self,
        path: SpanPath,
    ) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let queries = self.queries.as_ref().filter(|_| self.context.times_gpu())?;
        if self.spans.len() >= queries.capacity {
            return None;
        }
        let first = 2 * self.spans.len() as u32;
        self.spans.push(path);
        Some(wgpu::ComputePassTimestampWrites {
            query_set: &queries.timestamps.set,
            beginning_of_pass_write_index: Some(first),
            end_of_pass_write_index: Some(first + 1),
        })
    }

    /// Resolves this frame's queries; encode after the measured passes.
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        if let Some(timer) = &self.dispatches {
            timer.resolve(encoder);
        }
        if let Some(queries) = &self.queries {
            queries.timestamps.resolve(encoder, self.spans.len());
        }
    }

    /// Reads the resolved timestamps (waits for the GPU) and records each span into
    /// `profiler`. Call after submitting the frame that [`resolve`](Self::resolve)d.
    pub fn collect(
        &mut self,
        context: &GpuContext,
        profiler: &mut Profiler,
    ) -> Result<(), GpuError> {
        if let Some(timer) = &mut self.dispatches {
            timer.collect(context, profiler)?;
        }
        let Some(queries) = &mut self.queries else {
            return Ok(());
        };
        if self.spans.is_empty() {
            return Ok(());
        }
        // Taken first, so that a failed read leaves the profiler ready for the next frame.
        let spans = std::mem::take(&mut self.spans);
        for (span, ms) in spans
            .iter()
            .zip(queries.timestamps.read(context, spans.len())?)
        {
            profiler.record(span, SpanKind::Gpu, *ms);
        }
        self.spans = spans;
        self.spans.clear();
        Ok(())
    }
}

/// Records a host↔device copy of `ms` milliseconds (timed on the host around the copy and
/// its wait) at `path`.
pub fn record_copy(profiler: &mut Profiler, path: SpanPath, ms: f64) {
    profiler.record(path, SpanKind::Copy, ms);
}

thread_local! {
    /// The dispatch timer of the pass being encoded on this thread
    /// ([`GpuProfiler::timing_dispatches`]), where
    /// [`Dispatch::encode`](super::kernel::Dispatch::encode) finds it.
    static ACTIVE: RefCell<Option<DispatchTimer>> = const { RefCell::new(None) };
}

/// Dispatches timed between two collections at most; the ones past it go untimed.
const MAX_TIMED_DISPATCHES: u32 = 2048;

/// Timestamps around each dispatch (see the module docs): a query set written inside the
/// passes, and the kernel of each pair of queries.
#[derive(Debug)]
pub struct DispatchTimer {
    timestamps: Timestamps,
    /// The kernel of each dispatch timed since the last collection, in query order.
    names: Vec<&'static str>,
    /// Dispatches past [`MAX_TIMED_DISPATCHES`] since the last collection, left untimed.
    untimed: usize,
}

/// A dispatch between its two timestamps: [`Self::end`] writes the second.
pub struct TimedDispatch {
    set: wgpu::QuerySet,
    index: u32,
}

impl TimedDispatch {
    pub fn end(self, pass: &mut wgpu::ComputePass<'_>) {
        pass.write_timestamp(&self.set, self.index + 1);
    }
}

impl DispatchTimer {
    fn new(context: &GpuContext) -> Self {
        Self {
            timestamps: Timestamps::new(context, "dispatch timer", MAX_TIMED_DISPATCHES),
            names: Vec::new(),
            untimed: 0,
        }
    }

    /// Whether this thread is encoding a pass whose dispatches are timed: a caller may then
    /// name its dispatches more finely ([`Dispatch::named`](super::kernel::Dispatch::named)).
    pub fn is_active() -> bool {
        ACTIVE.with_borrow(Option::is_some)
    }

    /// Writes the first timestamp of a dispatch of kernel `name` when this thread is encoding
    /// a timed pass and queries are left; the caller ends it after the dispatch.
    pub fn begin(pass: &mut wgpu::ComputePass<'_>, name: &'static str) -> Option<TimedDispatch> {
        ACTIVE.with_borrow_mut(|active| {
            let timer = active.as_mut()?;
            if timer.names.len() >= MAX_TIMED_DISPATCHES as usize {
                timer.untimed += 1;
                return None;
            }
            let index = 2 * timer.names.len() as u32;
            timer.names.push(name);
            pass.write_timestamp(&timer.timestamps.set, index);
            Some(TimedDispatch {
                set: timer.timestamps.set.clone(),
                index,
            })
        })
    }

    fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        self.timestamps.resolve(encoder, self.names.len());
    }

    /// Records the dispatches' times at `dispatches` and `dispatches` / kernel, and those left
    /// untimed, as many calls of a line of their own.
    fn collect(&mut self, context: &GpuContext, profiler: &mut Profiler) -> Result<(), GpuError> {
        for _ in 0..std::mem::take(&mut self.untimed) {
            profiler.record(
                &["dispatches", "untimed (too many to time)"],
                SpanKind::Gpu,
                0.0,
            );
        }
        if self.names.is_empty() {
            return Ok(());
        }
        // Taken first, so that a failed read leaves the timer ready for the next frame.
        let names = std::mem::take(&mut self.names);
        for (name, ms) in names
            .iter()
            .zip(self.timestamps.read(context, names.len())?)
        {
            profiler.record(&["dispatches"], SpanKind::Gpu, *ms);
            profiler.record(&["dispatches", name], SpanKind::Gpu, *ms);
        }
        self.names = names;
        self.names.clear();
        Ok(())
    }
}
