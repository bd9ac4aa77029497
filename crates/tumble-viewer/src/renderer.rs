//! The renderer: pipelines, meshes and per-frame buffers on a device it is given, so the same
//! code draws into a window's surface and into an offscreen texture, and on the physics'
//! device from its buffers.
//!
//! A frame is a few render passes. The shadow pass draws every solid mesh's depth as the light
//! sees it (an orthographic view along the light over the bodies' bounds) into the shadow map.
//! Then, with [`Quality::depth_prepass`], a pass draws the depth of every surface. The meshes
//! pass draws every mesh instanced once (solid triangles, or its edges as lines in wireframe
//! mode) and contact segments as lines, then joints and the drag as lines over it all (at the
//! near plane's depth, so that the ground drawn after them leaves them be), the ground pass
//! the ground grids (after the meshes, so that the ground hidden by bodies is never shaded;
//! before them in [`DrawOrder::Submitted`]), and the overlay pass the text on top. The first
//! of them clears. Lit surfaces look their point up in the shadow map. When the step ran on
//! this device, a compute pass first writes the bodies' instance models from the physics'
//! pose buffers (pose.wgsl).
//! Triangle meshes are drawn from both sides, as the physics collides with both.
//! Each pass is timed on the GPU where the device has timestamp queries and
//! [`Renderer::time_passes`] asked for it.

use std::collections::BTreeMap;
use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};
use tumble::pipeline::world::DevicePoses;
use wgpu::util::DeviceExt;

use crate::camera::Camera;
use crate::context::GpuContext;
use crate::draw::{BACKGROUND, DrawList, GroundQuad, Instance, MeshKey, NO_BODY, PoseLink};
use crate::error::ViewError;
use crate::font::{CELL_HEIGHT, CELL_WIDTH, GLYPH_COUNT, GLYPH_HEIGHT, GLYPH_WIDTH};
use crate::mesh::{MeshData, Vertex};
use crate::overlay::{PANEL, TextQuad};
use crate::quality::{DrawOrder, Quality};
use crate::timing::PassTimer;

pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Towards the light (normalized before use): high and to the right of the default camera, so
/// the three faces of a box it sees get three different shades (top, right, front).
pub const LIGHT_DIRECTION: Vec3 = Vec3::new(0.5, 0.8, 0.3);
/// Light reaching a surface facing away from the light, and the Lambert weight on top.
const AMBIENT: f32 = 0.3;
const DIFFUSE: f32 = 0.7;
/// Shadow acne: depth bias of the shadow pass (in units of the depth format's precision and
/// of the triangle's depth slope) and the push of a lit point along its normal, in shadow map
/// texels.
const SHADOW_DEPTH_BIAS: wgpu::DepthBiasState = wgpu::DepthBiasState {
    constant: 2,
    slope_scale: 2.0,
    clamp: 0.0,
};
const SHADOW_NORMAL_OFFSET_TEXELS: f32 = 1.5;
/// Invocations per workgroup of the pose pass (pose.wgsl).
const POSE_WORKGROUP_SIZE: u32 = 64;
/// Grid lines on ground planes every GRID_SPACING metres.
const GRID_SPACING: f32 = 1.0;
const GROUND_COLOUR: [f32; 3] = [0.42, 0.42, 0.40];
const LINE_COLOUR: [f32; 3] = [0.18, 0.18, 0.18];

// repr(C) + Pod: the uniform buffer's bytes; mirrors `Globals` in common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Globals {
    view_projection: [[f32; 4]; 4],
    light_view_projection: [[f32; 4]; 4],
    light_direction: [f32; 4],
    lighting: [f32; 4],
    shadow: [f32; 4],
    viewport: [f32; 4],
}

const _: () = assert!(size_of::<Globals>() == 192);

// repr(C) + Pod: the ground vertex buffer's bytes; mirrors `VertexIn` in grid.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct GridVertex {
    position: [f32; 3],
    normal: [f32; 3],
    plane: [f32; 2],
}

const _: () = assert!(size_of::<GridVertex>() == 32);

/// A mesh on the GPU; index buffers are absent where the mesh has no such primitives.
struct GpuMesh {
    vertices: wgpu::Buffer,
    triangles: Option<(wgpu::Buffer, u32)>,
    lines: Option<(wgpu::Buffer, u32)>,
}

/// A buffer written from the host that grows (to the next power of two) and never shrinks.
struct GrowingBuffer {
    label: &'static str,
    usage: wgpu::BufferUsages,
    buffer: wgpu::Buffer,
}

impl GrowingBuffer {
    fn new(device: &wgpu::Device, label: &'static str, usage: wgpu::BufferUsages) -> Self {
        Self {
            label,
            usage,
            buffer: Self::create(device, label, usage, 4096),
        }
    }

