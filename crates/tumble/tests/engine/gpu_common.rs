//! Helpers shared by the GPU test files: the shared context and a seeded random generator.

#![allow(dead_code)] // each test file uses a different subset

use std::sync::{Mutex, MutexGuard};

use tumble::gpu::GpuContext;

/// Sizes every parity test runs: empty, one, around one workgroup, past one level of blocks.
pub const SIZES: [usize; 6] = [0, 1, 255, 256, 257, 65_537];
/// The large size, run once per primitive to keep the suite short on CPU drivers.
pub const LARGE: usize = 1_000_003;

/// The shared context, held by one test at a time: wgpu's GL backend locks its context
/// around every call and gives up (panics) after a second, which a long dispatch on llvmpipe
/// in a parallel test thread exceeds.
pub struct Gpu {
    context: GpuContext,
    _turn: MutexGuard<'static, ()>,
}

impl std::ops::Deref for Gpu {
    type Target = GpuContext;

    fn deref(&self) -> &GpuContext {
        &self.context
    }
}

pub fn context() -> Gpu {
    static TURN: Mutex<()> = Mutex::new(());
    // A test that panicked while holding the turn leaves nothing half-done behind.
    let turn = TURN.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    let context =
        GpuContext::shared().unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
    Gpu {
        context,
        _turn: turn,
    }
}

/// xorshift64*: deterministic inputs without a dependency.
pub struct Random(u64);

impl Random {
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    pub fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }

    pub fn below(&mut self, bound: u32) -> u32 {
        ((u64::from(self.next_u32()) * u64::from(bound)) >> 32) as u32
    }

    pub fn u32s(&mut self, count: usize) -> Vec<u32> {
        (0..count).map(|_| self.next_u32()).collect()
    }

    pub fn u32s_below(&mut self, count: usize, bound: u32) -> Vec<u32> {
        (0..count).map(|_| self.below(bound)).collect()
    }
}
