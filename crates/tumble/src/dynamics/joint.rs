//! Joints: a point (ball-and-socket), a hinge with angle limits and a motor, a cone-twist with
//! swing and twist limits, and a fixed joint. Each may break above an impulse threshold.
//!
//! A joint is described in the world frame at the bodies' current poses (anchor point, axis) and
//! stored in each body's local frame, so it follows the bodies. Angles are of body B relative
//! to body A, measured about the axis, zero at creation, in radians in (−π, π].

use crate::math::{Quat, Vec3, tangent_basis};

/// Names a joint in a [`World`](crate::World); carries a generation like [`crate::BodyHandle`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct JointHandle {
    pub(crate) index: u32,
    pub(crate) generation: u32,
}

/// A motor on a hinge: drives the relative angular speed about the axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motor {
    /// Relative angular speed of B about the axis to reach (rad/s).
    pub target_speed: f32,
    /// Largest torque the motor applies (N m).
    pub max_torque: f32,
}

/// What a joint holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JointKind {
    /// The anchor points of both bodies stay together; rotation is free.
    Point,
    /// A point joint that also keeps the axes aligned: one rotational freedom about `axis`.
    Hinge {
        /// Unit axis in the world frame at creation.
        axis: Vec3,
        /// (lower, upper) angle (rad), lower ≤ upper, within [−π, π].
        limits: Option<(f32, f32)>,
        motor: Option<Motor>,
    },
    /// A point joint whose twist axis may swing inside a cone and twist within limits
    /// (shoulders, hips).
    ConeTwist {
        /// Unit twist axis in the world frame at creation (e.g. along a limb).
        axis: Vec3,
        /// Largest angle between the two bodies' twist axes (rad), in [0, π].
        swing_limit: f32,
        /// (lower, upper) twist about the axis (rad), within [−π, π].
        twist_limits: (f32, f32),
    },
    /// No relative motion at all.
    Fixed,
}

/// Everything needed to create a joint between two bodies of a world.
#[must_use]
#[derive(Clone, Debug, PartialEq)]
pub struct JointDesc {
    pub kind: JointKind,
    pub body_a: crate::BodyHandle,
    pub body_b: crate::BodyHandle,
    /// The joint point in the world frame at the current poses (m).
    pub anchor: Vec3,
    /// The joint breaks (stops acting) when its impulse in one sub-step exceeds this (N s).
    pub break_impulse: Option<f32>,
}

impl JointDesc {
    pub fn new(
        kind: JointKind,
        body_a: crate::BodyHandle,
        body_b: crate::BodyHandle,
        anchor: Vec3,
    ) -> Self {
        Self {
            kind,
            body_a,
            body_b,
            anchor,
            break_impulse: None,
        }
    }

    pub fn break_impulse(mut self, impulse: f32) -> Self {
        self.break_impulse = Some(impulse);
        self
    }

    /// Checks the description; `Err` names the problem.
    pub fn validate(&self) -> Result<(), JointError> {
        if self.body_a == self.body_b {
            return Err(JointError::SameBody);
        }
        if !self.anchor.is_finite() {
            return Err(JointError::NotFinite { field: "anchor" });
        }
        if let Some(impulse) = self.break_impulse
            && !(impulse.is_finite() && impulse > 0.0)
        {
            return Err(JointError::BadBreakImpulse(impulse));
        }
        let check_axis = |axis: Vec3| {
            if !axis.is_finite() {
                Err(JointError::NotFinite { field: "axis" })
            } else if axis.length_squared() < 1e-12 {
                Err(JointError::ZeroAxis)
            } else {
                Ok(())
            }
        };
        let check_range = |field: &'static str, (lower, upper): (f32, f32)| {
            let pi = std::f32::consts::PI;
            if !(lower.is_finite() && upper.is_finite()) {
                Err(JointError::NotFinite { field })
            } else if lower > upper || lower < -pi || upper > pi {
                Err(JointError::BadLimits {
                    field,
                    lower,
                    upper,
                })
            } else {
                Ok(())
            }
        };
        match self.kind {
            JointKind::Point | JointKind::Fixed => Ok(()),
            JointKind::Hinge {
                axis,
                limits,
                motor,
            } => {
                check_axis(axis)?;
                if let Some(limits) = limits {
                    check_range("limits", limits)?;
                }
                if let Some(motor) = motor {
                    if !(motor.target_speed.is_finite() && motor.max_torque.is_finite()) {
                        return Err(JointError::NotFinite { field: "motor" });
                    }
                    if motor.max_torque < 0.0 {
                        return Err(JointError::NegativeMaxTorque(motor.max_torque));
                    }
                }
                Ok(())
            }
            JointKind::ConeTwist {
                axis,
                swing_limit,
                twist_limits,
            } => {
                check_axis(axis)?;
                if !(0.0..=std::f32::consts::PI).contains(&swing_limit) {
                    return Err(JointError::BadSwingLimit(swing_limit));
                }
                check_range("twist_limits", twist_limits)
            }
        }
    }
}