    fn create(
        device: &wgpu::Device,
        label: &'static str,
        usage: wgpu::BufferUsages,
        size: u64,
    ) -> wgpu::Buffer {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: usage | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    fn write(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, bytes: &[u8]) {
        let needed = bytes.len() as u64;
        if needed > self.buffer.size() {
            self.buffer = Self::create(device, self.label, self.usage, needed.next_power_of_two());
        }
        if !bytes.is_empty() {
            queue.write_buffer(&self.buffer, 0, bytes);
        }
    }
}

pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    globals: wgpu::Buffer,
    /// Group 0: the globals, for every pipeline.
    globals_bind_group: wgpu::BindGroup,
    /// Group 1: the shadow map and the font, for the frame pass (not the shadow pass, which
    /// writes the map).
    textures_bind_group: wgpu::BindGroup,
    shadow_map: wgpu::TextureView,
    shadow_pipeline: wgpu::RenderPipeline,
    solid_pipeline: wgpu::RenderPipeline,
    two_sided_pipeline: wgpu::RenderPipeline,
    line_pipeline: wgpu::RenderPipeline,
    /// Lines over the scene ([`MeshKey::over_scene`]), drawn after every other mesh.
    over_scene_pipeline: wgpu::RenderPipeline,
    grid_pipeline: wgpu::RenderPipeline,
    text_pipeline: wgpu::RenderPipeline,
    /// Writes instance models from the physics' device buffers; made on first use, so that a
    /// device that is never given them needs no compute support.
    pose_pipeline: Option<wgpu::ComputePipeline>,
    meshes: BTreeMap<MeshKey, GpuMesh>,
    instances: GrowingBuffer,
    /// Each instance's body, for `pose_pipeline`.
    links: GrowingBuffer,
    ground: GrowingBuffer,
    text: GrowingBuffer,
    /// This frame's instance range of each mesh.
    draws: Vec<(MeshKey, Range<u32>)>,
    ground_vertices: u32,
    text_quads: u32,
    wireframe: bool,
    /// Whether this frame has a shadow caster (and so a light view to draw the map from).
    shadows: bool,
    /// Side of the square shadow map in texels.
    shadow_map_size: u32,
    order: DrawOrder,
    /// Depth-only pipelines, with [`Quality::depth_prepass`].
    prepass: Option<Prepass>,
    /// The pose pass's bindings, kept while its buffers stay the same.
    pose_binding: Option<PoseBinding>,
    timer: Option<PassTimer>,
}

/// The depth pre-pass's pipelines: the frame pipelines' vertex stages, no fragment stage.
struct Prepass {
    culled: wgpu::RenderPipeline,
    two_sided: wgpu::RenderPipeline,
    ground: wgpu::RenderPipeline,
}

/// The pose pass's bind group and what it binds: the physics' poses, the links and the
/// instances (the last two grow), and how many links.
struct PoseBinding {
    buffers: [wgpu::Buffer; 3],
    links: usize,
    bind_group: wgpu::BindGroup,
}

/// A colour pass of the frame, after the shadow map and the depth pre-pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ColourPass {
    Meshes,
    Ground,
    Overlay,
}

impl Renderer {
    /// Pipelines on `context`'s device for colour targets of `format` (an sRGB format: shading
    /// is in linear RGB), drawing with `quality`'s choices. An adapter that cannot make them (a
    /// shadow map over its largest texture, a target format it cannot render to, a shader or
    /// pipeline it rejects) is an error, not a panic.
    pub fn new(
        context: &GpuContext,
        format: wgpu::TextureFormat,
        quality: Quality,
    ) -> Result<Self, ViewError> {
        let limit = context.device.limits().max_texture_dimension_2d;
        if quality.shadow_map_size > limit {
            return Err(ViewError::ShadowMapTooLarge {
                adapter: context.describe(),
                size: quality.shadow_map_size,
                limit,
            });
        }
        context.creating(|| Self::create(&context.device, &context.queue, format, quality))
    }

    fn create(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        format: wgpu::TextureFormat,
        quality: Quality,
    ) -> Self {
        let common = format!(
            "const SHADOW_FILTER: u32 = {}u;\n{}",
            quality.shadow_filter.wgsl(),
            include_str!("common.wgsl")
        );
        let shadow_map_size = quality.shadow_map_size;
        let mesh_source = format!("{common}\n{}", include_str!("mesh.wgsl"));
        let [gr, gg, gb] = GROUND_COLOUR;
        let [lr, lg, lb] = LINE_COLOUR;
        let grid_source = format!(
            "{common}\nconst GRID_SPACING: f32 = {GRID_SPACING:?};\n\
             const GROUND_COLOUR: vec3<f32> = vec3<f32>({gr:?}, {gg:?}, {gb:?});\n\
             const LINE_COLOUR: vec3<f32> = vec3<f32>({lr:?}, {lg:?}, {lb:?});\n{}",
            include_str!("grid.wgsl")
        );
        let text_source = format!(
            "{common}\nconst CELL_WIDTH: u32 = {CELL_WIDTH}u;\nconst CELL_HEIGHT: u32 = \
             {CELL_HEIGHT}u;\nconst GLYPH_WIDTH: u32 = {GLYPH_WIDTH}u;\nconst GLYPH_HEIGHT: u32 \
             = {GLYPH_HEIGHT}u;\nconst PANEL: u32 = {PANEL}u;\n{}",
            include_str!("text.wgsl")
        );
        let shader = |label: &str, source: String| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
        };
        let mesh_shader = shader("mesh.wgsl", mesh_source);
        let grid_shader = shader("grid.wgsl", grid_source);
        let text_shader = shader("text.wgsl", text_source);

