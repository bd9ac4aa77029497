//! The engine's integration tests, one module per subject, in one binary: one link instead of
//! forty keeps `cargo test` fast and its build small. The host-memory tests stay binaries of
//! their own because they cap the whole process's address space.

mod batches;
mod common;
mod compound;
mod convex_oracle;
mod determinism;
mod drag;
mod friction;
mod gpu_batching;
mod gpu_bitonic_sort;
mod gpu_broadphase;
mod gpu_common;
mod gpu_compact;
mod gpu_context;
mod gpu_integrate;
mod gpu_joint_rows;
mod gpu_joints;
mod gpu_layout;
mod gpu_narrowphase;
mod gpu_particles;
mod gpu_profiler;
mod gpu_radix_sort;
mod gpu_reduce;
mod gpu_scan;
mod gpu_scenes;
mod gpu_solver;
mod gpu_solver_world;
mod gpu_stages;
mod gpu_windows;
mod hulls;
mod jacobi;
mod joints;
mod landscape;
mod ragdolls;
mod rest;
mod restitution;
mod rigid_particles;
mod scene_errors;
mod scene_meshes;
mod shape_cast_oracle;
mod sleep;
mod stacks;
mod trimesh_floor;
