//! Stage 5: constraint rows — contact rows from the manifolds ([`contact`], on the GPU [`gpu`])
//! and joint rows from the joints ([`joint`], on the GPU [`joint_gpu`]). Both are solved
//! together by the same batched solver.

pub mod contact;
pub mod gpu;
pub mod joint;
pub mod joint_gpu;
pub mod lanes;
pub mod tally;

pub use contact::{
    CONTACT_CONSTRAINT_WGSL, ConstraintPoint, ContactConstraint, Row, RowInputs,
    body_inverse_inertia, build_constraints, constraint_bodies, constraint_slots, has_constraint,
    world_inverse_inertia,
};
pub use joint::{
    AngularRow, DRAG_JOINT, Drag, JOINT_CONSTRAINT_WGSL, JointConstraint, JointFrame, JointSlot,
    RowKind, build_joint_constraints, drag_constraint, joint_slots,
};

/// Body index of a constraint's static side: such a body has zero velocity and infinite mass.
pub const STATIC_BODY: u32 = u32::MAX;