        let globals = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("globals"),
            size: size_of::<Globals>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let globals_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("globals"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let globals_bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("globals"),
            layout: &globals_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: globals.as_entire_binding(),
            }],
        });

        let shadow_map = device
            .create_texture(&wgpu::TextureDescriptor {
                label: Some("shadow map"),
                size: wgpu::Extent3d {
                    width: shadow_map_size,
                    height: shadow_map_size,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: DEPTH_FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            })
            .create_view(&Default::default());
        // Linear filtering of the comparisons: each bilinear tap of the shader is itself a
        // blend of four (gathers ignore the filter and weigh the four in the shader).
        let shadow_sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("shadow"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            compare: Some(wgpu::CompareFunction::LessEqual),
            ..Default::default()
        });
        let font = upload_font(device, queue);
        let texture_entry = |binding: u32, ty: wgpu::BindingType| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty,
            count: None,
        };
        let textures_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("textures"),
            entries: &[
                texture_entry(
                    0,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                ),
                texture_entry(
                    1,
                    wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Comparison),
                ),
                texture_entry(
                    2,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: true },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                ),
            ],
        });
        let textures_bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("textures"),
            layout: &textures_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&shadow_map),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Sampler(&shadow_sampler),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(&font),
                },
            ],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("viewer"),
            bind_group_layouts: &[Some(&globals_layout), Some(&textures_layout)],
            immediate_size: 0,
        });
        // The shadow and depth pre-pass pipelines read only the globals.
        let shadow_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("depth only"),
            bind_group_layouts: &[Some(&globals_layout)],
            immediate_size: 0,
        });

        let mesh_buffers = [
            Some(wgpu::VertexBufferLayout {
                array_stride: size_of::<Vertex>() as u64,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3],
            }),
            Some(wgpu::VertexBufferLayout {
                array_stride: size_of::<Instance>() as u64,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &wgpu::vertex_attr_array![
                    2 => Float32x4, 3 => Float32x4, 4 => Float32x4, 5 => Float32x4, 6 => Float32x4
                ],
            }),
        ];
        let grid_buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: size_of::<GridVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2],
        })];
        let text_buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: size_of::<TextQuad>() as u64,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &wgpu::vertex_attr_array![
                0 => Float32x2, 1 => Float32x2, 2 => Float32x4, 3 => Uint32
            ],
        })];
        let depth_test = wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::LessEqual),
            stencil: Default::default(),
            bias: Default::default(),
        };
        let pipeline = |label: &str,
                        shader: &wgpu::ShaderModule,
                        vertex: &str,
                        fragment: &str,
                        buffers: &[Option<wgpu::VertexBufferLayout>],
                        topology: wgpu::PrimitiveTopology,
                        cull_mode: Option<wgpu::Face>| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: shader,
                    entry_point: Some(vertex),
                    compilation_options: Default::default(),
                    buffers,
                },
                primitive: wgpu::PrimitiveState {
                    topology,
                    front_face: wgpu::FrontFace::Ccw,
                    cull_mode,
                    ..Default::default()
                },
                depth_stencil: Some(depth_test.clone()),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: shader,
                    entry_point: Some(fragment),
                    compilation_options: Default::default(),
                    targets: &[Some(format.into())],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let solid_pipeline = pipeline(
            "solid",
            &mesh_shader,
            "vs_main",
            "fs_solid",
            &mesh_buffers,
            wgpu::PrimitiveTopology::TriangleList,
            Some(wgpu::Face::Back),
        );
        // A triangle mesh is an open surface (a landscape, a floor): no side of it is hidden
        // by the rest of it, and a camera under a floor still sees the floor.
        let two_sided_pipeline = pipeline(
            "two-sided",
            &mesh_shader,
            "vs_main",
            "fs_two_sided",
            &mesh_buffers,
            wgpu::PrimitiveTopology::TriangleList,
            None,
        );
        let line_pipeline = pipeline(
            "lines",
            &mesh_shader,
            "vs_main",
            "fs_line",
            &mesh_buffers,
            wgpu::PrimitiveTopology::LineList,
            None,
        );
        // Joints and the drag: their anchors lie inside the bodies they join (draw.rs).
        let over_scene_pipeline = pipeline(
            "constraints",
            &mesh_shader,
            "vs_over_scene",
            "fs_line",
            &mesh_buffers,
            wgpu::PrimitiveTopology::LineList,
            None,
        );
        // Planes are seen from both sides (a camera may dip below the ground).
        let grid_pipeline = pipeline(
            "grid",
            &grid_shader,
            "vs_main",
            "fs_main",
            &grid_buffers,
            wgpu::PrimitiveTopology::TriangleList,
            None,
        );
        let depth_only = |label: &str,
                          shader: &wgpu::ShaderModule,
                          entry_point: &str,
                          buffers: &[Option<wgpu::VertexBufferLayout>],
                          cull_mode: Option<wgpu::Face>,
                          bias: wgpu::DepthBiasState| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&shadow_layout),
                vertex: wgpu::VertexState {
                    module: shader,
                    entry_point: Some(entry_point),
                    compilation_options: Default::default(),
                    buffers,
                },
                primitive: wgpu::PrimitiveState {
                    cull_mode,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    bias,
                    ..depth_test.clone()
                }),
                multisample: Default::default(),
                fragment: None,
                multiview_mask: None,
                cache: None,
            })
        };
        // Both faces cast: triangle meshes are open, and the bias handles the lit faces.
        let shadow_pipeline = depth_only(
            "shadow",
            &mesh_shader,
            "vs_shadow",
            &mesh_buffers,
            None,
            SHADOW_DEPTH_BIAS,
        );
        // The frame's own vertex stages (their positions are @invariant), so that the colour
        // passes' fragments meet the depth the pre-pass wrote exactly.
        let prepass = quality.depth_prepass.then(|| Prepass {
            culled: depth_only(
                "prepass",
                &mesh_shader,
                "vs_main",
                &mesh_buffers,
                Some(wgpu::Face::Back),
                Default::default(),
            ),
            two_sided: depth_only(
                "prepass two-sided",
                &mesh_shader,
                "vs_main",
                &mesh_buffers,
                None,
                Default::default(),
            ),
            ground: depth_only(
                "prepass ground",
                &grid_shader,
                "vs_main",
                &grid_buffers,
                None,
                Default::default(),
            ),
        });
        // Text lies on top of everything and blends its panel over the scene.
        let text_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("text"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &text_shader,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &text_buffers,
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(wgpu::DepthStencilState {
                depth_write_enabled: Some(false),
                depth_compare: Some(wgpu::CompareFunction::Always),
                ..depth_test
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &text_shader,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format,
                    blend: Some(wgpu::BlendState::ALPHA_BLENDING),
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });

        Self {
            device: device.clone(),
            queue: queue.clone(),
            globals,
            globals_bind_group,
            textures_bind_group,
            shadow_map,
            shadow_pipeline,
            solid_pipeline,
            two_sided_pipeline,
            line_pipeline,
            over_scene_pipeline,
            grid_pipeline,
            text_pipeline,
            pose_pipeline: None,
            meshes: BTreeMap::new(),
            // Storage too: the pose pass writes the models in place.
            instances: GrowingBuffer::new(
                device,
                "instances",
                wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE,
            ),
            links: GrowingBuffer::new(device, "pose links", wgpu::BufferUsages::STORAGE),
            ground: GrowingBuffer::new(device, "ground", wgpu::BufferUsages::VERTEX),
            text: GrowingBuffer::new(device, "text", wgpu::BufferUsages::VERTEX),
            draws: Vec::new(),
            ground_vertices: 0,
            text_quads: 0,
            wireframe: false,
            shadows: false,
            order: quality.order,
            prepass,
            pose_binding: None,
            timer: None,
            shadow_map_size,
        }
    }

    /// Times each pass of every later frame on the GPU ([`Self::pass_times`]); false (and no
    /// timing) where the device has no timestamp queries.
    pub fn time_passes(&mut self) -> bool {
        self.timer = PassTimer::new(&self.device, &self.queue);
        self.timer.is_some()
    }

    /// The GPU time (ms) of each pass of the last frame encoded, in order, once it is done
    /// (this waits for it); `None` without [`Self::time_passes`].
    pub fn pass_times(&self) -> Result<Option<Vec<(&'static str, f64)>>, ViewError> {
        self.timer
            .as_ref()
            .map(|timer| timer.read(&self.device))
            .transpose()
    }

    /// Uploads what `list` draws, seen by `camera` on a viewport of `width` × `height` pixels.
    /// With `device_poses` (a GPU step's buffers on this renderer's device), the bodies are
    /// drawn at the poses in those buffers, not at the models in `list`.
    pub fn prepare(
        &mut self,
        list: &DrawList,
        camera: &Camera,
        (width, height): (u32, u32),
        device_poses: Option<DevicePoses>,
    ) {
        if let Some(timer) = &mut self.timer {
            timer.start_frame();
        }
        let light = LIGHT_DIRECTION.normalize();
        // Solid meshes cast shadows; wireframes are lines, which would cast none.
        let shadow_view = list
            .shadow_bounds
            .filter(|_| !list.wireframe)
            .map(|(center, radius)| {
                light_view_projection(light, center, radius, self.shadow_map_size)
            });
        self.shadows = shadow_view.is_some();
        let (light_view_projection, shadow) = match shadow_view {
            Some((matrix, texel)) => (
                matrix,
                [
                    self.shadow_map_size as f32,
                    SHADOW_NORMAL_OFFSET_TEXELS * texel,
                    0.0,
                    0.0,
                ],
            ),
            None => (Mat4::IDENTITY, [0.0; 4]),
        };
        let globals = Globals {
            view_projection: camera
                .view_projection(width as f32 / height as f32)
                .to_cols_array_2d(),
            light_view_projection: light_view_projection.to_cols_array_2d(),
            light_direction: light.extend(0.0).to_array(),
            lighting: [AMBIENT, DIFFUSE, 0.0, 0.0],
            shadow,
            viewport: [width as f32, height as f32, 0.0, 0.0],
        };
        self.queue
            .write_buffer(&self.globals, 0, bytemuck::bytes_of(&globals));

        let mut instances: Vec<Instance> = Vec::new();
        let mut links: Vec<PoseLink> = Vec::new();
        let mut order: Vec<(f32, u32)> = Vec::new();
        let eye = camera.eye();
        self.draws.clear();
        for (&key, group) in &list.instances {
            if !self.meshes.contains_key(&key) {
                let mesh = upload_mesh(&self.device, &mesh_data(key, list));
                self.meshes.insert(key, mesh);
            }
            let group_links = list.links.get(&key).map_or(&[][..], Vec::as_slice);
            debug_assert_eq!(group_links.len(), group.len(), "{key:?}");
            // Nearest first, by the distance of the instance's origin from the eye (the host's
            // poses, also when the device's are drawn: the order needs only be nearly right).
            // A stable sort on a total order: the same frame is drawn the same way every time.
            order.clear();
            order.extend(group.iter().enumerate().map(|(i, instance)| {
                let origin = Vec3::from_slice(&instance.model[3][..3]);
                (origin.distance_squared(eye), i as u32)
            }));
            if self.order == DrawOrder::FrontToBack {
                order.sort_by(|a, b| a.0.total_cmp(&b.0));
            }
            let start = instances.len() as u32;
            instances.extend(order.iter().map(|&(_, i)| group[i as usize]));
            if !group_links.is_empty() {
                links.extend(order.iter().map(|&(_, i)| group_links[i as usize]));
            }
            self.draws.push((key, start..instances.len() as u32));
        }
        self.instances
            .write(&self.device, &self.queue, bytemuck::cast_slice(&instances));
        if let Some(poses) = device_poses {
            self.pose_instances(&links, poses);
        }

        let ground: Vec<GridVertex> = list.grounds.iter().flat_map(ground_vertices).collect();
        self.ground
            .write(&self.device, &self.queue, bytemuck::cast_slice(&ground));
        self.ground_vertices = ground.len() as u32;

        let text = crate::overlay::layout(&list.overlay, height);
        self.text
            .write(&self.device, &self.queue, bytemuck::cast_slice(&text));
        self.text_quads = text.len() as u32;
        self.wireframe = list.wireframe;
    }

    /// Records the frame prepared last into `encoder`: the shadow map, then clears `color` and
    /// `depth` (a [`DEPTH_FORMAT`] view of the same size) and draws; with pass timing, resolves
    /// the frame's timestamps last.
    pub fn encode(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) {
        if self.shadows {
            self.encode_shadows(encoder);
        }
        let prepass = self.prepass.is_some() && !self.wireframe;
        if prepass {
            self.encode_prepass(encoder, depth);
        }
        let ground = (self.ground_vertices > 0).then_some(ColourPass::Ground);
        let (first, second) = match self.order {
            DrawOrder::FrontToBack => (Some(ColourPass::Meshes), ground),
            DrawOrder::Submitted => (ground, Some(ColourPass::Meshes)),
        };
        let overlay = (self.text_quads > 0).then_some(ColourPass::Overlay);
        let passes = [first, second, overlay].into_iter().flatten();
        for (index, kind) in passes.enumerate() {
            self.encode_colour_pass(encoder, kind, color, depth, index == 0, prepass);
        }
        if let Some(timer) = &self.timer {
            timer.resolve(encoder);
        }
    }

    /// One colour pass: the first clears `color`, and `depth` unless the pre-pass drew it.
    fn encode_colour_pass(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        kind: ColourPass,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        first: bool,
        prepass: bool,
    ) {
        let [r, g, b] = BACKGROUND.map(f64::from);
        let name = match kind {
            ColourPass::Meshes => "meshes",
            ColourPass::Ground => "ground",
            ColourPass::Overlay => "overlay",
        };
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(name),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: color,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: if first {
                        wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a: 1.0 })
                    } else {
                        wgpu::LoadOp::Load
                    },
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    load: if first && !prepass {
                        wgpu::LoadOp::Clear(1.0)
                    } else {
                        wgpu::LoadOp::Load
                    },
                    // The overlay, always last, neither tests nor writes depth.
                    store: if kind == ColourPass::Overlay {
                        wgpu::StoreOp::Discard
                    } else {
                        wgpu::StoreOp::Store
                    },
                }),
                stencil_ops: None,
            }),
            timestamp_writes: self.timer.as_mut().map(|timer| timer.render_pass(name)),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_bind_group(0, &self.globals_bind_group, &[]);
        pass.set_bind_group(1, &self.textures_bind_group, &[]);
        match kind {
            ColourPass::Ground => {
                pass.set_pipeline(&self.grid_pipeline);
                pass.set_vertex_buffer(0, self.ground.buffer.slice(..));
                pass.draw(0..self.ground_vertices, 0..1);
            }
            ColourPass::Meshes => {
                pass.set_vertex_buffer(1, self.instances.buffer.slice(..));
                // What is drawn over the scene comes after the scene it is drawn over.
                let scene = self.draws.iter().filter(|(key, _)| !key.over_scene());
                let over = self.draws.iter().filter(|(key, _)| key.over_scene());
                for (key, range) in scene.chain(over) {
                    let mesh = &self.meshes[key];
                    let (pipeline, indices) = match (&mesh.triangles, self.wireframe) {
                        _ if key.over_scene() => match &mesh.lines {
                            Some(lines) => (&self.over_scene_pipeline, lines),
                            None => continue,
                        },
                        (Some(triangles), false) if matches!(key, MeshKey::TriMesh(_)) => {
                            (&self.two_sided_pipeline, triangles)
                        }
                        (Some(triangles), false) => (&self.solid_pipeline, triangles),
                        _ => match &mesh.lines {
                            Some(lines) => (&self.line_pipeline, lines),
                            None => continue,
                        },
                    };
                    pass.set_pipeline(pipeline);
                    pass.set_vertex_buffer(0, mesh.vertices.slice(..));
                    pass.set_index_buffer(indices.0.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed(0..indices.1, 0, range.clone());
                }
            }
            ColourPass::Overlay => {
                pass.set_pipeline(&self.text_pipeline);
                pass.set_vertex_buffer(0, self.text.buffer.slice(..));
                pass.draw(0..6, 0..self.text_quads);
            }
        }
    }

    /// The depth pre-pass: clears `depth` and draws the depth of every solid surface (lines,
    /// thin, are left to the colour pass), so that the colour passes shade each pixel once.
    fn encode_prepass(&mut self, encoder: &mut wgpu::CommandEncoder, depth: &wgpu::TextureView) {
        let Some(prepass) = &self.prepass else {
            return;
        };
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("depth pre-pass"),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: self
                .timer
                .as_mut()
                .map(|timer| timer.render_pass("depth pre-pass")),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_bind_group(0, &self.globals_bind_group, &[]);
        pass.set_vertex_buffer(1, self.instances.buffer.slice(..));
        for (key, range) in &self.draws {
            let mesh = &self.meshes[key];
            if let Some((indices, count)) = &mesh.triangles {
                pass.set_pipeline(if matches!(key, MeshKey::TriMesh(_)) {
                    &prepass.two_sided
                } else {
                    &prepass.culled
                });
                pass.set_vertex_buffer(0, mesh.vertices.slice(..));
                pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..*count, 0, range.clone());
            }
        }
        if self.ground_vertices > 0 {
            pass.set_pipeline(&prepass.ground);
            pass.set_vertex_buffer(0, self.ground.buffer.slice(..));
            pass.draw(0..self.ground_vertices, 0..1);
        }
    }

    /// Overwrites the models of the instances that `links` tie to a body with the body's pose
    /// in `poses` times the link's local matrix: one compute dispatch, submitted now, so it runs
    /// after the instance upload and before the frame that draws them.
    fn pose_instances(&mut self, links: &[PoseLink], poses: DevicePoses) {
        if links.is_empty() {
            return;
        }
        let device = &self.device;
        let pipeline = self.pose_pipeline.get_or_insert_with(|| {
            let source = format!(
                "const NO_BODY: u32 = {NO_BODY}u;\nconst WORKGROUP_SIZE: u32 = \
                 {POSE_WORKGROUP_SIZE}u;\n{}",
                include_str!("pose.wgsl")
            );
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("pose.wgsl"),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("poses"),
                layout: None,
                module: &module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            })
        });
        self.links
            .write(device, &self.queue, bytemuck::cast_slice(links));
        // A new bind group only when a buffer was replaced (the physics' grew, or ours) or the
        // link count changed: the bindings' sizes are the count's (pose.wgsl's arrayLength).
        let buffers = [
            poses.poses.clone(),
            self.links.buffer.clone(),
            self.instances.buffer.clone(),
        ];
        let current = self
            .pose_binding
            .as_ref()
            .is_some_and(|binding| binding.buffers == buffers && binding.links == links.len());
        if !current {
            let bytes = |count: usize, size: usize| wgpu::BufferSize::new((count * size) as u64);
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("poses"),
                layout: &pipeline.get_bind_group_layout(0),
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: poses.poses.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &self.links.buffer,
                            offset: 0,
                            size: bytes(links.len(), size_of::<PoseLink>()),
                        }),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &self.instances.buffer,
                            offset: 0,
                            size: bytes(links.len(), size_of::<Instance>()),
                        }),
                    },
                ],
            });
            self.pose_binding = Some(PoseBinding {
                buffers,
                links: links.len(),
                bind_group,
            });
        }
        let Some(binding) = &self.pose_binding else {
            return;
        };
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("poses"),
                timestamp_writes: self.timer.as_mut().map(|timer| timer.compute_pass("pose")),
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &binding.bind_group, &[]);
            pass.dispatch_workgroups((links.len() as u32).div_ceil(POSE_WORKGROUP_SIZE), 1, 1);
        }
        self.queue.submit([encoder.finish()]);
    }

    /// The shadow pass: every solid mesh's depth as the light sees it.
    fn encode_shadows(&mut self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("shadow"),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.shadow_map,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: self.timer.as_mut().map(|timer| timer.render_pass("shadow")),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.shadow_pipeline);
        pass.set_bind_group(0, &self.globals_bind_group, &[]);
        pass.set_vertex_buffer(1, self.instances.buffer.slice(..));
        for (key, range) in &self.draws {
            let mesh = &self.meshes[key];
            if let Some((indices, count)) = &mesh.triangles {
                pass.set_vertex_buffer(0, mesh.vertices.slice(..));
                pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..*count, 0, range.clone());
            }
        }
    }
}

