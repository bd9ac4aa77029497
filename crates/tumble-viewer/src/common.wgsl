// Shared by mesh.wgsl, grid.wgsl and text.wgsl (prepended by renderer.rs). Mirrors `Globals` in
// renderer.rs.

struct Globals {
    view_projection: mat4x4<f32>,
    // World to the shadow map's clip space: an orthographic view along the light over the
    // scene's bounds, depth 0 (nearest the light) to 1.
    light_view_projection: mat4x4<f32>,
    // Unit vector towards the light (world space); w unused.
    light_direction: vec4<f32>,
    // x: ambient, y: diffuse (Lambert) weight; zw unused.
    lighting: vec4<f32>,
    // x: shadow map side in texels (0: no shadows), y: how far a surface point is pushed along
    // its normal before the map is read (m, about a texel), so a surface does not shadow itself.
    shadow: vec4<f32>,
    // xy: the picture's size in pixels; zw unused.
    viewport: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;
@group(1) @binding(0) var shadow_map: texture_depth_2d;
@group(1) @binding(1) var shadow_sampler: sampler_comparison;

// Fraction of the light reaching `position` (0 shadowed, 1 lit): 3 x 3 texels compared against
// the map (percentage-closer filtering, so shadow edges are soft instead of jagged). Points
// outside the map are lit: the map covers the bodies and whatever they can shade.
fn light_reaching(position: vec3<f32>, normal: vec3<f32>) -> f32 {
    let size = globals.shadow.x;
    if (size == 0.0) {
        return 1.0;
    }
    let moved = position + normal * globals.shadow.y;
    let clip = globals.light_view_projection * vec4<f32>(moved, 1.0);
    let ndc = clip.xyz / clip.w;
    let uv = vec2<f32>(0.5 + 0.5 * ndc.x, 0.5 - 0.5 * ndc.y);
    if (any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0)) || ndc.z > 1.0) {
        return 1.0;
    }
    var lit = 0.0;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let offset = vec2<f32>(f32(dx), f32(dy)) / size;
            // The Level variant: no derivatives, so it may sit behind the branch above.
            lit += textureSampleCompareLevel(shadow_map, shadow_sampler, uv + offset, ndc.z);
        }
    }
    return lit / 9.0;
}

// Lambert + ambient, the Lambert part shadowed: a scalar times the colour, so the hue of a
// surface is its colour's hue.
fn shade(colour: vec3<f32>, normal: vec3<f32>, position: vec3<f32>) -> vec3<f32> {
    let n = normalize(normal);
    let lambert = max(dot(n, globals.light_direction.xyz), 0.0);
    var light = 1.0;
    if (lambert > 0.0) {
        light = light_reaching(position, n);
    }
    return colour * (globals.lighting.x + globals.lighting.y * lambert * light);
}
