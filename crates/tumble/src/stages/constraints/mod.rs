//! Stage 5: constraint rows — contact rows from the manifolds ([`contact`]) and joint rows from
//! the joints ([`joint`]). Both are solved together by the same batched solver.

pub mod contact;
pub mod gpu;
pub mod joint;

pub use contact::{
    CONTACT_CONSTRAINT_WGSL, ConstraintPoint, ContactConstraint, Row, RowInputs, build_constraints,
    constraint_bodies, constraint_slots, world_inverse_inertia,
};
pub use joint::{
    AngularRow, DRAG_JOINT, Drag, JOINT_CONSTRAINT_WGSL, JointConstraint, JointFrame, RowKind,
    build_joint_constraints, drag_constraint,
};

/// Body index of a constraint's static side: such a body has zero velocity and infinite mass.
pub const STATIC_BODY: u32 = u32::MAX;