/// The light's view of a sphere (`center`, `radius`) and what lies below it along the light:
/// world to the shadow map's clip space (orthographic, depth 0 at the light), and the size of a
/// texel in metres of a map `shadow_map_size` texels across. The map spans the sphere across;
/// in depth it reaches from in front of the sphere to far enough behind it for the ground under
/// raised bodies.
fn light_view_projection(
    light: Vec3,
    center: Vec3,
    radius: f32,
    shadow_map_size: u32,
) -> (Mat4, f32) {
    let radius = radius.max(1.0e-3);
    let eye = center + light * (2.0 * radius);
    // Any up vector not along the light will do; the light is never straight up here.
    let up = if light.cross(Vec3::Y).length_squared() > 1.0e-6 {
        Vec3::Y
    } else {
        Vec3::Z
    };
    let view = glam::camera::rh::view::look_at_mat4(eye, center, up);
    let far = 2.0 * radius + (8.0 * radius).max(50.0);
    let projection =
        glam::camera::rh::proj::directx::orthographic(-radius, radius, -radius, radius, 0.0, far);
    (projection * view, 2.0 * radius / shadow_map_size as f32)
}

/// The font atlas (font.rs) as a one-channel texture.
fn upload_font(device: &wgpu::Device, queue: &wgpu::Queue) -> wgpu::TextureView {
    let size = wgpu::Extent3d {
        width: GLYPH_COUNT * GLYPH_WIDTH,
        height: GLYPH_HEIGHT,
        depth_or_array_layers: 1,
    };
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("font"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::R8Unorm,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    queue.write_texture(
        texture.as_image_copy(),
        &crate::font::atlas(),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(size.width),
            rows_per_image: Some(size.height),
        },
        size,
    );
    texture.create_view(&Default::default())
}

