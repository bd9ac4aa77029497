// Instanced meshes: boxes, spheres, capsules, hulls, triangle meshes (solid or wireframe),
// contact segments, and joints and the drag over the scene (lines).
// Vertex layout: `Vertex` in mesh.rs; instance layout: `Instance` in draw.rs.

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) model_0: vec4<f32>,
    @location(3) model_1: vec4<f32>,
    @location(4) model_2: vec4<f32>,
    @location(5) model_3: vec4<f32>,
    @location(6) colour: vec4<f32>,
};

struct VertexOut {
    // Invariant: the depth pre-pass draws with this same vertex stage, and the colour pass's
    // depth must equal it.
    @builtin(position) @invariant clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) colour: vec3<f32>,
    @location(2) world: vec3<f32>,
};

@vertex
fn vs_main(in: VertexIn) -> VertexOut {
    return transform(in);
}

fn transform(in: VertexIn) -> VertexOut {
    let model = mat4x4<f32>(in.model_0, in.model_1, in.model_2, in.model_3);
    // The model is R S (rotation times axis scale), so normals transform by its inverse
    // transpose R S⁻¹, whose column i is the model's column i divided by s_i² = |column i|².
    let c0 = in.model_0.xyz;
    let c1 = in.model_1.xyz;
    let c2 = in.model_2.xyz;
    var out: VertexOut;
    let world = model * vec4<f32>(in.position, 1.0);
    out.clip = globals.view_projection * world;
    out.world = world.xyz;
    out.normal = c0 * (in.normal.x / dot(c0, c0)) + c1 * (in.normal.y / dot(c1, c1))
        + c2 * (in.normal.z / dot(c2, c2));
    out.colour = in.colour.rgb;
    return out;
}

// Joints and the drag, drawn over the scene: at the near plane's depth (0), which passes the
// depth test everywhere and, written, keeps the ground drawn after them from covering them.
@vertex
fn vs_over_scene(in: VertexIn) -> VertexOut {
    var out = transform(in);
    out.clip.z = 0.0;
    return out;
}

// The shadow pass: depth only, as the light sees the mesh.
@vertex
fn vs_shadow(in: VertexIn) -> @builtin(position) vec4<f32> {
    let model = mat4x4<f32>(in.model_0, in.model_1, in.model_2, in.model_3);
    return globals.light_view_projection * model * vec4<f32>(in.position, 1.0);
}

@fragment
fn fs_solid(in: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(shade(in.colour, in.normal, in.world), 1.0);
}

// Triangle meshes: seen from behind, a triangle is lit as its back face (the normal flipped).
@fragment
fn fs_two_sided(in: VertexOut, @builtin(front_facing) front_facing: bool) -> @location(0) vec4<f32> {
    let normal = select(-in.normal, in.normal, front_facing);
    return vec4<f32>(shade(in.colour, normal, in.world), 1.0);
}

// Wireframe edges and contact normals: unlit, so they read the same from every side.
@fragment
fn fs_line(in: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(in.colour, 1.0);
}
