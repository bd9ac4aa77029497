//! Joint rows. Every joint kind keeps its anchors together with a **point part**, solved as one
//! 3×3 block (Jolt's PointConstraintPart), plus up to [`MAX_ANGULAR_ROWS`] one-dimensional
//! **angular rows** solved one after the other.
//!
//! Point part, with r_a, r_b the world arms from each centre of mass to the anchor:
//!
//! ```text
//!   C     = (x_b + r_b) − (x_a + r_a)                       (m, world)
//!   C_dot = v_b + ω_b × r_b − v_a − ω_a × r_a
//!   K     = (1/m_a + 1/m_b) 𝟙 − [r_a]× I_a⁻¹ [r_a]× − [r_b]× I_b⁻¹ [r_b]×
//!   λ     = −K⁻¹ (C_dot + bias);  B gets +λ at r_b, A gets −λ at r_a
//! ```
//!
//! Angular row along a unit direction d: `C_dot = d·(ω_b − ω_a)`, `K = d·(I_a⁻¹ + I_b⁻¹) d`:
//! - hinge alignment: with a = A's axis and b₁, b₂ ⊥ B's axis, `C_i = a·b_i`, d = b_i × a;
//! - fixed: three rows along world X, Y, Z driving the rotation error to zero;
//! - limits: inequality rows (impulse ≥ 0) on the distance `s` to the limit, speculative like
//!   contacts (`C_dot ≥ −s/h` while inside, soft push back when outside);
//! - hinge motor: `C_dot = target_speed`, |impulse| ≤ max_torque · h.
//!
//! Position errors are removed softly (a spring-damper bias, [`Softness`]) during the solve
//! iterations of each sub-step and not at all in the relax iteration, as for contacts. Because
//! the bodies turn during the sub-steps, the rows are rebuilt from the current rotations
//! (step-start rotation composed with the solver's delta rotation) each time they are solved.

use crate::dynamics::body::{BodyMass, BodyPose};
use crate::dynamics::joint::{Joint, JointKind, MAX_ANGULAR_ROWS};
use crate::math::{Mat3, Quat, Vec3, tangent_basis};
use crate::pipeline::config::Softness;
use crate::stages::constraints::{STATIC_BODY, body_inverse_inertia};

/// What an angular row enforces.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum RowKind {
    /// An unused slot.
    #[default]
    Unused,
    /// `error` → 0, impulse unbounded.
    Equality,
    /// `error` is the distance to a limit and must stay ≥ 0; impulse ≥ 0.
    Limit,
    /// Relative angular speed → `target_speed`, |impulse| ≤ `max_impulse`.
    Motor { target_speed: f32, max_impulse: f32 },
}

/// One angular row at the current rotations.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AngularRow {
    pub kind: RowKind,
    /// Unit direction, world frame.
    pub direction: Vec3,
    /// Position error (rad) or distance to the limit.
    pub error: f32,
}

// Layout: `JointFrame` and `JointConstraint` are repr(C) + Pod with WGSL twins in
// `joint_constraint.wgsl` (checked by tests/engine/gpu_layout.rs), so both executors solve the same
// array. Each vec3 shares its 16 bytes with a scalar, as in the contact rows; the joint kind
// is a number and its options flags, since a Rust enum has no WGSL twin. The inverse inertias
// stay glam `Mat3`s (36 bytes, columns packed), which WGSL reads as `array<f32, 9>`: its
// mat3x3 would pad each column to 16 bytes.

/// [`JointFrame::kind`] of a point joint: no angular rows.
pub const JOINT_POINT: u32 = 0;
/// [`JointFrame::kind`] of a hinge: two alignment rows, a motor row, two limit rows.
pub const JOINT_HINGE: u32 = 1;
/// [`JointFrame::kind`] of a cone-twist: a swing limit row and two twist limit rows.
pub const JOINT_CONE_TWIST: u32 = 2;
/// [`JointFrame::kind`] of a fixed joint: three rows on the rotation error.
pub const JOINT_FIXED: u32 = 3;
/// [`JointFrame::flags`]: the hinge has angle limits (`lower`, `upper`).
pub const HAS_LIMITS: u32 = 1;
/// [`JointFrame::flags`]: the hinge has a motor (`target_speed`, `max_torque`).
pub const HAS_MOTOR: u32 = 2;