/// Why a joint could not be created or restored.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum JointError {
    #[error("a joint needs two different bodies")]
    SameBody,
    #[error("joint {field} must be finite (no NaN or infinity)")]
    NotFinite { field: &'static str },
    #[error("joint axis must be non-zero")]
    ZeroAxis,
    #[error("joint {field} [{lower}, {upper}] must have lower <= upper, both within [-pi, pi] rad")]
    BadLimits {
        field: &'static str,
        lower: f32,
        upper: f32,
    },
    #[error("joint swing_limit must be within [0, pi] rad, got {0}")]
    BadSwingLimit(f32),
    #[error("joint motor max_torque must be >= 0, got {0}")]
    NegativeMaxTorque(f32),
    #[error("joint break_impulse must be > 0, got {0}")]
    BadBreakImpulse(f32),
    #[error("a joint needs at least one dynamic body")]
    BothStatic,
    #[error("joint refers to a body that does not exist or was removed")]
    StaleBody,
    #[error("the joint handle is stale: that joint was removed")]
    StaleHandle,
    #[error("reading the bodies back from the GPU failed: {0}")]
    BodiesReadback(String),
}

impl JointError {
    /// A failed read-back of the bodies the device holds (the joint's frames need their
    /// poses).
    pub(crate) fn readback(error: crate::gpu::context::GpuError) -> Self {
        JointError::BodiesReadback(error.to_string())
    }

    /// The field of the description (as the scene file names it) the error is about, if one.
    pub fn field(&self) -> Option<&'static str> {
        match self {
            JointError::SameBody => Some("body_b"),
            JointError::NotFinite { field } | JointError::BadLimits { field, .. } => Some(field),
            JointError::ZeroAxis => Some("axis"),
            JointError::BadSwingLimit(_) => Some("swing_limit"),
            JointError::NegativeMaxTorque(_) => Some("motor.max_torque"),
            JointError::BadBreakImpulse(_) => Some("break_impulse"),
            JointError::BothStatic
            | JointError::StaleBody
            | JointError::StaleHandle
            | JointError::BodiesReadback(_) => None,
        }
    }

    /// The problem without the field's name, for callers that name the field themselves
    /// (the scene loader writes `joints[2].axis: must be non-zero`).
    pub fn requirement(&self) -> String {
        match self {
            JointError::SameBody => {
                "is the same body as body_a; a joint needs two different bodies".into()
            }
            JointError::NotFinite { .. } => "must be finite (no NaN or infinity)".into(),
            JointError::ZeroAxis => "must be non-zero".into(),
            JointError::BadLimits { lower, upper, .. } => {
                format!("[{lower}, {upper}] must have lower <= upper, both within [-pi, pi] rad")
            }
            JointError::BadSwingLimit(value) => {
                format!("must be within [0, pi] rad, got {value}")
            }
            JointError::NegativeMaxTorque(value) => format!("must be >= 0, got {value}"),
            JointError::BadBreakImpulse(value) => format!("must be > 0, got {value}"),
            other => other.to_string(),
        }
    }
}

/// What a joint carries beyond its description: its frames in the two bodies (fixed when it
/// was created, which is where its angles are zero), its warm-start impulses and whether it
/// broke. A dumped scene stores it so that loading the dump continues the run bitwise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointState {
    pub local_anchor_a: Vec3,
    pub local_anchor_b: Vec3,
    pub local_axis_a: Vec3,
    pub local_axis_b: Vec3,
    pub local_reference_a: Vec3,
    pub local_reference_b: Vec3,
    pub relative_rotation: Quat,
    pub point_impulse: Vec3,
    pub angular_impulse: [f32; MAX_ANGULAR_ROWS],
    pub broken: bool,
}

