//! GPU batching against the CPU executor: the same colors, bit for bit, for both batchers on
//! random constraint graphs of edge sizes, and the batches' guarantees on the GPU's output.

use crate::gpu_common;

use tumble::gpu::buffer::GpuVec;
use tumble::stages::batching::gpu::GpuBatching;
use tumble::stages::batching::layout::{GpuBatchLayout, LAYOUT_BATCHES, USED_END};
use tumble::stages::batching::{
    Batcher, Coloring, MAX_COLORS, MAX_ROUNDS, batch_order, color_constraints,
};
use tumble::stages::constraints::STATIC_BODY;

/// Deterministic pseudo-random numbers (xorshift).
fn next(state: &mut u64) -> u64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    *state
}

/// `count` constraints among `bodies` bodies; a quarter against a static body.
fn random_edges(state: &mut u64, bodies: usize, count: usize) -> Vec<(u32, u32)> {
    (0..count)
        .map(|_| {
            let a = (next(state) % bodies as u64) as u32;
            let b = (next(state) % bodies as u64) as u32;
            if next(state).is_multiple_of(4) || a == b {
                (STATIC_BODY, a)
            } else {
                (a, b)
            }
        })
        .collect()
}

#[test]
fn gpu_colors_equal_cpu_colors() {
    let context = gpu_common::context();
    let mut gpu = GpuBatching::new(&context).unwrap();
    let mut state = 0x9e37_79b9_7f4a_7c15;
    // A star of 70 constraints on body 0 overflows (one wins per round).
    let star: Vec<(u32, u32)> = (1..=70).map(|other| (0, other)).collect();
    let mut graphs = vec![(71, star)];
    for &(bodies, count) in &[
        (1usize, 0usize),
        (1, 1),
        (2, 1),
        (10, 255),
        (100, 257),
        (3000, 12_001),
        (50_000, 200_003),
        (300_000, 1_000_000),
    ] {
        graphs.push((bodies, random_edges(&mut state, bodies, count)));
    }
    for batcher in Batcher::ALL {
        for (bodies, edges) in &graphs {
            let mut cpu = Coloring::default();
            // A tenth of each set ranks by index, as the joints do in a step.
            let ordered = edges.len() / 10;
            color_constraints(edges.iter().copied(), *bodies, ordered, batcher, &mut cpu);
            let mut from_gpu = Coloring::default();
            gpu.run(
                &context,
                edges.iter().copied(),
                *bodies,
                ordered,
                batcher,
                MAX_ROUNDS,
                &mut from_gpu,
            )
            .unwrap();
            let size = edges.len();
            assert_eq!(from_gpu.colors.len(), size, "{batcher} {size}");
            if let Some(i) = (0..size).find(|&i| from_gpu.colors[i] != cpu.colors[i]) {
                panic!(
                    "{batcher}, {size} constraints: constraint {i} colored {} on the GPU, {} on the CPU",
                    from_gpu.colors[i], cpu.colors[i]
                );
            }
            assert_eq!(from_gpu.histogram, cpu.histogram, "{batcher} {size}");
            assert_eq!(from_gpu.has_overflow, cpu.has_overflow);
            assert_eq!(from_gpu.rounds, cpu.rounds, "{batcher} {size}: rounds");
            // The colors are valid batches: no dynamic body twice in a normal batch.
            let mut owner = vec![u8::MAX; *bodies];
            for color in 0..MAX_COLORS as u8 {
                for (i, &(a, b)) in edges.iter().enumerate() {
                    if from_gpu.colors[i] != color {
                        continue;
                    }
                    for body in [a, b].into_iter().filter(|&body| body != STATIC_BODY) {
                        assert_ne!(owner[body as usize], color, "body {body} twice in {color}");
                        owner[body as usize] = color;
                    }
                }
            }
        }
    }
    // The star overflows with both batchers.
    let mut star = Coloring::default();
    gpu.run(
        &context,
        graphs[0].1.iter().copied(),
        71,
        0,
        Batcher::Colors,
        MAX_ROUNDS,
        &mut star,
    )
    .unwrap();
    assert!(star.has_overflow);
    assert_eq!(star.histogram.last(), Some(&6));
}