/// A [`Joint`] as the solver reads it: its kind and options flattened, everything in the
/// bodies' frames. 128 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct JointFrame {
    /// Anchor in each body's frame (m).
    pub local_anchor_a: Vec3,
    /// [`JOINT_POINT`], [`JOINT_HINGE`], [`JOINT_CONE_TWIST`] or [`JOINT_FIXED`].
    pub kind: u32,
    pub local_anchor_b: Vec3,
    /// [`HAS_LIMITS`] | [`HAS_MOTOR`] (hinges only).
    pub flags: u32,
    /// The hinge or twist axis in each body's frame; X for point and fixed joints.
    pub local_axis_a: Vec3,
    /// Lower angle limit (rad): the hinge's limits or the cone-twist's twist limits.
    pub lower: f32,
    pub local_axis_b: Vec3,
    /// Upper angle limit (rad).
    pub upper: f32,
    /// Angle zero is where these two directions, ⊥ the axis, coincide.
    pub local_reference_a: Vec3,
    /// Largest swing of a cone-twist (rad).
    pub swing_limit: f32,
    pub local_reference_b: Vec3,
    /// Hinge motor: relative angular speed of B about the axis to reach (rad/s).
    pub target_speed: f32,
    /// B's orientation relative to A at creation, q_a⁻¹ q_b (the fixed joint holds it).
    pub relative_rotation: Quat,
    /// Hinge motor: largest torque (N m).
    pub max_torque: f32,
    pub _pad: [f32; 3],
}
const _: () = assert!(size_of::<JointFrame>() == 128);

impl From<&Joint> for JointFrame {
    fn from(joint: &Joint) -> Self {
        let mut frame = Self {
            local_anchor_a: joint.local_anchor_a,
            local_anchor_b: joint.local_anchor_b,
            local_axis_a: joint.local_axis_a,
            local_axis_b: joint.local_axis_b,
            local_reference_a: joint.local_reference_a,
            local_reference_b: joint.local_reference_b,
            relative_rotation: joint.relative_rotation,
            ..Self::default()
        };
        match joint.kind {
            JointKind::Point => frame.kind = JOINT_POINT,
            JointKind::Fixed => frame.kind = JOINT_FIXED,
            JointKind::Hinge { limits, motor, .. } => {
                frame.kind = JOINT_HINGE;
                if let Some((lower, upper)) = limits {
                    frame.flags |= HAS_LIMITS;
                    (frame.lower, frame.upper) = (lower, upper);
                }
                if let Some(motor) = motor {
                    frame.flags |= HAS_MOTOR;
                    (frame.target_speed, frame.max_torque) = (motor.target_speed, motor.max_torque);
                }
            }
            JointKind::ConeTwist {
                swing_limit,
                twist_limits: (lower, upper),
                ..
            } => {
                frame.kind = JOINT_CONE_TWIST;
                frame.swing_limit = swing_limit;
                (frame.lower, frame.upper) = (lower, upper);
            }
        }
        frame
    }
}

/// A joint as the solver sees it during one step. 320 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct JointConstraint {
    /// The joint in the bodies' frames.
    pub frame: JointFrame,
    /// Body rotations at the start of the step.
    pub rotation_a: Quat,
    pub rotation_b: Quat,
    /// x_b − x_a at the start of the step (m).
    pub center_offset: Vec3,
    pub inverse_mass_a: f32,
    /// Accumulated impulse of the point part (N s).
    pub point_impulse: Vec3,
    pub inverse_mass_b: f32,
    pub body_a: u32,
    pub body_b: u32,
    /// Index of the joint in the world, to store impulses back.
    pub joint: u32,
    /// Largest point impulse per sub-step (N s): infinite for joints, max_force · h for a drag.
    pub max_point_impulse: f32,
    pub softness: Softness,
    /// Accumulated impulses of the angular rows (N m s).
    pub angular_impulse: [f32; MAX_ANGULAR_ROWS],
    pub inverse_inertia_a: Mat3,
    pub inverse_inertia_b: Mat3,
    pub _pad: [f32; 2],
}
const _: () = assert!(size_of::<JointConstraint>() == 320);

/// One slot of the world's joint array as the GPU rows read it: the joint in its bodies'
/// frames and its two bodies, or a slot whose joint is gone or broken (`live` 0). The device
/// keeps one per slot, uploaded only when the joints change; the rows are built from them and
/// the step's poses and masses. 144 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct JointSlot {
    pub frame: JointFrame,
    /// The joint's bodies as the world numbers them (a side without mass becomes
    /// [`STATIC_BODY`] in the row, not here).
    pub body_a: u32,
    pub body_b: u32,
    /// 1 for a live, unbroken joint; 0 for a free or broken slot, which gets no row.
    pub live: u32,
    pub _pad: u32,
}
const _: () = assert!(size_of::<JointSlot>() == 144);

