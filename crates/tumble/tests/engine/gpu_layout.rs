//! Every WGSL struct shared with Rust has the `#[repr(C)]` twin's size and field offsets.
//! naga (the compiler wgpu uses) parses each kernel's composed source, which also proves
//! every kernel compiles, and reports the WGSL layout; a struct found in WGSL but not listed
//! here fails the test, so a new shared struct cannot be forgotten.

use std::collections::BTreeMap;

use tumble::gpu::kernel::Source;
use tumble::gpu::prims::{bitonic_sort, compact, fill, radix_sort, reduce, scan};
use tumble::particles::{self, BodyInfo, Particle, ParticleParams, RigidBody, RigidParams};

/// (field name, offset) of each member, and the size, of every struct in `source`.
fn wgsl_structs(source: &Source) -> BTreeMap<String, (Vec<(String, u32)>, u32)> {
    let module = naga::front::wgsl::parse_str(source.text())
        .unwrap_or_else(|error| panic!("{}", error.emit_to_string(source.text())));
    module
        .types
        .iter()
        .filter_map(|(_, ty)| match &ty.inner {
            naga::TypeInner::Struct { members, span } => Some((
                ty.name.clone().unwrap_or_default(),
                (
                    members
                        .iter()
                        .map(|member| (member.name.clone().unwrap_or_default(), member.offset))
                        .collect(),
                    *span,
                ),
            )),
            _ => None,
        })
        .collect()
}

/// The Rust layout of a struct: its fields, their offsets, its size.
macro_rules! rust_layout {
    ($type:ty { $($field:ident),* $(,)? }) => {
        (
            stringify!($type).rsplit("::").next().unwrap_or_default().to_owned(),
            (
                vec![$((stringify!($field).to_owned(), std::mem::offset_of!($type, $field) as u32)),*],
                size_of::<$type>() as u32,
            ),
        )
    };
}

/// A struct's name, and its fields with their offsets and its size.
type Layout = (String, (Vec<(String, u32)>, u32));

fn check(source: Source, rust: Vec<Layout>) {
    check_with_gpu_only(source, rust, &[]);
}

/// [`check`] for a source that also defines structs only its kernels use (`gpu_only`), which
/// have no Rust twin.
fn check_with_gpu_only(source: Source, rust: Vec<Layout>, gpu_only: &[&str]) {
    let mut wgsl = wgsl_structs(&source);
    for name in gpu_only {
        assert!(
            wgsl.remove(*name).is_some(),
            "struct {name} is not in the WGSL"
        );
    }
    for (name, layout) in rust {
        let found = wgsl
            .remove(&name)
            .unwrap_or_else(|| panic!("struct {name} is not in the WGSL"));
        assert_eq!(found, layout, "layout of {name} (WGSL, then Rust)");
    }
    assert!(
        wgsl.is_empty(),
        "WGSL structs without a Rust twin: {:?}",
        wgsl.keys()
    );
}

#[test]
fn primitive_parameter_blocks_match_rust() {
    // Both halves of the scan define `ThreadIds`, the kernel's builtin inputs.
    for path in [scan::ScanPath::Baseline, scan::ScanPath::Subgroups] {
        check_with_gpu_only(
            scan::wgsl(path),
            vec![rust_layout!(scan::ScanParams {
                count,
                inclusive,
                tile_count,
                first_tile
            })],
            &["ThreadIds"],
        );
    }
    // Both rankings of the sort define `ThreadIds` too.
    for key_words in [1, 2] {
        for path in [
            radix_sort::SortPath::Baseline,
            radix_sort::SortPath::Subgroups,
        ] {
            check_with_gpu_only(
                radix_sort::wgsl(key_words, path, 32),
                vec![rust_layout!(radix_sort::RadixParams {
                    count,
                    pass_index,
                    passes,
                    tile_count,
                    first_tile,
                    destination_first,
                    destination_count,
                    replay
                })],
                &["ThreadIds"],
            );
        }
    }
    check(
        bitonic_sort::wgsl(),
        vec![rust_layout!(bitonic_sort::BitonicParams {
            count,
            flip_block,
            distance,
            padding
        })],
    );
    check(
        fill::wgsl(),
        vec![rust_layout!(fill::FillParams {
            count,
            value,
            padding0,
            padding1
        })],
    );
    check(
        compact::wgsl(),
        vec![rust_layout!(compact::CompactParams {
            count,
            destination_first,
            destination_count,
            writes_total
        })],
    );
    for op in [
        reduce::ReduceOp::Min,
        reduce::ReduceOp::Max,
        reduce::ReduceOp::Sum,
    ] {
        for source in [reduce::wgsl::<u32>(op), reduce::wgsl::<f32>(op)] {
            check(
                source,
                vec![rust_layout!(reduce::ReduceParams {
                    count,
                    first_block,
                    padding1,
                    padding2
                })],
            );
        }
    }
}

