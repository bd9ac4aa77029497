// The overlays: one quad per `TextQuad` (overlay.rs), in pixels from the top-left corner; a
// glyph quad reads its cell of the font atlas (font.rs), the panel is filled. CELL_WIDTH,
// CELL_HEIGHT, GLYPH_WIDTH, GLYPH_HEIGHT and PANEL are prepended by renderer.rs.

@group(1) @binding(2) var font: texture_2d<f32>;

struct QuadIn {
    @location(0) position: vec2<f32>,
    @location(1) size: vec2<f32>,
    @location(2) colour: vec4<f32>,
    @location(3) glyph: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    // Position in the quad, in font pixels (0..CELL_WIDTH, 0..CELL_HEIGHT for a glyph).
    @location(0) cell: vec2<f32>,
    @location(1) colour: vec4<f32>,
    @location(2) @interpolate(flat) glyph: u32,
};

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, quad: QuadIn) -> VertexOut {
    // Two triangles: corners (0,0) (1,0) (1,1), (0,0) (1,1) (0,1).
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 0.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 1.0), vec2<f32>(0.0, 1.0),
    );
    let corner = corners[vertex];
    let pixel = quad.position + corner * quad.size;
    // Pixels (y down) to clip space (y up).
    let ndc = vec2<f32>(2.0 * pixel.x / globals.viewport.x - 1.0, 1.0 - 2.0 * pixel.y / globals.viewport.y);
    var out: VertexOut;
    out.clip = vec4<f32>(ndc, 0.0, 1.0);
    out.cell = corner * vec2<f32>(f32(CELL_WIDTH), f32(CELL_HEIGHT));
    out.colour = quad.colour;
    out.glyph = quad.glyph;
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    if (in.glyph == PANEL) {
        return in.colour;
    }
    let texel = vec2<u32>(floor(in.cell));
    if (texel.x >= GLYPH_WIDTH || texel.y >= GLYPH_HEIGHT) {
        discard;
    }
    let ink = textureLoad(font, vec2<u32>(in.glyph * GLYPH_WIDTH + texel.x, texel.y), 0).r;
    if (ink < 0.5) {
        discard;
    }
    return in.colour;
}