impl From<&Option<Joint>> for JointSlot {
    fn from(joint: &Option<Joint>) -> Self {
        match joint {
            Some(joint) if !joint.broken => Self {
                frame: JointFrame::from(joint),
                body_a: joint.body_a,
                body_b: joint.body_b,
                live: 1,
                _pad: 0,
            },
            _ => Self::default(),
        }
    }
}

/// WGSL twins of [`JointFrame`], [`JointConstraint`] and [`JointSlot`], and of the solver's
/// [`BatchedJointImpulses`](crate::stages::solver::batched::BatchedJointImpulses), which the
/// rows read their warm start from.
pub const JOINT_CONSTRAINT_WGSL: &str = include_str!("joint_constraint.wgsl");

/// The `joint` index of the drag constraint (it is no joint of the world).
pub const DRAG_JOINT: u32 = u32::MAX;

/// A temporary point constraint pulling a body's point towards a moving target (the viewer's
/// mouse drag), as [`World::set_drag_target`](crate::World::set_drag_target) sets it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drag {
    pub body: u32,
    /// The dragged point in the body's frame (m).
    pub local_anchor: Vec3,
    /// Where the point is pulled, world frame (m).
    pub target: Vec3,
    /// Largest pull (N).
    pub max_force: f32,
    /// Warm-start impulse (N s), kept while the same point is dragged.
    pub impulse: Vec3,
}

/// The drag as a point joint whose body A is the static world with the target as its anchor;
/// `softness` (softer than the joints') lets the point trail a moving target instead of
/// jumping onto it. Built on the host on every path (one row; on the GPU it is written beside
/// the joint rows the device builds).
pub fn drag_constraint(
    drag: &Drag,
    poses: &[BodyPose],
    masses: &[BodyMass],
    softness: Softness,
    h: f32,
) -> JointConstraint {
    let body = drag.body as usize;
    let frame = JointFrame {
        local_anchor_a: drag.target,
        kind: JOINT_POINT,
        local_anchor_b: drag.local_anchor,
        local_axis_a: Vec3::X,
        local_axis_b: Vec3::X,
        local_reference_a: Vec3::Y,
        local_reference_b: Vec3::Y,
        relative_rotation: Quat::IDENTITY,
        ..JointFrame::default()
    };
    JointConstraint {
        body_a: STATIC_BODY,
        body_b: drag.body,
        joint: DRAG_JOINT,
        inverse_mass_a: 0.0,
        inverse_mass_b: masses[body].inverse_mass,
        inverse_inertia_a: Mat3::ZERO,
        inverse_inertia_b: body_inverse_inertia(&poses[body], &masses[body]),
        frame,
        rotation_a: Quat::IDENTITY,
        rotation_b: poses[body].rotation,
        // The world frame is A's: its origin is A's centre.
        center_offset: poses[body].position,
        softness,
        point_impulse: drag.impulse,
        angular_impulse: [0.0; MAX_ANGULAR_ROWS],
        max_point_impulse: drag.max_force * h,
        _pad: [0.0; 2],
    }
}

/// The joints that get a constraint this step, in the order of the rows: every live, unbroken
/// joint (`None` is a free joint slot) with a body that moves. Each comes as its slot in
/// `joints` and its bodies as the constraint names them ([`STATIC_BODY`] for a side without
/// mass). Both executors' rows follow this list, and the batching reads the bodies from it.
pub fn joint_slots<'a>(
    joints: &'a [Option<Joint>],
    masses: &'a [BodyMass],
) -> impl Iterator<Item = (u32, (u32, u32))> + 'a {
    joints.iter().enumerate().filter_map(|(index, joint)| {
        let joint = joint.as_ref().filter(|joint| !joint.broken)?;
        let moves = |body: u32| masses[body as usize].inverse_mass > 0.0;
        // Both bodies asleep (or one asleep on the static world): nothing to solve; the joint
        // keeps its impulses for when they wake.
        if !moves(joint.body_a) && !moves(joint.body_b) {
            return None;
        }
        let side = |body: u32| if moves(body) { body } else { STATIC_BODY };
        Some((index as u32, (side(joint.body_a), side(joint.body_b))))
    })
}