/// However many rounds get dispatches of their own, the ones after them (one workgroup's
/// `rest_rounds`) give the colors and round count of every round dispatched: what the step
/// does when it encodes the rounds the last step needed and a few more.
#[test]
fn rounds_left_to_one_workgroup_give_the_same_colors() {
    let context = gpu_common::context();
    let mut gpu = GpuBatching::new(&context).unwrap();
    let mut state = 0x5eed_u64;
    let edges = random_edges(&mut state, 400, 3000);
    for batcher in Batcher::ALL {
        let run = |gpu: &mut GpuBatching, rounds| {
            let mut coloring = Coloring::default();
            let edges = edges.iter().copied();
            gpu.run(&context, edges, 400, 30, batcher, rounds, &mut coloring)
                .unwrap();
            coloring
        };
        let whole = run(&mut gpu, MAX_ROUNDS);
        assert!(whole.rounds > 3, "{batcher}: {} rounds", whole.rounds);
        for rounds in [0, 2, whole.rounds / 2, whole.rounds - 1, whole.rounds] {
            let parts = run(&mut gpu, rounds);
            assert_eq!(parts.colors, whole.colors, "{batcher}, {rounds} rounds");
            assert_eq!(
                parts.histogram, whole.histogram,
                "{batcher}, {rounds} rounds"
            );
            assert_eq!(parts.rounds, whole.rounds, "{batcher}, {rounds} rounds");
        }
    }
}

/// The device's batch layout of the GPU's colors is the host's `batch_order` of them, bit for
/// bit: the same order, each used color's batch at the host's offsets, the overflow batch last,
/// and the end of the used batches (sizes at the edges of the layout's blocks).
#[test]
fn device_layout_is_the_hosts_batch_order() {
    let context = gpu_common::context();
    let mut gpu = GpuBatching::new(&context).unwrap();
    let mut layout = GpuBatchLayout::new(&context).unwrap();
    let mut order = GpuVec::<u32>::with_capacity(&context, "test order", 0).unwrap();
    let mut state = 0x1a70_u64;
    let star: Vec<(u32, u32)> = (1..=70).map(|other| (0, other)).collect();
    let mut graphs = vec![(71, star)];
    for &(bodies, count) in &[
        (1usize, 0usize),
        (2, 1),
        (10, 255),
        (100, 256),
        (100, 257),
        (3000, 12_001),
        (50_000, 200_003),
        (300_000, 1_000_000),
        (3000, 12_001),
    ] {
        graphs.push((bodies, random_edges(&mut state, bodies, count)));
    }
    for (bodies, edges) in &graphs {
        let mut coloring = Coloring::default();
        let size = edges.len();
        gpu.run(
            &context,
            edges.iter().copied(),
            *bodies,
            0,
            Batcher::Colors,
            MAX_ROUNDS,
            &mut coloring,
        )
        .unwrap();
        let (mut host_order, mut host_offsets) = (Vec::new(), Vec::new());
        batch_order(
            &coloring.colors,
            &coloring,
            &mut host_order,
            &mut host_offsets,
        );
        order.resize(&context, size).unwrap();
        context
            .submit_pass("layout", |pass| {
                layout.encode(&context, pass, gpu.tally(), &gpu.colors, &order)
            })
            .unwrap();
        let device_order = order.download(&context).unwrap();
        let offsets = layout.offsets.download(&context).unwrap();
        assert_eq!(device_order, host_order, "{size} constraints: the order");
        // Host batch b is color b, the overflow batch (the host's last) is color MAX_COLORS.
        let used = coloring.batch_count - coloring.has_overflow as usize;
        for batch in 0..LAYOUT_BATCHES {
            let (start, end) = (offsets[batch], offsets[batch + 1]);
            let expected = if batch < used {
                (host_offsets[batch], host_offsets[batch + 1])
            } else if batch == MAX_COLORS && coloring.has_overflow {
                let last = coloring.batch_count;
                (host_offsets[last - 1], host_offsets[last])
            } else {
                (start, start)
            };
            assert_eq!((start, end), expected, "{size} constraints: batch {batch}");
        }
        assert_eq!(offsets[LAYOUT_BATCHES], size as u32);
        let used_end = if coloring.has_overflow {
            LAYOUT_BATCHES
        } else {
            used
        };
        assert_eq!(offsets[USED_END], used_end as u32, "{size} constraints");
    }
}