#[test]
fn particle_structs_match_rust() {
    let [
        hash,
        cell_bounds,
        collide,
        symmetric,
        world,
        rigid_collide,
        bodies,
    ] = particles::kernel_sources();
    let rigid = || {
        vec![
            rust_layout!(RigidBody {
                position,
                orientation,
                linear_velocity,
                angular_velocity,
            }),
            rust_layout!(BodyInfo {
                first_particle,
                particle_count,
                inverse_mass,
                padding,
                inverse_inertia,
            }),
            rust_layout!(RigidParams {
                body_count,
                padding0,
                padding1,
                padding2,
            }),
        ]
    };
    let sources = [
        (hash, vec![]),
        (cell_bounds, vec![]),
        (collide, vec![]),
        (symmetric, vec![]),
        (world, rigid()),
        (rigid_collide, rigid()),
        (bodies, rigid()),
    ];
    for (source, extra) in sources {
        check(
            source,
            [
                rust_layout!(Particle { position, velocity }),
                rust_layout!(ParticleParams {
                    origin,
                    cell_size,
                    grid,
                    count,
                    gravity,
                    dt,
                    radius,
                    inverse_mass,
                    spring,
                    damping,
                    shear,
                    wall_spring,
                    wall_damping,
                    cell_count,
                    force_scale,
                    force_quantum,
                    padding0,
                    padding1,
                }),
            ]
            .into_iter()
            .chain(extra)
            .collect(),
        );
    }
}

/// The Rust layouts of `body.wgsl`'s structs, which every rigid-body kernel includes.
fn body_layouts() -> Vec<Layout> {
    use tumble::dynamics::body::{BodyMass, BodyPose, BodyVelocity, ColliderData};
    vec![
        rust_layout!(BodyPose {
            position,
            _pad,
            rotation
        }),
        rust_layout!(BodyVelocity {
            linear,
            _pad0,
            angular,
            _pad1
        }),
        rust_layout!(BodyMass {
            inverse_inertia,
            inverse_mass
        }),
        rust_layout!(ColliderData {
            kind,
            friction,
            restitution,
            bounding_radius,
            params
        }),
    ]
}

#[test]
fn body_structs_match_rust() {
    use tumble::dynamics::body::BODY_WGSL;
    check(
        Source::new().snippet("body.wgsl", BODY_WGSL),
        body_layouts(),
    );
}

/// The Rust layouts of `pair_contact.wgsl`'s structs, which several kernels include.
fn pair_contact_layouts() -> Vec<Layout> {
    use tumble::collision::manifold::{ContactPoint, Manifold};
    use tumble::stages::narrowphase::{ManifoldCache, PairContact, PointImpulse};
    vec![
        rust_layout!(ContactPoint {
            position,
            separation,
            anchor,
            id
        }),
        rust_layout!(Manifold {
            normal,
            count,
            points
        }),
        rust_layout!(PointImpulse { normal, tangent }),
        rust_layout!(ManifoldCache {
            position,
            margin,
            rotation,
            normal,
            valid,
            separations
        }),
        rust_layout!(PairContact {
            manifold,
            impulses,
            cache
        }),
    ]
}

#[test]
fn pair_contact_structs_match_rust() {
    use tumble::stages::narrowphase::PAIR_CONTACT_WGSL;
    check(
        Source::new().snippet("pair_contact.wgsl", PAIR_CONTACT_WGSL),
        pair_contact_layouts(),
    );
}

#[test]
fn narrowphase_structs_match_rust() {
    use tumble::stages::narrowphase::NarrowphaseParams;
    use tumble::stages::narrowphase::gpu::wgsl;
    check_with_gpu_only(
        wgsl(u32::MAX),
        [
            vec![rust_layout!(NarrowphaseParams {
                pair_count,
                skipped_count,
                margin,
                dt
            })],
            body_layouts(),
            pair_contact_layouts(),
        ]
        .concat(),
        // Box–box's polygon vertex and the hull pairs' views of the packed hulls, frames,
        // queries, polygon vertices and round cores' features live in one thread's private
        // memory; the hulls themselves are words (`pack_hulls`).
        &[
            "ClipVertex",
            "Polyhedron",
            "Frame",
            "HullClipVertex",
            "FaceQuery",
            "EdgeQuery",
            "PlaneCandidates",
            "CoreFeature",
            "CoreContact",
        ],
    );
}

