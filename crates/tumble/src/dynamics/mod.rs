//! Body data: what the solver and integrator read and write each step.

pub mod body;
pub mod island;
pub mod island_gpu;
pub mod joint;
pub mod rest_gpu;
pub mod wake;