/// Builds the constraint of every joint of [`joint_slots`], in its order.
pub fn build_joint_constraints(
    joints: &[Option<Joint>],
    poses: &[BodyPose],
    masses: &[BodyMass],
    inverse_inertia: &[Mat3],
    softness: Softness,
    out: &mut Vec<JointConstraint>,
) {
    out.clear();
    for (index, (body_a, body_b)) in joint_slots(joints, masses) {
        let Some(joint) = &joints[index as usize] else {
            unreachable!("joint_slots lists live joints")
        };
        let (ia, ib) = (joint.body_a as usize, joint.body_b as usize);
        let (mass_a, mass_b) = (masses[ia].inverse_mass, masses[ib].inverse_mass);
        out.push(JointConstraint {
            body_a,
            body_b,
            joint: index,
            inverse_mass_a: mass_a,
            inverse_mass_b: mass_b,
            inverse_inertia_a: inverse_inertia[ia],
            inverse_inertia_b: inverse_inertia[ib],
            frame: JointFrame::from(joint),
            rotation_a: poses[ia].rotation,
            rotation_b: poses[ib].rotation,
            center_offset: poses[ib].position - poses[ia].position,
            softness,
            point_impulse: joint.point_impulse,
            angular_impulse: joint.angular_impulse,
            max_point_impulse: f32::INFINITY,
            _pad: [0.0; 2],
        });
    }
}

impl JointConstraint {
    /// World arms from the centres of mass to the anchor at rotations `q_a`, `q_b`.
    pub fn arms(&self, q_a: Quat, q_b: Quat) -> (Vec3, Vec3) {
        (
            q_a * self.frame.local_anchor_a,
            q_b * self.frame.local_anchor_b,
        )
    }

    /// The angular rows at rotations `q_a`, `q_b`; `h` is the sub-step (s).
    pub fn angular_rows(&self, q_a: Quat, q_b: Quat, h: f32) -> [AngularRow; MAX_ANGULAR_ROWS] {
        let joint = &self.frame;
        let mut rows = [AngularRow::default(); MAX_ANGULAR_ROWS];
        let equality = |direction: Vec3, error: f32| AngularRow {
            kind: RowKind::Equality,
            direction,
            error,
        };
        let limit = |direction: Vec3, error: f32| AngularRow {
            kind: RowKind::Limit,
            direction,
            error,
        };
        let axis_a = q_a * joint.local_axis_a;
        let axis_b = q_b * joint.local_axis_b;
        match joint.kind {
            JOINT_FIXED => {
                // Rotation taking where B should be (q_a · q_rel) to where it is: θ ≈ 2 · vec(q_err).
                let mut rotation_error = q_b * (q_a * joint.relative_rotation).inverse();
                if rotation_error.w < 0.0 {
                    rotation_error = -rotation_error;
                }
                let angle = 2.0 * Vec3::new(rotation_error.x, rotation_error.y, rotation_error.z);
                for (i, direction) in [Vec3::X, Vec3::Y, Vec3::Z].into_iter().enumerate() {
                    rows[i] = equality(direction, angle[i]);
                }
            }
            JOINT_HINGE => {
                let (b1, b2) = tangent_basis(axis_b);
                rows[0] = equality(b1.cross(axis_a), axis_a.dot(b1));
                rows[1] = equality(b2.cross(axis_a), axis_a.dot(b2));
                // The motor before the limits: Gauss-Seidel favours the row solved last, and a
                // motor driving into a limit must not push past it (Box2D orders them so too).
                if joint.flags & HAS_MOTOR != 0 {
                    let kind = RowKind::Motor {
                        target_speed: joint.target_speed,
                        max_impulse: joint.max_torque * h,
                    };
                    rows[2] = AngularRow {
                        kind,
                        direction: axis_a,
                        error: 0.0,
                    };
                }
                if joint.flags & HAS_LIMITS != 0
                    && let Some([lower_row, upper_row]) =
                        twist_limit_rows(joint, q_a, q_b, axis_a, axis_b)
                {
                    rows[3] = lower_row;
                    rows[4] = upper_row;
                }
            }
            JOINT_CONE_TWIST => {
                let swing_axis = axis_a.cross(axis_b);
                let sin_swing = swing_axis.length();
                if sin_swing > 1e-6 {
                    let swing = sin_swing.atan2(axis_a.dot(axis_b));
                    // Swinging further turns B's axis away from A's about a × b.
                    rows[0] = limit(-swing_axis / sin_swing, joint.swing_limit - swing);
                }
                if let Some([lower_row, upper_row]) =
                    twist_limit_rows(joint, q_a, q_b, axis_a, axis_b)
                {
                    rows[1] = lower_row;
                    rows[2] = upper_row;
                }
            }
            // JOINT_POINT: the point part alone.
            _ => {}
        }
        rows
    }
}

