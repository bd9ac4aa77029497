//! What a dependent round of the solver's sweeps could cost, measured apart from the solver:
//! R rounds in which every thread reads two words that threads of other workgroups wrote in
//! the round before and writes one of its own, run three ways:
//!
//! - `dispatches`: a dispatch a round, in one compute pass (how the sweeps meet between
//!   batches now);
//! - `walk`: one workgroup, a storage barrier a round (how a walk meets between small batches);
//! - `grid`: one dispatch of P workgroups that meet at a barrier of their own between rounds (a
//!   counter in storage, spun on by a thread a workgroup). WebGPU promises no forward progress
//!   between workgroups, so this is a measurement, not a design: the kernel gives up after a
//!   bounded spin and says so, and the words it read are checked against the dispatches'.
//!
//! ```text
//! cargo run --release -p tumble --example grid_rounds -- [ROUNDS [WORKGROUPS [THREADS]]]
//! ```
//!
//! Defaults: 2000 rounds, 64 workgroups of 64 threads (the walk: one workgroup of 256).

use std::process::ExitCode;
use std::time::Instant;

use tumble::gpu::GpuContext;

const WGSL: &str = r"
struct Params {
    round: u32,
    rounds: u32,
    threads: u32,
    workgroups: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// Two halves of `threads` words: round r reads half r % 2 and writes the other.
@group(0) @binding(1) var<storage, read_write> words: array<atomic<u32>>;
// Word 0: workgroups arrived; word 1: set when a spin gave up.
@group(0) @binding(2) var<storage, read_write> sync: array<atomic<u32>>;

fn mix(x: u32) -> u32 {
    var h = x * 0x9e3779b1u;
    h ^= h >> 15u;
    return h * 0x85ebca6bu;
}

// Thread i's work in round r: two words from elsewhere (other workgroups, mostly), one out.
// `after` is 0, but not to the compiler: the grid's rounds pass the arrival count they saw
// through it, so that the loads of a round depend on the barrier's.
fn round_of(i: u32, r: u32, after: u32) {
    let n = params.threads;
    let src = (r % 2u) * n;
    let dst = n - src;
    let x = atomicLoad(&words[src + (i * 37u + r * 101u + 13u + after) % n]);
    let y = atomicLoad(&words[src + (i * 53u + r * 7u + 61u + after) % n]);
    atomicStore(&words[dst + i], mix(x ^ (y + i + r)));
}

@compute @workgroup_size(THREADS)
fn one_round(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < params.threads {
        round_of(id.x, params.round, 0u);
    }
}

@compute @workgroup_size(WALK)
fn walk(@builtin(local_invocation_index) local: u32) {
    for (var r = 0u; r < params.rounds; r++) {
        for (var i = local; i < params.threads; i += WALK) {
            round_of(i, r, 0u);
        }
        storageBarrier();
    }
}

// The arrival count the workgroup's thread 0 saw last, or GAVE_UP.
var<workgroup> seen: u32;
const GAVE_UP: u32 = 0xffffffffu;

@compute @workgroup_size(THREADS)
fn grid(@builtin(local_invocation_index) local: u32, @builtin(workgroup_id) group: vec3<u32>) {
    let i = group.x * THREADS + local;
    var after = 0u;
    for (var r = 0u; r < params.rounds; r++) {
        round_of(i, r, after);
        storageBarrier();
        // The barrier: one load of the counter a spin, and one workgroup barrier after it
        // (the word thread 0 saw); whether another workgroup gave up is looked at only
        // every 4096 spins.
        if local == 0u {
            atomicAdd(&sync[0], 1u);
            let arrived = (r + 1u) * params.workgroups;
            var spins = 0u;
            var count = atomicLoad(&sync[0]);
            while count < arrived {
                count = atomicLoad(&sync[0]);
                spins++;
                if spins % 4096u == 0u && atomicLoad(&sync[1]) != 0u {
                    count = GAVE_UP;
                    break;
                }
                if spins > 4000000u {
                    atomicStore(&sync[1], 1u);
                    count = GAVE_UP;
                    break;
                }
            }
            seen = count;
        }
        let count = workgroupUniformLoad(&seen);
        if count == GAVE_UP {
            return;
        }
        after = (count >> 31u) * (DEPEND);
    }
}
";

/// Mirrors `Params`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    round: u32,
    rounds: u32,
    threads: u32,
    workgroups: u32,
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("grid_rounds: {error}");
            ExitCode::FAILURE
        }
    }
}