#[test]
fn collision_front_half_parameter_blocks_match_rust() {
    use tumble::stages::aabb::gpu::{self as aabb, AabbParams};
    use tumble::stages::broadphase::gpu::TraverseParams;
    use tumble::stages::broadphase::gpu::{self as broadphase, BuildParams, CodeParams};
    use tumble::stages::pairs::gpu::{self as pairs, DiffParams};
    check(
        aabb::wgsl(),
        [
            vec![rust_layout!(AabbParams {
                count,
                margin,
                dt,
                padding
            })],
            // body.wgsl's structs, included by the kernel.
            body_layouts(),
        ]
        .concat(),
    );
    let [codes, build, traverse] = broadphase::wgsl();
    check(
        codes,
        vec![rust_layout!(CodeParams {
            leaf_count,
            partial_count,
            padding0,
            padding1
        })],
    );
    check(
        build,
        vec![rust_layout!(BuildParams {
            leaf_count,
            padding0,
            padding1,
            padding2
        })],
    );
    check(
        traverse,
        vec![rust_layout!(TraverseParams {
            dynamic_leaves,
            static_leaves,
            capacity,
            body_bits,
            extra_count,
            _pad0,
            _pad1,
            _pad2
        })],
    );
    check(
        pairs::wgsl(),
        vec![rust_layout!(DiffParams {
            new_count,
            old_count,
            padding0,
            padding1
        })],
    );
}

#[test]
fn contact_constraint_structs_match_rust() {
    use tumble::stages::constraints::CONTACT_CONSTRAINT_WGSL;
    check(
        Source::new().snippet("contact_constraint.wgsl", CONTACT_CONSTRAINT_WGSL),
        contact_constraint_layouts(),
    );
}

/// The Rust layouts of `contact_constraint.wgsl`'s structs, which the solver includes.
fn contact_constraint_layouts() -> Vec<Layout> {
    use tumble::pipeline::config::Softness;
    vec![rust_layout!(Softness {
        bias_rate,
        mass_scale,
        impulse_scale
    })]
}

#[test]
fn solver_structs_match_rust() {
    use tumble::stages::constraints::{JointConstraint, JointFrame, JointSlot};
    use tumble::stages::solver::SolverBody;
    use tumble::stages::solver::batched::BatchedJointImpulses;
    use tumble::stages::solver::gpu::{SolverParams, wgsl};
    // AngularRow, JointPose and JointMasses are the joint kernels' locals, PointRows and
    // ConstraintHeader the contact kernels' registers.
    check_with_gpu_only(
        wgsl(),
        [
            body_layouts(),
            contact_constraint_layouts(),
            vec![
                rust_layout!(SolverBody {
                    linear_velocity,
                    inverse_mass,
                    angular_velocity,
                    _pad0,
                    delta_position,
                    _pad1,
                    delta_rotation
                }),
                rust_layout!(SolverParams {
                    gravity,
                    h,
                    first_batch,
                    end_batch,
                    sequential,
                    use_bias,
                    max_push_velocity,
                    restitution_threshold,
                    body_count,
                    overflow_batch,
                    softness,
                    static_softness
                }),
                rust_layout!(JointFrame {
                    local_anchor_a,
                    kind,
                    local_anchor_b,
                    flags,
                    local_axis_a,
                    lower,
                    local_axis_b,
                    upper,
                    local_reference_a,
                    swing_limit,
                    local_reference_b,
                    target_speed,
                    relative_rotation,
                    max_torque,
                    _pad
                }),
                rust_layout!(JointConstraint {
                    frame,
                    rotation_a,
                    rotation_b,
                    center_offset,
                    inverse_mass_a,
                    point_impulse,
                    inverse_mass_b,
                    body_a,
                    body_b,
                    joint,
                    max_point_impulse,
                    softness,
                    angular_impulse,
                    inverse_inertia_a,
                    inverse_inertia_b,
                    _pad
                }),
                rust_layout!(JointSlot {
                    frame,
                    body_a,
                    body_b,
                    live,
                    _pad
                }),
                rust_layout!(BatchedJointImpulses { point, angular }),
            ],
        ]
        .concat(),
        &[
            "AngularRow",
            "JointPose",
            "JointMasses",
            "PointRows",
            "ConstraintHeader",
        ],
    );
}