/// A depth attachment for a `width` × `height` colour target.
pub fn depth_view(device: &wgpu::Device, width: u32, height: u32) -> wgpu::TextureView {
    device
        .create_texture(&wgpu::TextureDescriptor {
            label: Some("depth"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            view_formats: &[],
        })
        .create_view(&Default::default())
}

fn mesh_data(key: MeshKey, list: &DrawList) -> MeshData {
    match key {
        MeshKey::Cube => MeshData::cube(),
        MeshKey::Sphere => MeshData::sphere(),
        MeshKey::Particle => MeshData::particle(),
        MeshKey::Capsule {
            radius,
            half_height,
        } => MeshData::capsule(f32::from_bits(radius), f32::from_bits(half_height)),
        MeshKey::Segment | MeshKey::ConstraintSegment => MeshData::segment(),
        MeshKey::ConstraintPoint => MeshData::cross(),
        MeshKey::Hull(hash) => MeshData::hull(&list.hulls[&hash]),
        MeshKey::TriMesh(hash) => MeshData::trimesh(&list.trimeshes[&hash]),
    }
}

fn upload_mesh(device: &wgpu::Device, mesh: &MeshData) -> GpuMesh {
    let indices = |label: &str, data: &[u32]| {
        (!data.is_empty()).then(|| {
            let buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::cast_slice(data),
                usage: wgpu::BufferUsages::INDEX,
            });
            (buffer, data.len() as u32)
        })
    };
    GpuMesh {
        vertices: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("mesh vertices"),
            contents: bytemuck::cast_slice(&mesh.vertices),
            usage: wgpu::BufferUsages::VERTEX,
        }),
        triangles: indices("mesh triangles", &mesh.triangles),
        lines: indices("mesh lines", &mesh.lines),
    }
}

