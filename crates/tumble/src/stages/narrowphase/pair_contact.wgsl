// What a pair keeps from one step to the next, as the GPU stages read and write it: the twins
// of ContactPoint, Manifold (collision/manifold.rs), PointImpulse, ManifoldCache and
// PairContact (stages/narrowphase/mod.rs). tests/engine/gpu_layout.rs checks that the layouts agree.

const MAX_MANIFOLD_POINTS: u32 = 4u;

// One contact point: world position midway between the surfaces, separation (> 0 apart),
// the point in body A's frame, and the feature id.
struct ContactPoint {
    position: vec3<f32>,
    separation: f32,
    anchor: vec3<f32>,
    id: u32,
}

// Up to four points sharing one unit normal, from body B to body A.
struct Manifold {
    normal: vec3<f32>,
    count: u32,
    points: array<ContactPoint, 4>,
}

// Accumulated impulses of one point (N s): normal, then the two tangents of tangent_basis.
struct PointImpulse {
    normal: f32,
    tangent: array<f32, 2>,
}

// The relative pose the manifold was computed at (body B in body A's frame), the margin it
// was given, its normal in A's frame and its points' separations then; valid 0 when none.
struct ManifoldCache {
    position: vec3<f32>,
    margin: f32,
    rotation: vec4<f32>,
    normal: vec3<f32>,
    valid: u32,
    separations: vec4<f32>,
}

struct PairContact {
    manifold: Manifold,
    impulses: array<PointImpulse, 4>,
    cache: ManifoldCache,
}
