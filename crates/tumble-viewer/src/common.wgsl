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

// Fraction of the light reaching `position` (0 shadowed, 1 lit): the map's depths around the
// point compared with the point's (percentage-closer filtering, so shadow edges are soft
// instead of jagged), as SHADOW_FILTER (prepended by renderer.rs, `ShadowFilter` in quality.rs)
// says. Points outside the map are lit: the map covers the bodies and whatever they can shade.
fn light_reaching(position: vec3<f32>, normal: vec3<f32>) -> f32 {
    let size = globals.shadow.x;
    if (size == 0.0 || SHADOW_FILTER == FILTER_OFF) {
        return 1.0;
    }
    let moved = position + normal * globals.shadow.y;
    let clip = globals.light_view_projection * vec4<f32>(moved, 1.0);
    let ndc = clip.xyz / clip.w;
    let uv = vec2<f32>(0.5 + 0.5 * ndc.x, 0.5 - 0.5 * ndc.y);
    if (any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0)) || ndc.z > 1.0) {
        return 1.0;
    }
    // The Level variants: no derivatives, so they may sit behind the branches above (gathers
    // never use any).
    if (SHADOW_FILTER == FILTER_TAP1) {
        return textureSampleCompareLevel(shadow_map, shadow_sampler, uv, ndc.z);
    }
    if (SHADOW_FILTER == FILTER_TAPS9) {
        var lit = 0.0;
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                let offset = vec2<f32>(f32(dx), f32(dy)) / size;
                lit += textureSampleCompareLevel(shadow_map, shadow_sampler, uv + offset, ndc.z);
            }
        }
        return lit / 9.0;
    }
    // Else (SHADOW_FILTER 0, gather4): the nine bilinear taps above, one texel apart, cover the 4 x 4 texels
    // from `base` - 1 to `base` + 2 on each axis (texel centres at whole `texel` values), with
    // weights 1 - f, 1, 1, f (f: the point's fraction between texel centres); the product of
    // the two axes' weights over 9 is the filter. Four gathers read the 16 comparisons.
    let texel = uv * size - 0.5;
    let base = floor(texel);
    let f = texel - base;
    // A gather at (base + 0) / size reads texels base - 1 and base on each axis (it sits
    // halfway between their centres); at (base + 2) / size, base + 1 and base + 2.
    let low = (base + 0.0) / size;
    let high = (base + 2.0) / size;
    let near_x = vec2<f32>(1.0 - f.x, 1.0);
    let far_x = vec2<f32>(1.0, f.x);
    let near_y = vec2<f32>(1.0 - f.y, 1.0);
    let far_y = vec2<f32>(1.0, f.y);
    let lit = gathered(vec2<f32>(low.x, low.y), ndc.z, near_x, near_y)
        + gathered(vec2<f32>(high.x, low.y), ndc.z, far_x, near_y)
        + gathered(vec2<f32>(low.x, high.y), ndc.z, near_x, far_y)
        + gathered(vec2<f32>(high.x, high.y), ndc.z, far_x, far_y);
    return lit / 9.0;
}

const FILTER_TAPS9: u32 = 1u;
const FILTER_TAP1: u32 = 2u;
const FILTER_OFF: u32 = 3u;

// The 2 x 2 comparisons a bilinear tap at `coords` would blend, weighted by `x` (the lower and
// the higher column) and `y` (the lower and the higher row). A gather's components are the
// texels (x_low, y_high), (x_high, y_high), (x_high, y_low), (x_low, y_low), in that order.
fn gathered(coords: vec2<f32>, depth: f32, x: vec2<f32>, y: vec2<f32>) -> f32 {
    let compared = textureGatherCompare(shadow_map, shadow_sampler, coords, depth);
    return dot(compared, vec4<f32>(x.x * y.y, x.y * y.y, x.y * y.x, x.x * y.x));
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