/// Two triangles covering the quad (the grid pipeline does not cull, so winding is free).
fn ground_vertices(quad: &GroundQuad) -> [GridVertex; 6] {
    let [u, v] = quad.tangents;
    // Plane coordinates are measured from the world origin's projection, so grid lines do not
    // slide when the quad's centre follows the scene.
    let origin_u = quad.center.dot(u);
    let origin_v = quad.center.dot(v);
    let corner = |a: f32, b: f32| {
        let (du, dv) = (a * quad.half_size, b * quad.half_size);
        GridVertex {
            position: (quad.center + du * u + dv * v).to_array(),
            normal: quad.normal.to_array(),
            plane: [origin_u + du, origin_v + dv],
        }
    };
    let (a, b, c, d) = (
        corner(-1.0, -1.0),
        corner(1.0, -1.0),
        corner(1.0, 1.0),
        corner(-1.0, 1.0),
    );
    [a, b, c, a, c, d]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::draw::DrawSettings;
    use tumble::pipeline::devices::{Executor, StageDevices};
    use tumble::{BodyDesc, Shape, StepConfig, World};

    #[test]
    fn an_adapter_that_cannot_make_the_renderer_is_an_error() {
        let context = crate::GpuContext::headless().expect("an adapter");
        let srgb = wgpu::TextureFormat::Rgba8UnormSrgb;
        let limit = context.device.limits().max_texture_dimension_2d;
        let quality = Quality {
            shadow_map_size: limit + 1,
            ..Quality::default()
        };
        match Renderer::new(&context, srgb, quality) {
            Err(ViewError::ShadowMapTooLarge {
                size, limit: said, ..
            }) => {
                assert_eq!((size, said), (limit + 1, limit));
            }
            other => panic!("{:?}", other.err()),
        }
        // A colour format nothing renders to: the pipelines fail validation, which wgpu's
        // default handler would have made a panic.
        match Renderer::new(
            &context,
            wgpu::TextureFormat::Rgb9e5Ufloat,
            Quality::default(),
        ) {
            Err(error @ ViewError::CreateRenderer { .. }) => {
                let message = error.to_string();
                assert!(message.contains(&context.describe()), "{message}");
            }
            other => panic!("{:?}", other.err()),
        }
        // The device stays usable: a renderer it can make is made.
        assert!(Renderer::new(&context, srgb, Quality::default()).is_ok());
    }

    #[test]
    fn the_pose_pass_makes_its_bind_group_once_while_its_buffers_stay() {
        let mut world = World::new(StepConfig::default()).unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
        for x in 0..3 {
            world
                .add_body(
                    BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(
                        2.0 * x as f32,
                        0.5,
                        0.0,
                    )),
                )
                .unwrap();
        }
        world
            .set_stage_devices(StageDevices::all(Executor::Gpu))
            .unwrap();
        let context = crate::GpuContext::headless().expect("an adapter");
        let mut renderer = Renderer::new(
            &context,
            wgpu::TextureFormat::Rgba8UnormSrgb,
            Quality::default(),
        )
        .unwrap();
        let camera = Camera::look_at(Vec3::new(0.0, 4.0, 8.0), Vec3::ZERO);
        let mut bind_groups = Vec::new();
        for _ in 0..3 {
            world.step();
            let list = DrawList::build(&world, DrawSettings::default());
            renderer.prepare(&list, &camera, (64, 48), world.device_poses());
            let binding = renderer.pose_binding.as_ref().expect("poses were bound");
            bind_groups.push(binding.bind_group.clone());
        }
        assert!(bind_groups.iter().all(|group| *group == bind_groups[0]));
        // Contact markers add instances that belong to no body: more links, a new group.
        let list = DrawList::build(
            &world,
            DrawSettings {
                contacts: true,
                ..Default::default()
            },
        );
        renderer.prepare(&list, &camera, (64, 48), world.device_poses());
        let binding = renderer.pose_binding.as_ref().expect("poses were bound");
        assert_ne!(binding.bind_group, bind_groups[0]);
    }
}