fn arg(index: usize, default: u32) -> Result<u32, String> {
    std::env::args().nth(index).map_or(Ok(default), |s| {
        s.parse().map_err(|_| format!("bad number {s:?}"))
    })
}

fn run() -> Result<(), String> {
    let rounds = arg(1, 2000)?;
    let workgroups = arg(2, 64)?;
    let threads = arg(3, 64)?;
    let context = GpuContext::new().map_err(|e| e.to_string())?;
    println!("{}", context.describe());
    for depend in [false, true] {
        let bench = Bench::new(&context, threads, workgroups, depend)?;
        println!("grid rounds' loads depending on the barrier's: {depend}");
        bench.report(rounds)?;
    }
    Ok(())
}

impl Bench<'_> {
    fn report(&self, rounds: u32) -> Result<(), String> {
        let (workgroups, threads, bench) = (self.workgroups, self.threads, self);
        for repeat in 0..3 {
            let (dispatches, reference) = bench.dispatches(rounds)?;
            let (walk, walked) = bench.walk(rounds)?;
            let (grid, gridded, [arrivals, gave_up]) = bench.grid(rounds)?;
            let per = |ms: f64| ms * 1000.0 / f64::from(rounds);
            println!(
                "repeat {repeat}: {rounds} rounds of {} threads ({workgroups} x {threads}); µs a \
             round: dispatches {:.2}, walk (1 x {WALK}) {:.2}{}, grid {:.2}{}{}",
                workgroups * threads,
                per(dispatches),
                per(walk),
                if walked == reference {
                    ""
                } else {
                    " (WORDS DIFFER)"
                },
                per(grid),
                if gridded == reference {
                    ""
                } else {
                    " (WORDS DIFFER)"
                },
                if arrivals != rounds * workgroups || gave_up != 0 {
                    format!(
                        " ({arrivals} of {} arrivals, a spin gave up: {})",
                        rounds * workgroups,
                        gave_up != 0
                    )
                } else {
                    String::new()
                },
            );
        }
        Ok(())
    }
}

/// Threads of the walk's one workgroup.
const WALK: u32 = 256;

struct Bench<'a> {
    context: &'a GpuContext,
    threads: u32,
    workgroups: u32,
    words: wgpu::Buffer,
    sync: wgpu::Buffer,
    readback: wgpu::Buffer,
    layout: wgpu::BindGroupLayout,
    pipelines: [wgpu::ComputePipeline; 3],
}

