// Ground planes: a lit quad with anti-aliased grid lines. Vertex layout: `GridVertex` in
// renderer.rs. GRID_SPACING, GROUND_COLOUR and LINE_COLOUR are prepended by renderer.rs.

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    // Coordinates along the plane's tangents (m), so lines sit at whole multiples of the spacing.
    @location(2) plane: vec2<f32>,
};

struct VertexOut {
    // Invariant: the depth pre-pass draws with this same vertex stage, and the colour pass's
    // depth must equal it.
    @builtin(position) @invariant clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) plane: vec2<f32>,
    @location(2) world: vec3<f32>,
};

@vertex
fn vs_main(in: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = globals.view_projection * vec4<f32>(in.position, 1.0);
    out.normal = in.normal;
    out.plane = in.plane;
    out.world = in.position;
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let cell = in.plane / GRID_SPACING;
    // Distance to the nearest line in pixels (fwidth: cells per pixel), so lines stay about a
    // pixel wide at any distance.
    let width = fwidth(cell);
    let to_line = abs(fract(cell - 0.5) - 0.5) / max(width, vec2<f32>(1e-6));
    let on_line = 1.0 - min(min(to_line.x, to_line.y), 1.0);
    // Far away a pixel spans many cells and the lines would shimmer: fade them out.
    let fade = 1.0 - smoothstep(0.15, 0.5, max(width.x, width.y));
    let colour = mix(GROUND_COLOUR, LINE_COLOUR, on_line * fade);
    return vec4<f32>(shade(colour, in.normal, in.world), 1.0);
}