impl JointState {
    /// A new joint's state: a joint of `kind` at `anchor` (world frame, m) made between bodies
    /// at poses `(position, rotation)` a and b, with no impulses yet. Its frames are those
    /// poses' view of the world axis and of a reference direction perpendicular to it, so all
    /// its angles are zero at these poses. Peers (the benchmark's rapier adapter) build their
    /// joint frames from this too.
    pub fn new(
        kind: JointKind,
        anchor: Vec3,
        (position_a, rotation_a): (Vec3, Quat),
        (position_b, rotation_b): (Vec3, Quat),
    ) -> Self {
        let axis = match kind {
            JointKind::Hinge { axis, .. } | JointKind::ConeTwist { axis, .. } => axis.normalize(),
            JointKind::Point | JointKind::Fixed => Vec3::X,
        };
        let (reference, _) = tangent_basis(axis);
        let (inverse_a, inverse_b) = (rotation_a.inverse(), rotation_b.inverse());
        JointState {
            local_anchor_a: inverse_a * (anchor - position_a),
            local_anchor_b: inverse_b * (anchor - position_b),
            local_axis_a: inverse_a * axis,
            local_axis_b: inverse_b * axis,
            local_reference_a: inverse_a * reference,
            local_reference_b: inverse_b * reference,
            relative_rotation: inverse_a * rotation_b,
            point_impulse: Vec3::ZERO,
            angular_impulse: [0.0; MAX_ANGULAR_ROWS],
            broken: false,
        }
    }

    pub fn is_finite(&self) -> bool {
        [
            self.local_anchor_a,
            self.local_anchor_b,
            self.local_axis_a,
            self.local_axis_b,
            self.local_reference_a,
            self.local_reference_b,
            self.point_impulse,
        ]
        .iter()
        .all(|v| v.is_finite())
            && self.relative_rotation.is_finite()
            && self.angular_impulse.iter().all(|v| v.is_finite())
    }
}

/// A joint as the step sees it: everything in the bodies' local frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Joint {
    pub kind: JointKind,
    pub body_a: u32,
    pub body_b: u32,
    /// Anchor in each body's frame (m).
    pub local_anchor_a: Vec3,
    pub local_anchor_b: Vec3,
    /// The axis (twist / hinge axis) in each body's frame; X for point and fixed joints.
    pub local_axis_a: Vec3,
    pub local_axis_b: Vec3,
    /// A direction perpendicular to the axis, in each body's frame: angle zero is where the
    /// two coincide.
    pub local_reference_a: Vec3,
    pub local_reference_b: Vec3,
    /// B's orientation relative to A at creation, q_a⁻¹ q_b (the fixed joint holds it).
    pub relative_rotation: Quat,
    pub break_impulse: Option<f32>,
    pub broken: bool,
    /// Warm-start impulses: the point part (N s) and the angular rows (N m s).
    pub point_impulse: Vec3,
    pub angular_impulse: [f32; MAX_ANGULAR_ROWS],
}

/// Most angular rows a joint uses (hinge: 2 alignment, 1 motor, 2 limits).
pub const MAX_ANGULAR_ROWS: usize = 5;

impl Joint {
    /// The joint of `desc` between bodies at poses `(position, rotation)` a and b.
    pub fn new(desc: &JointDesc, pose_a: (Vec3, Quat), pose_b: (Vec3, Quat)) -> Self {
        let mut joint = Joint {
            kind: desc.kind,
            body_a: desc.body_a.index,
            body_b: desc.body_b.index,
            local_anchor_a: Vec3::ZERO,
            local_anchor_b: Vec3::ZERO,
            local_axis_a: Vec3::X,
            local_axis_b: Vec3::X,
            local_reference_a: Vec3::Y,
            local_reference_b: Vec3::Y,
            relative_rotation: Quat::IDENTITY,
            break_impulse: desc.break_impulse,
            broken: false,
            point_impulse: Vec3::ZERO,
            angular_impulse: [0.0; MAX_ANGULAR_ROWS],
        };
        joint.restore(&JointState::new(desc.kind, desc.anchor, pose_a, pose_b));
        joint
    }

    pub fn state(&self) -> JointState {
        JointState {
            local_anchor_a: self.local_anchor_a,
            local_anchor_b: self.local_anchor_b,
            local_axis_a: self.local_axis_a,
            local_axis_b: self.local_axis_b,
            local_reference_a: self.local_reference_a,
            local_reference_b: self.local_reference_b,
            relative_rotation: self.relative_rotation,
            point_impulse: self.point_impulse,
            angular_impulse: self.angular_impulse,
            broken: self.broken,
        }
    }

    /// Replaces the frames, impulses and broken flag; the kind and bodies stay.
    pub fn restore(&mut self, state: &JointState) {
        self.local_anchor_a = state.local_anchor_a;
        self.local_anchor_b = state.local_anchor_b;
        self.local_axis_a = state.local_axis_a;
        self.local_axis_b = state.local_axis_b;
        self.local_reference_a = state.local_reference_a;
        self.local_reference_b = state.local_reference_b;
        self.relative_rotation = state.relative_rotation;
        self.point_impulse = state.point_impulse;
        self.angular_impulse = state.angular_impulse;
        self.broken = state.broken;
    }
}