/// The two limit rows on the twist angle φ between `joint.lower` and `joint.upper` (lower row,
/// then upper), or `None` where φ is undefined (the axes opposite).
///
/// φ does not change at the rate `a·Δω`: turning B about its own axis b changes it as fast as
/// turning about a, and turning about n = a × b (pure swing) not at all. Hence
/// `φ̇ = J·(ω_b − ω_a)` with `J = (a + b) / (1 + a·b)` (J·a = J·b = 1, J·n = 0). The rows use
/// the unit direction d = J/|J| (Bullet's cone-twist uses the same bisector) and express the
/// distance to the limit along it, `(φ − lower) / |J|`. With `a` alone as the direction, a
/// swung cone-twist (a shoulder at 1.5 rad) measured its twist rate wrongly, and its limit rows
/// pumped energy into the limb: ragdoll arms kept flailing on the ground.
fn twist_limit_rows(
    joint: &JointFrame,
    q_a: Quat,
    q_b: Quat,
    axis_a: Vec3,
    axis_b: Vec3,
) -> Option<[AngularRow; 2]> {
    let (lower, upper) = (joint.lower, joint.upper);
    let one_plus_cos = 1.0 + axis_a.dot(axis_b);
    if one_plus_cos < 1e-3 {
        return None;
    }
    let bisector = axis_a + axis_b;
    let bisector_length = bisector.length();
    let direction = bisector / bisector_length;
    let rate = bisector_length / one_plus_cos;
    let angle = twist_angle(joint, q_a, q_b, axis_a, axis_b);
    let row = |direction: Vec3, error: f32| AngularRow {
        kind: RowKind::Limit,
        direction,
        error: error / rate,
    };
    Some([
        row(direction, angle - lower),
        row(-direction, upper - angle),
    ])
}

/// Rotation of B relative to A about the axis (rad, in (−π, π]), zero at creation: B's
/// reference direction is first swung back onto A's axis, then compared with A's.
fn twist_angle(joint: &JointFrame, q_a: Quat, q_b: Quat, axis_a: Vec3, axis_b: Vec3) -> f32 {
    let reference_a = q_a * joint.local_reference_a;
    let reference_b = Quat::from_rotation_arc(axis_b, axis_a) * (q_b * joint.local_reference_b);
    reference_a
        .cross(reference_b)
        .dot(axis_a)
        .atan2(reference_a.dot(reference_b))
}

/// [v]×: the matrix of the cross product, [v]× u = v × u.
pub fn skew(v: Vec3) -> Mat3 {
    Mat3::from_cols(
        Vec3::new(0.0, v.z, -v.y),
        Vec3::new(-v.z, 0.0, v.x),
        Vec3::new(v.y, -v.x, 0.0),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dynamics::joint::JointDesc;

    /// The twist limit rows' direction and error scale match the twist angle's actual rate of
    /// change, also far from the cone's centre (a finite-difference check).
    #[test]
    fn twist_rows_follow_the_twist_rate_at_large_swing() {
        let handle = |index| crate::BodyHandle {
            index,
            generation: 0,
        };
        let kind = JointKind::ConeTwist {
            axis: Vec3::X,
            swing_limit: 3.0,
            twist_limits: (-3.0, 3.0),
        };
        let desc = JointDesc::new(kind, handle(0), handle(1), Vec3::ZERO);
        let joint = JointFrame::from(&Joint::new(
            &desc,
            (Vec3::ZERO, Quat::IDENTITY),
            (Vec3::ZERO, Quat::IDENTITY),
        ));
        let q_a = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.2, 0.5);
        for swing in [0.0, 0.7, 1.5, 2.5] {
            let q_b = Quat::from_rotation_z(swing) * Quat::from_rotation_x(0.4) * q_a;
            let (axis_a, axis_b) = (q_a * joint.local_axis_a, q_b * joint.local_axis_b);
            let [lower_row, _] = twist_limit_rows(&joint, q_a, q_b, axis_a, axis_b).unwrap();
            for omega in [Vec3::X, Vec3::Y, Vec3::Z, Vec3::new(0.3, -1.0, 0.7)] {
                let epsilon = 1e-3;
                let turned = Quat::from_scaled_axis(omega * epsilon) * q_b;
                let axis_turned = turned * joint.local_axis_b;
                let measured = (twist_angle(&joint, q_a, turned, axis_a, axis_turned)
                    - twist_angle(&joint, q_a, q_b, axis_a, axis_b))
                    / epsilon;
                // The row's error is the angle's distance divided by |J|, along d = J/|J|.
                let rate = (lower_row.error
                    / (twist_angle(&joint, q_a, q_b, axis_a, axis_b) + 3.0))
                    .recip();
                let predicted = rate * lower_row.direction.dot(omega);
                assert!(
                    (measured - predicted).abs() < 0.02 * (1.0 + predicted.abs()),
                    "swing {swing}, ω {omega}: error changes at {measured}, row says {predicted}"
                );
            }
        }
    }
}