/// The impulses the solver reads back when the rows stay on the device. The source also holds
/// the constraint structs, whose layouts `solver_structs_match_rust` checks.
#[test]
fn batched_impulses_match_rust() {
    use tumble::stages::solver::batched::{BatchedImpulses, BatchedJointImpulses, wgsl};
    check_with_gpu_only(
        wgsl(),
        vec![
            rust_layout!(BatchedImpulses {
                normal,
                tangent1,
                tangent2
            }),
            rust_layout!(BatchedJointImpulses { point, angular }),
        ],
        &["Softness", "JointFrame", "JointConstraint", "JointSlot"],
    );
}

/// The scatter of the solved impulses to the pairs' contacts on the device: the contact it
/// writes has the Rust layout; the constraint structs are `solver_structs_match_rust`'s.
#[test]
fn pair_impulses_structs_match_rust() {
    use tumble::stages::solver::batched::pair_impulses_wgsl;
    check_with_gpu_only(pair_impulses_wgsl(), pair_contact_layouts(), &["Softness"]);
}

/// The parameter block of the body kernels (the solver bodies' preparation and the
/// integration on the device); the body structs are checked by the body and solver tests.
#[test]
fn body_kernel_parameters_match_rust() {
    use tumble::stages::integrate::gpu::{BodyCount, finalize_wgsl, prepare_wgsl};
    for source in [prepare_wgsl(), finalize_wgsl()] {
        check_with_gpu_only(
            source,
            vec![rust_layout!(BodyCount {
                count,
                _pad0,
                _pad1,
                _pad2
            })],
            &[
                "BodyPose",
                "BodyVelocity",
                "BodyMass",
                "ColliderData",
                "Softness",
                "SolverBody",
            ],
        );
    }
}

/// The joint rows' parameter block. The source also holds the body and constraint structs,
/// whose layouts the body and solver tests check.
#[test]
fn joint_row_parameters_match_rust() {
    use tumble::stages::constraints::joint_gpu::{JointRowParams, wgsl};
    check_with_gpu_only(
        wgsl(),
        vec![rust_layout!(JointRowParams {
            softness,
            slot_count,
            max_point_impulse,
            _pad0,
            _pad1
        })],
        &[
            "BodyPose",
            "BodyVelocity",
            "BodyMass",
            "ColliderData",
            "Softness",
            "JointFrame",
            "JointConstraint",
            "JointSlot",
            "BatchedJointImpulses",
        ],
    );
}

/// The parameter blocks of the rows and batching kernels. The rows' source also holds the body,
/// manifold and constraint structs, whose layouts the narrowphase and solver tests check.
#[test]
fn row_and_batching_parameters_match_rust() {
    use tumble::stages::batching::gpu::{self as batching, BatchParams};
    use tumble::stages::constraints::gpu::{self as rows, RowParams};
    check_with_gpu_only(
        rows::wgsl(),
        vec![rust_layout!(RowParams {
            softness,
            static_softness,
            slots,
            _pad0,
            _pad1,
            _pad2
        })],
        &[
            "BodyPose",
            "BodyVelocity",
            "BodyMass",
            "ColliderData",
            "ContactPoint",
            "Manifold",
            "PointImpulse",
            "ManifoldCache",
            "PairContact",
            "Softness",
        ],
    );
    // Tally is three u32 words on the host ([u32; 3]: batched, count, rounds).
    check_with_gpu_only(
        batching::wgsl(),
        vec![rust_layout!(BatchParams {
            body_count,
            round,
            batcher,
            ordered
        })],
        &["Tally"],
    );
    // The warm start by body's adjacency.
    use tumble::stages::solver::adjacency::{self, AdjacencyParams};
    check_with_gpu_only(
        adjacency::wgsl(),
        vec![rust_layout!(AdjacencyParams {
            body_count,
            _pad0,
            _pad1,
            _pad2
        })],
        &[],
    );
    // The layout reads the same tally.
    use tumble::stages::batching::layout::{self, LayoutParams};
    check_with_gpu_only(
        layout::wgsl(),
        vec![rust_layout!(LayoutParams {
            blocks,
            _pad0,
            _pad1,
            _pad2
        })],
        &["Tally"],
    );
}
