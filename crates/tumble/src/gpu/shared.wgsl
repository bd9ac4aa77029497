// Snippets every kernel includes. The constants WORKGROUP_SIZE (threads per workgroup) and
// MAX_GROUPS_X are injected from Rust (`gpu::kernel`), so they are written once.

// Index of this workgroup in a dispatch that `gpu::kernel::dispatch_grid` split over x and y
// because it had more than 65535 workgroups: rows of `groups.x` workgroups, row-major.
fn flat_workgroup(workgroup: vec3<u32>, groups: vec3<u32>) -> u32 {
    return workgroup.y * groups.x + workgroup.x;
}
