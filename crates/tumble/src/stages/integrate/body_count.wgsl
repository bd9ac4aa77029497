// The parameter block of the body kernels (prepare.wgsl, finalize.wgsl): how many bodies.
struct BodyCount {
    count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}
