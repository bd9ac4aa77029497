// A body's world-frame inverse inertia: how the rows' build (rows.wgsl) and the solver's
// bodies (prepare.wgsl) compute it, and how the solver keeps it beside its bodies. Needs
// body.wgsl and lanes.wgsl.

// R diag(d) Rᵀ: the world-frame inverse inertia of a body of rotation `rotation` and inverse
// principal inertia `d` (zero for a static body), by its upper triangle
// (SymmetricMat3::from_upper).
fn world_inverse_inertia(rotation: vec4<f32>, d: vec3<f32>) -> SymmetricMat3 {
    let r = mat3_from_quat(rotation);
    let scaled = mat3x3<f32>(r[0] * d.x, r[1] * d.y, r[2] * d.z);
    let m = scaled * transpose(r);
    return SymmetricMat3(vec3<f32>(m[0].x, m[1].y, m[2].z), vec3<f32>(m[1].x, m[2].x, m[2].y));
}

// A body's inverse inertia as the solver keeps it beside its bodies (BodyInertia in
// stages/solver/gpu.rs): two words, [0] the diagonal and xy, [1] xz and yz, then zeros. The
// contact sweeps read it there rather than from each constraint (`load_header`).
fn body_inertia_words(m: SymmetricMat3) -> array<vec4<f32>, 2> {
    return array<vec4<f32>, 2>(vec4<f32>(m[0], m[1].x), vec4<f32>(m[1].yz, 0.0, 0.0));
}

fn body_inertia_of(words: array<vec4<f32>, 2>) -> SymmetricMat3 {
    return SymmetricMat3(words[0].xyz, vec3<f32>(words[0].w, words[1].xy));
}