impl<'a> Bench<'a> {
    fn new(
        context: &'a GpuContext,
        threads: u32,
        workgroups: u32,
        depend: bool,
    ) -> Result<Self, String> {
        let device = &context.device;
        let source = WGSL
            .replace("THREADS", &format!("{threads}u"))
            .replace("WALK", &format!("{WALK}u"))
            .replace("DEPEND", if depend { "1u" } else { "0u" });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("grid_rounds"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        };
        let storage = wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: false },
            has_dynamic_offset: false,
            min_binding_size: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("grid_rounds"),
            entries: &[
                entry(
                    0,
                    wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: true,
                        min_binding_size: None,
                    },
                ),
                entry(1, storage),
                entry(2, storage),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("grid_rounds"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |entry_point| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry_point),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry_point),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let total = u64::from(threads * workgroups);
        let buffer = |label, size, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let storage_usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC;
        Ok(Self {
            context,
            threads,
            workgroups,
            words: buffer("words", 8 * total, storage_usage),
            sync: buffer("sync", 8, storage_usage),
            readback: buffer(
                "readback",
                8 * total + 8,
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
            layout,
            pipelines: [pipeline("one_round"), pipeline("walk"), pipeline("grid")],
        })
    }

    fn total(&self) -> u32 {
        self.threads * self.workgroups
    }

    /// Parameter blocks, 256 bytes apart (dynamic offsets), one a round.
    fn params(&self, rounds: u32) -> wgpu::Buffer {
        let mut bytes = vec![0u8; 256 * rounds.max(1) as usize];
        for round in 0..rounds.max(1) {
            let params = Params {
                round,
                rounds,
                threads: self.total(),
                workgroups: self.workgroups,
            };
            let at = 256 * round as usize;
            bytes[at..at + 16].copy_from_slice(bytemuck::bytes_of(&params));
        }
        let buffer = self.context.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: bytes.len() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.context.queue.write_buffer(&buffer, 0, &bytes);
        buffer
    }

    fn bind_group(&self, params: &wgpu::Buffer) -> wgpu::BindGroup {
        fn whole(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            }
        }
        self.context
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("grid_rounds"),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: params,
                            offset: 0,
                            size: std::num::NonZeroU64::new(16),
                        }),
                    },
                    whole(1, &self.words),
                    whole(2, &self.sync),
                ],
            })
    }

    /// Resets the words (to their index) and the sync words, waits.
    fn reset(&self) -> Result<(), String> {
        let initial: Vec<u32> = (0..2 * self.total()).collect();
        let queue = &self.context.queue;
        queue.write_buffer(&self.words, 0, bytemuck::cast_slice(&initial));
        queue.write_buffer(&self.sync, 0, &[0u8; 8]);
        queue.submit([]);
        self.context.wait().map_err(|e| e.to_string())
    }

    /// Runs `encode` in one compute pass, timed from submit to the end of the wait (ms), then
    /// reads the words and the sync words back.
    fn time(
        &self,
        params: &wgpu::Buffer,
        encode: impl FnOnce(&mut wgpu::ComputePass<'_>, &wgpu::BindGroup),
    ) -> Result<(f64, Vec<u32>), String> {
        self.reset()?;
        let group = self.bind_group(params);
        let device = &self.context.device;
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            encode(&mut pass, &group);
        }
        let command = encoder.finish();
        let start = Instant::now();
        self.context.queue.submit([command]);
        self.context.wait().map_err(|e| e.to_string())?;
        let ms = start.elapsed().as_secs_f64() * 1000.0;
        let mut encoder = device.create_command_encoder(&Default::default());
        let words = 8 * u64::from(self.total());
        encoder.copy_buffer_to_buffer(&self.words, 0, &self.readback, 0, words);
        encoder.copy_buffer_to_buffer(&self.sync, 0, &self.readback, words, 8);
        self.context.queue.submit([encoder.finish()]);
        let slice = self.readback.slice(..);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        self.context.wait().map_err(|e| e.to_string())?;
        let out = {
            let view = slice.get_mapped_range().map_err(|e| e.to_string())?;
            bytemuck::cast_slice(&view).to_vec()
        };
        self.readback.unmap();
        Ok((ms, out))
    }

    fn dispatches(&self, rounds: u32) -> Result<(f64, Vec<u32>), String> {
        let params = self.params(rounds);
        let (ms, out) = self.time(&params, |pass, group| {
            pass.set_pipeline(&self.pipelines[0]);
            for round in 0..rounds {
                pass.set_bind_group(0, group, &[256 * round]);
                pass.dispatch_workgroups(self.workgroups, 1, 1);
            }
        })?;
        Ok((ms, self.words_of(&out)))
    }

    fn walk(&self, rounds: u32) -> Result<(f64, Vec<u32>), String> {
        let params = self.params(rounds);
        let (ms, out) = self.time(&params, |pass, group| {
            pass.set_pipeline(&self.pipelines[1]);
            pass.set_bind_group(0, group, &[0]);
            pass.dispatch_workgroups(1, 1, 1);
        })?;
        Ok((ms, self.words_of(&out)))
    }

    /// Also the arrivals counted and whether a spin gave up.
    fn grid(&self, rounds: u32) -> Result<(f64, Vec<u32>, [u32; 2]), String> {
        let params = self.params(rounds);
        let (ms, out) = self.time(&params, |pass, group| {
            pass.set_pipeline(&self.pipelines[2]);
            pass.set_bind_group(0, group, &[0]);
            pass.dispatch_workgroups(self.workgroups, 1, 1);
        })?;
        let sync = &out[2 * self.total() as usize..];
        Ok((ms, self.words_of(&out), [sync[0], sync[1]]))
    }

    /// Both halves of the words, as the last round left them.
    fn words_of(&self, out: &[u32]) -> Vec<u32> {
        out[..2 * self.total() as usize].to_vec()
    }
}
