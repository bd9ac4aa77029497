// Shared by mesh.wgsl and grid.wgsl (prepended by renderer.rs). Mirrors `Globals` in renderer.rs.

struct Globals {
    view_projection: mat4x4<f32>,
    // Unit vector towards the light (world space); w unused.
    light_direction: vec4<f32>,
    // x: ambient, y: diffuse (Lambert) weight; zw unused.
    lighting: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;

// Lambert + ambient: a scalar times the colour, so the hue of a surface is its colour's hue.
fn shade(colour: vec3<f32>, normal: vec3<f32>) -> vec3<f32> {
    let lambert = max(dot(normalize(normal), globals.light_direction.xyz), 0.0);
    return colour * (globals.lighting.x + globals.lighting.y * lambert);
}
