//! What can go wrong in the viewer, each message saying how to fix it.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error(transparent)]
    Scene(#[from] tumble::scene::SceneError),
    /// No adapter or device for the physics' GPU stages, which headless pictures draw with too,
    /// or no adapter that can present to the window.
    #[error(transparent)]
    Gpu(#[from] tumble::gpu::GpuError),
    #[error(
        "no display to open a window on ({reason}); render headless instead, e.g. \
         `tumble view {scene} --steps 120 --png {scene}.png` (or --frames DIR for a PNG per step)"
    )]
    NoDisplay { scene: String, reason: String },
    #[error("the adapter {adapter:?} refused to create a device: {reason}")]
    RequestDevice { adapter: String, reason: String },
    #[error(
        "the adapter {adapter:?} cannot render a {width}x{height} image (largest: {limit}); \
         use a smaller --size"
    )]
    TooLarge {
        adapter: String,
        width: u32,
        height: u32,
        limit: u32,
    },
    #[error(
        "the adapter {adapter:?} cannot hold a {size}x{size} shadow map (largest: {limit}); \
         use a smaller --quality shadow-size"
    )]
    ShadowMapTooLarge {
        adapter: String,
        size: u32,
        limit: u32,
    },
    #[error(
        "the adapter {adapter:?} cannot make the renderer: {reason}; pick another with \
         TUMBLE_ADAPTER or WGPU_BACKEND"
    )]
    CreateRenderer { adapter: String, reason: String },
    #[error("the GPU reported an error while rendering on {adapter:?}: {reason}")]
    Render { adapter: String, reason: String },
    #[error("reading the picture back from the GPU failed: {0}")]
    Readback(String),
    #[error("cannot write {path}: {reason}")]
    Write { path: PathBuf, reason: String },
    #[error(transparent)]
    Particles(#[from] tumble::particles::ParticleError),
    #[error(
        "the {scene} scene is drawn headless only: give --png FILE or --frames DIR, e.g. \
         `tumble view {scene} --scale 0.01 --steps 600 --png {scene}.png`"
    )]
    HeadlessOnly { scene: String },
    #[error("{flag} draws what a rigid-body world has; the particle demo has none of it")]
    NotForParticles { flag: &'static str },
    #[error("cannot open a window: {0}")]
    Window(String),
    #[error("cannot draw into the window: {0}")]
    Surface(String),
}