/// The body adjacency the warm start gathers by, from the GPU's colors, masks and layout, is
/// the host's: for each body, its constraints' sides in batch order (entry 2 p + side for the
/// constraint at batch place p), overflow ones last, for both batchers, with an overflow hub.
#[test]
fn body_adjacency_lists_each_bodys_constraints_in_batch_order() {
    use tumble::stages::solver::adjacency::{AdjacencyInputs, GpuBodyAdjacency};
    let context = gpu_common::context();
    let mut gpu = GpuBatching::new(&context).unwrap();
    let mut layout = GpuBatchLayout::new(&context).unwrap();
    let mut adjacency = GpuBodyAdjacency::new(&context).unwrap();
    let mut order = GpuVec::<u32>::with_capacity(&context, "test order", 0).unwrap();
    let mut state = 0xad1a_u64;
    // Body 0 is a hub of 80 constraints: 64 colors, then the overflow batch.
    let mut hub: Vec<(u32, u32)> = (1..=80).map(|other| (0, other)).collect();
    hub.extend(random_edges(&mut state, 81, 300));
    for batcher in Batcher::ALL {
        for (bodies, edges) in [
            (81, hub.clone()),
            (3000, random_edges(&mut state, 3000, 12_001)),
        ] {
            let mut coloring = Coloring::default();
            gpu.run(
                &context,
                edges.iter().copied(),
                bodies,
                0,
                batcher,
                MAX_ROUNDS,
                &mut coloring,
            )
            .unwrap();
            let row_bodies: Vec<[u32; 2]> = edges.iter().map(|&(a, b)| [a, b]).collect();
            let row_bodies = GpuVec::from_slice(&context, "test row bodies", &row_bodies).unwrap();
            order.resize(&context, edges.len()).unwrap();
            context
                .submit_pass("layout and adjacency", |pass| {
                    layout.encode(&context, pass, gpu.tally(), &gpu.colors, &order)?;
                    let inputs = AdjacencyInputs {
                        masks: gpu.masks(),
                        colors: &gpu.colors,
                        order: &order,
                        row_bodies: &row_bodies,
                        offsets: &layout.offsets,
                    };
                    adjacency.encode(&context, pass, &inputs, bodies, order.capacity())
                })
                .unwrap();
            let (mut host_order, mut host_offsets) = (Vec::new(), Vec::new());
            batch_order(
                &coloring.colors,
                &coloring,
                &mut host_order,
                &mut host_offsets,
            );
            let mut lists = vec![Vec::new(); bodies];
            for (place, &row) in host_order.iter().enumerate() {
                let (a, b) = edges[row as usize];
                for (side, body) in [(0, a), (1, b)] {
                    if body != STATIC_BODY {
                        lists[body as usize].push(2 * place as u32 + side);
                    }
                }
            }
            let starts = adjacency.starts.download(&context).unwrap();
            let entries = adjacency.entries.download(&context).unwrap();
            assert!(coloring.has_overflow || bodies > 81, "the hub overflows");
            for (body, list) in lists.iter().enumerate() {
                let (start, end) = (starts[body] as usize, starts[body + 1] as usize);
                assert_eq!(
                    &entries[start..end],
                    &list[..],
                    "{batcher}, {bodies} bodies: body {body}"
                );
            }
        }
    }
}
