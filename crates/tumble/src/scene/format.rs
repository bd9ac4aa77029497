//! Scene file format v1 (DESIGN.md). Unknown fields are errors and every error names the field
//! (`bodies[3].shape.box.half_extents: must be > 0, got 0`).
//!
//! Beyond DESIGN.md's fields, a dumped scene carries `contacts`: the warm-start impulses of the
//! persistent contacts, and each joint's `state`: its frames in the two bodies (where its angles
//! are zero), its warm-start impulses and whether it broke. Loading a dump therefore continues
//! the run bitwise (the impulses are solver state, as much a part of the world as the
//! velocities). A joint without `state` is made at the bodies' poses in the file.

use crate::dynamics::body::{BodyDesc, BodyError};
use crate::dynamics::joint::{JointDesc, JointKind, JointState, MAX_ANGULAR_ROWS, Motor};
use crate::math::{Quat, Transform, Vec3};
use crate::pipeline::config::StepConfig;
use crate::pipeline::world::World;
use crate::shape::{CompoundChild, CompoundError, Shape, TriMesh};
use crate::stages::narrowphase::{ManifoldCache, PairContact, PointImpulse};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Why a scene could not be read or built. Messages name the file, the field and the fix.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("cannot read scene file {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("cannot write {path}: {source}")]
    Write {
        path: String,
        source: std::io::Error,
    },
    #[error("{field}: {message}")]
    Parse { field: String, message: String },
    #[error("{field}: {message}")]
    Invalid { field: String, message: String },
    #[error(
        "unknown scene {0:?}: give a JSON file or a built-in name (`tumble scenes` lists them)"
    )]
    UnknownScene(String),
    #[error("scale must be a positive finite number, got {0}")]
    BadScale(f32),
}

/// The JSON document, field for field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    #[serde(default = "default_gravity")]
    pub gravity: [f32; 3],
    #[serde(default = "default_dt")]
    pub dt: f32,
    #[serde(default = "default_substeps")]
    pub substeps: u32,
    #[serde(default = "default_solver_iterations")]
    pub solver_iterations: u32,
    pub bodies: Vec<BodyFile>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub joints: Vec<JointFile>,
    /// Warm-start state of persistent contacts (written by dumps).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub contacts: Vec<ContactFile>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodyFile {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    pub shape: ShapeFile,
    #[serde(default = "default_mass")]
    pub mass: f32,
    #[serde(default)]
    pub position: [f32; 3],
    #[serde(default = "default_rotation")]
    pub rotation: [f32; 4],
    #[serde(default)]
    pub linear_velocity: [f32; 3],
    #[serde(default)]
    pub angular_velocity: [f32; 3],
    #[serde(default = "default_friction")]
    pub friction: f32,
    #[serde(default)]
    pub restitution: f32,
    /// Dumped state: seconds the body has rested (see `dynamics::island`).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub sleep_timer: f32,
    /// Dumped state: the sleeping island the body belongs to; bodies with the same number
    /// sleep (and wake) together. Absent for awake bodies.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub island: Option<u32>,
}

fn is_zero(value: &f32) -> bool {
    *value == 0.0
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeFile {
    Sphere {
        radius: f32,
    },
    Box {
        half_extents: [f32; 3],
    },
    Capsule {
        radius: f32,
        half_height: f32,
    },
    Plane {
        normal: [f32; 3],
        #[serde(default)]
        offset: f32,
    },
    /// A static triangle mesh: three indices into `vertices` per triangle, counter-clockwise
    /// seen from the front (see `shape::trimesh`).
    Trimesh {
        vertices: Vec<[f32; 3]>,
        indices: Vec<u32>,
    },
    /// A Wavefront OBJ file loaded as a static triangle mesh (all its objects together), or
    /// with `hull: true` as the convex hull of its faces' vertices (a body of any mass). A
    /// relative path is relative to the scene file's folder.
    Obj {
        path: String,
        #[serde(default)]
        hull: bool,
    },
    /// The convex hull of `points` (m, body frame). The body is placed at the hull's principal
    /// centroid frame; a dump writes the hull in that frame and the body's pose.
    ConvexHull {
        points: Vec<[f32; 3]>,
    },
    /// Convex shapes (sphere, box, capsule, convex hull) at poses in the body frame. The body
    /// is placed at the compound's principal centroid frame; a dump writes the children in that
    /// frame and the body's pose.
    Compound {
        children: Vec<CompoundChildFile>,
    },
}

/// One child of a compound: its shape at `position` (m) and `rotation` (`[x, y, z, w]`,
/// normalized by the loader) in the body frame. Defaults: origin, identity.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompoundChildFile {
    pub shape: ShapeFile,
    #[serde(default)]
    pub position: [f32; 3],
    #[serde(default = "default_rotation")]
    pub rotation: [f32; 4],
}

/// One joint. `anchor` and `axis` are in the world frame at the poses of `bodies`; which of the
/// optional fields a joint takes depends on its kind (DESIGN.md), and any other is an error.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointFile {
    pub kind: JointKindFile,
    pub body_a: BodyReference,
    pub body_b: BodyReference,
    /// m.
    pub anchor: [f32; 3],
    /// Hinge and cone-twist: the hinge or twist axis (normalized by the loader).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis: Option<[f32; 3]>,
    /// Hinge, optional: [lower, upper] angle of B relative to A about the axis (rad).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limits: Option<[f32; 2]>,
    /// Hinge, optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motor: Option<MotorFile>,
    /// Cone-twist: largest angle between the two bodies' twist axes (rad).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub swing_limit: Option<f32>,
    /// Cone-twist: [lower, upper] twist of B relative to A about the axis (rad).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub twist_limits: Option<[f32; 2]>,
    /// Optional: the joint breaks when its impulse in one sub-step exceeds this (N s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub break_impulse: Option<f32>,
    /// Written by dumps (see the module documentation).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state: Option<JointStateFile>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointKindFile {
    Point,
    Hinge,
    ConeTwist,
    Fixed,
}

impl JointKindFile {
    fn name(self) -> &'static str {
        match self {
            JointKindFile::Point => "point",
            JointKindFile::Hinge => "hinge",
            JointKindFile::ConeTwist => "cone_twist",
            JointKindFile::Fixed => "fixed",
        }
    }
}

/// A body named by its index in `bodies` or by its name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BodyReference {
    Index(usize),
    Name(String),
}

impl Serialize for BodyReference {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self {
            BodyReference::Index(index) => serializer.serialize_u64(*index as u64),
            BodyReference::Name(name) => serializer.serialize_str(name),
        }
    }
}

impl<'de> Deserialize<'de> for BodyReference {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = BodyReference;
            fn expecting(&self, formatter: &mut std::fmt::Formatter) -> std::fmt::Result {
                formatter.write_str("a body index (0, 1, ...) or a body name")
            }
            fn visit_u64<E: serde::de::Error>(self, index: u64) -> Result<Self::Value, E> {
                usize::try_from(index)
                    .map(BodyReference::Index)
                    .map_err(|_| E::invalid_value(serde::de::Unexpected::Unsigned(index), &self))
            }
            fn visit_str<E: serde::de::Error>(self, name: &str) -> Result<Self::Value, E> {
                Ok(BodyReference::Name(name.to_string()))
            }
        }
        deserializer.deserialize_any(Visitor)
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotorFile {
    /// rad/s of B relative to A about the axis.
    pub target_speed: f32,
    /// N m, ≥ 0.
    pub max_torque: f32,
}

/// [`JointState`] field for field; vectors in the frame of the body they name.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointStateFile {
    pub local_anchor_a: [f32; 3],
    pub local_anchor_b: [f32; 3],
    pub local_axis_a: [f32; 3],
    pub local_axis_b: [f32; 3],
    pub local_reference_a: [f32; 3],
    pub local_reference_b: [f32; 3],
    /// [x, y, z, w]; kept as written (not normalized), so that a dump reloads bitwise.
    pub relative_rotation: [f32; 4],
    pub point_impulse: [f32; 3],
    pub angular_impulse: [f32; MAX_ANGULAR_ROWS],
    pub broken: bool,
}

/// One persistent contact: the two bodies (indices into `bodies`) and its points' impulses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactFile {
    pub bodies: [usize; 2],
    /// For a contact with a triangle mesh: the triangle (the child manifold's key).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub child: Option<u32>,
    pub points: Vec<ContactPointFile>,
    /// Where the narrowphase computed the points, which lets it move them with the bodies
    /// instead of computing them again; without it, the next step computes them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cache: Option<ContactCacheFile>,
}

/// A contact's [`ManifoldCache`](crate::stages::narrowphase::ManifoldCache): the second body's
/// pose in the first's frame when the points were computed, the margin they were computed
/// for, the normal in the first body's frame and each point's separation then.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactCacheFile {
    pub position: [f32; 3],
    /// [x, y, z, w], unit.
    pub rotation: [f32; 4],
    /// Unit.
    pub normal: [f32; 3],
    pub margin: f32,
    /// One per point of the contact.
    pub separations: Vec<f32>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactPointFile {
    /// Feature id of the point (see the narrowphase).
    pub id: u32,
    /// The point in the frame of the first body of `bodies` (m).
    pub anchor: [f32; 3],
    pub normal_impulse: f32,
    pub tangent_impulse: [f32; 2],
}

// A scene file's defaults are the engine's (`StepConfig::default()`), written once.
fn default_gravity() -> [f32; 3] {
    StepConfig::default().gravity.to_array()
}
fn default_dt() -> f32 {
    StepConfig::default().dt
}
fn default_substeps() -> u32 {
    StepConfig::default().substeps
}
fn default_solver_iterations() -> u32 {
    StepConfig::default().solver_iterations
}
fn default_mass() -> f32 {
    1.0
}
fn default_rotation() -> [f32; 4] {
    [0.0, 0.0, 0.0, 1.0]
}
fn default_friction() -> f32 {
    0.5
}

/// A validated scene: step settings, bodies, joints and warm-start contacts.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub config: StepConfig,
    pub bodies: Vec<BodyDesc>,
    /// Sleep state of each body, index for index with `bodies`; empty when all are awake and
    /// have not rested (a scene that starts afresh).
    pub sleep: Vec<BodySleep>,
    pub joints: Vec<SceneJoint>,
    /// (body index, body index, impulses by feature id).
    pub contacts: Vec<(usize, usize, PairContact)>,
    /// (body index, body index, triangle, impulses by feature id): child manifolds of pairs
    /// with a mesh.
    pub child_contacts: Vec<(usize, usize, u32, PairContact)>,
}

/// A body's sleep state in a scene: its rest time (s) and, asleep, its island's number.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BodySleep {
    pub timer: f32,
    pub island: Option<u32>,
}

/// A joint of a scene: a [`JointDesc`] whose bodies are indices into [`Scene::bodies`].
#[derive(Clone, Debug, PartialEq)]
pub struct SceneJoint {
    pub kind: JointKind,
    pub body_a: usize,
    pub body_b: usize,
    /// World frame, at the bodies' poses in the scene (m).
    pub anchor: Vec3,
    pub break_impulse: Option<f32>,
    /// Frames and impulses of a dumped joint; `None` makes the joint at the bodies' poses.
    pub state: Option<JointState>,
}

impl SceneJoint {
    pub fn new(kind: JointKind, body_a: usize, body_b: usize, anchor: Vec3) -> Self {
        Self {
            kind,
            body_a,
            body_b,
            anchor,
            break_impulse: None,
            state: None,
        }
    }

    /// The joint's state as [`Scene::build`] gives it to the world: the dumped `state`, or a
    /// new joint's at the poses of its bodies in `bodies` (the scene's). `None` if either
    /// body index is out of range.
    pub fn state_in(&self, bodies: &[BodyDesc]) -> Option<JointState> {
        if let Some(state) = self.state {
            return Some(state);
        }
        let pose = |body: &BodyDesc| (body.position, body.unit_rotation());
        Some(JointState::new(
            self.kind,
            self.anchor,
            pose(bodies.get(self.body_a)?),
            pose(bodies.get(self.body_b)?),
        ))
    }
}

impl Scene {
    /// An empty scene with the default settings.
    pub fn new(config: StepConfig) -> Self {
        Self {
            config,
            bodies: Vec::new(),
            sleep: Vec::new(),
            joints: Vec::new(),
            contacts: Vec::new(),
            child_contacts: Vec::new(),
        }
    }

    /// Reads and validates a scene file; `obj` paths are relative to its folder.
    pub fn load(path: &Path) -> Result<Self, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.display().to_string(),
            source,
        })?;
        let folder = path.parent().unwrap_or(Path::new(""));
        Self::from_file_in(&parse(&text)?, folder)
    }

    /// Parses and validates scene JSON; `obj` paths are relative to the working directory.
    pub fn from_json(text: &str) -> Result<Self, SceneError> {
        Self::from_file(&parse(text)?)
    }

    /// Validates a parsed scene file; `obj` paths are relative to the working directory.
    pub fn from_file(file: &SceneFile) -> Result<Self, SceneError> {
        Self::from_file_in(file, Path::new(""))
    }

    /// Validates a parsed scene file whose relative `obj` paths start at `folder`.
    pub fn from_file_in(file: &SceneFile, folder: &Path) -> Result<Self, SceneError> {
        let invalid = |field: String, message: String| SceneError::Invalid { field, message };
        let config = StepConfig {
            gravity: Vec3::from_array(file.gravity),
            dt: file.dt,
            substeps: file.substeps,
            solver_iterations: file.solver_iterations,
            ..StepConfig::default()
        };
        config
            .validate()
            .map_err(|e| invalid("scene".into(), e.to_string()))?;
        let mut names = std::collections::HashSet::new();
        let mut bodies = Vec::with_capacity(file.bodies.len());
        let mut sleep = Vec::new();
        for (i, body) in file.bodies.iter().enumerate() {
            let desc = body_desc(body, folder)
                .map_err(|(field, message)| invalid(format!("bodies[{i}].{field}"), message))?;
            if !(body.sleep_timer.is_finite() && body.sleep_timer >= 0.0) {
                return Err(invalid(
                    format!("bodies[{i}].sleep_timer"),
                    format!("must be finite and >= 0, got {}", body.sleep_timer),
                ));
            }
            if body.island.is_some() && desc.is_static() {
                return Err(invalid(
                    format!("bodies[{i}].island"),
                    "a static body never sleeps; only dynamic bodies belong to islands".into(),
                ));
            }
            if body.sleep_timer != 0.0 || body.island.is_some() {
                sleep.resize(i, BodySleep::default());
                sleep.push(BodySleep {
                    timer: body.sleep_timer,
                    island: body.island,
                });
            }
            if let Some(name) = &desc.name
                && !names.insert(name.clone())
            {
                return Err(invalid(
                    format!("bodies[{i}].name"),
                    format!("{name:?} is used by an earlier body; names must be unique"),
                ));
            }
            bodies.push(desc);
        }
        if !sleep.is_empty() {
            sleep.resize(bodies.len(), BodySleep::default());
        }
        let mut joints = Vec::with_capacity(file.joints.len());
        for (i, joint) in file.joints.iter().enumerate() {
            let joint = scene_joint(joint, &bodies)
                .map_err(|(field, message)| invalid(format!("joints[{i}]{field}"), message))?;
            joints.push(joint);
        }
        let mut contacts = Vec::with_capacity(file.contacts.len());
        let mut child_contacts = Vec::new();
        for (i, contact) in file.contacts.iter().enumerate() {
            let [a, b] = contact.bodies;
            if a >= bodies.len() || b >= bodies.len() || a == b {
                return Err(invalid(
                    format!("contacts[{i}].bodies"),
                    format!(
                        "[{a}, {b}] must name two different bodies of the {} in `bodies`",
                        bodies.len()
                    ),
                ));
            }
            if contact.points.len() > crate::collision::manifold::MAX_MANIFOLD_POINTS {
                return Err(invalid(
                    format!("contacts[{i}].points"),
                    "at most 4 points".into(),
                ));
            }
            let mut pair = PairContact::default();
            for (j, point) in contact.points.iter().enumerate() {
                let numbers = [
                    point.normal_impulse,
                    point.tangent_impulse[0],
                    point.tangent_impulse[1],
                    point.anchor[0],
                    point.anchor[1],
                    point.anchor[2],
                ];
                if !numbers.iter().all(|v| v.is_finite()) {
                    return Err(invalid(
                        format!("contacts[{i}].points[{j}]"),
                        "impulses and anchor must be finite".into(),
                    ));
                }
                pair.manifold
                    .push(crate::collision::manifold::ContactPoint {
                        anchor: Vec3::from_array(point.anchor),
                        ..crate::collision::manifold::ContactPoint::new(Vec3::ZERO, 0.0, point.id)
                    });
                pair.impulses[j] = PointImpulse {
                    normal: point.normal_impulse,
                    tangent: point.tangent_impulse,
                };
            }
            if let Some(cache) = &contact.cache {
                let at = format!("contacts[{i}].cache");
                if contact.child.is_some() {
                    // A mesh's child manifolds are computed afresh each step.
                    return Err(invalid(
                        at,
                        "a contact with a mesh triangle keeps no cache".into(),
                    ));
                }
                pair.cache = manifold_cache(cache, contact.points.len())
                    .map_err(|message| invalid(at, message))?;
            }
            match contact.child {
                Some(child) => child_contacts.push((a, b, child, pair)),
                None => contacts.push((a, b, pair)),
            }
        }
        Ok(Scene {
            config,
            bodies,
            sleep,
            joints,
            contacts,
            child_contacts,
        })
    }

    /// Builds a world holding the scene's bodies, in order (body `i` gets slot `i`).
    pub fn build(&self) -> Result<World, SceneError> {
        let mut world = World::new(self.config).map_err(|e| SceneError::Invalid {
            field: "scene".into(),
            message: e.to_string(),
        })?;
        let mut handles = Vec::with_capacity(self.bodies.len());
        for (i, desc) in self.bodies.iter().enumerate() {
            let handle = world
                .add_body(desc.clone())
                .map_err(|e| SceneError::Invalid {
                    field: format!("bodies[{i}]"),
                    message: e.to_string(),
                })?;
            handles.push(handle);
        }
        for (i, joint) in self.joints.iter().enumerate() {
            let field = format!("joints[{i}]");
            let bad = |error: crate::JointError| SceneError::Invalid {
                field: field.clone(),
                message: error.to_string(),
            };
            let (body_a, body_b) = (
                handles
                    .get(joint.body_a)
                    .ok_or_else(|| bad(crate::JointError::StaleBody))?,
                handles
                    .get(joint.body_b)
                    .ok_or_else(|| bad(crate::JointError::StaleBody))?,
            );
            let mut desc = JointDesc::new(joint.kind, *body_a, *body_b, joint.anchor);
            desc.break_impulse = joint.break_impulse;
            let handle = world.add_joint(desc).map_err(bad)?;
            if let Some(state) = &joint.state {
                world.restore_joint_state(handle, state).map_err(bad)?;
            }
        }
        for (i, &(a, b, contact)) in self.contacts.iter().enumerate() {
            world
                .restore_contact(handles[a], handles[b], contact)
                .map_err(|e| SceneError::Invalid {
                    field: format!("contacts[{i}]"),
                    message: e.to_string(),
                })?;
        }
        for (i, &(a, b, child, contact)) in self.child_contacts.iter().enumerate() {
            world
                .restore_child_contact(handles[a], handles[b], child, contact)
                .map_err(|e| SceneError::Invalid {
                    field: format!("contacts[{}]", self.contacts.len() + i),
                    message: e.to_string(),
                })?;
        }
        if !self.sleep.is_empty() {
            let states: Vec<_> = handles
                .iter()
                .zip(&self.sleep)
                .map(|(&handle, state)| (handle, state.timer, state.island))
                .collect();
            // The loader checked each rest time above.
            world
                .restore_sleep(&states)
                .map_err(|e| SceneError::Invalid {
                    field: "bodies[].sleep_timer".into(),
                    message: e.to_string(),
                })?;
        }
        Ok(world)
    }

    /// The world's current state as a scene: loading it continues the run.
    pub fn from_world(world: &World) -> Self {
        let handles: Vec<_> = world.bodies().collect();
        let mut index_of = std::collections::HashMap::new();
        let mut bodies = Vec::with_capacity(handles.len());
        let current = world.current_bodies_or_host();
        for (i, &handle) in handles.iter().enumerate() {
            index_of.insert(handle, i);
            // Handles from `bodies()` are live, so `body_desc_in` cannot fail.
            if let Ok(desc) = world.body_desc_in(handle, current) {
                bodies.push(desc);
            }
        }
        let joints = world
            .joints()
            .filter_map(|(_, joint)| {
                let (a, b) = (joint.body_a, joint.body_b);
                let body_a = *index_of.get(&world.handle_of(a))?;
                let body_b = *index_of.get(&world.handle_of(b))?;
                // Anchor and axis where body A carries them now; the state keeps the frames.
                let pose_a = &current.0[a as usize];
                let axis = pose_a.rotation * joint.local_axis_a;
                let kind = match joint.kind {
                    JointKind::Hinge { limits, motor, .. } => JointKind::Hinge {
                        axis,
                        limits,
                        motor,
                    },
                    JointKind::ConeTwist {
                        swing_limit,
                        twist_limits,
                        ..
                    } => JointKind::ConeTwist {
                        axis,
                        swing_limit,
                        twist_limits,
                    },
                    other @ (JointKind::Point | JointKind::Fixed) => other,
                };
                Some(SceneJoint {
                    kind,
                    body_a,
                    body_b,
                    anchor: pose_a.transform().transform_point(joint.local_anchor_a),
                    break_impulse: joint.break_impulse,
                    state: Some(joint.state()),
                })
            })
            .collect();
        let contacts = world
            .contacts()
            .filter_map(|(a, b, contact)| Some((*index_of.get(&a)?, *index_of.get(&b)?, *contact)))
            .collect();
        let mut sleep: Vec<BodySleep> = handles
            .iter()
            .map(|&handle| {
                let state = world.sleep_state(handle.index());
                BodySleep {
                    timer: state.timer,
                    island: state.is_asleep().then_some(state.island),
                }
            })
            .collect();
        if sleep.iter().all(|state| *state == BodySleep::default()) {
            sleep.clear();
        }
        let child_contacts = world
            .child_contacts()
            .filter_map(|(a, b, child, contact)| {
                Some((*index_of.get(&a)?, *index_of.get(&b)?, child, *contact))
            })
            .collect();
        Scene {
            config: *world.config(),
            bodies,
            sleep,
            joints,
            contacts,
            child_contacts,
        }
    }

    /// The scene as a JSON document.
    pub fn to_file(&self) -> SceneFile {
        SceneFile {
            gravity: self.config.gravity.to_array(),
            dt: self.config.dt,
            substeps: self.config.substeps,
            solver_iterations: self.config.solver_iterations,
            bodies: self
                .bodies
                .iter()
                .enumerate()
                .map(|(i, desc)| BodyFile {
                    sleep_timer: self.sleep.get(i).map_or(0.0, |s| s.timer),
                    island: self.sleep.get(i).and_then(|s| s.island),
                    ..body_file(desc)
                })
                .collect(),
            joints: self
                .joints
                .iter()
                .map(|joint| joint_file(joint, &self.bodies))
                .collect(),
            contacts: self
                .contacts
                .iter()
                .map(|(a, b, contact)| contact_file([*a, *b], None, contact))
                .chain(
                    self.child_contacts.iter().map(|(a, b, child, contact)| {
                        contact_file([*a, *b], Some(*child), contact)
                    }),
                )
                .collect(),
        }
    }

    pub fn to_json(&self) -> String {
        // Serializing plain numbers, strings and arrays cannot fail.
        serde_json::to_string_pretty(&self.to_file()).unwrap_or_default()
    }

    /// Writes the scene as JSON to `path`.
    pub fn save(&self, path: &Path) -> Result<(), SceneError> {
        std::fs::write(path, self.to_json()).map_err(|source| SceneError::Write {
            path: path.display().to_string(),
            source,
        })
    }
}

/// A body of the file as a description, or (field, message) of the first problem.
fn body_desc(body: &BodyFile, folder: &Path) -> Result<BodyDesc, (String, String)> {
    let shape = match &body.shape {
        ShapeFile::Trimesh { vertices, indices } => {
            let vertices = vertices.iter().copied().map(Vec3::from_array).collect();
            let mesh = TriMesh::from_flat_indices(vertices, indices)
                .map_err(|error| ("shape.trimesh".to_string(), error.to_string()))?;
            Shape::trimesh(mesh)
        }
        ShapeFile::Obj { path, hull: false } => {
            let mesh = load_obj(&folder.join(path))
                .map_err(|message| ("shape.obj.path".to_string(), message))?;
            Shape::trimesh(mesh)
        }
        ShapeFile::Obj { path, hull: true } => {
            let path = folder.join(path);
            let (vertices, _) =
                read_obj(&path).map_err(|message| ("shape.obj.path".to_string(), message))?;
            Shape::convex_hull(&vertices).map_err(|error| {
                (
                    "shape.obj.hull".to_string(),
                    format!(
                        "{}: no convex hull of its vertices: {error}",
                        path.display()
                    ),
                )
            })?
        }
        ShapeFile::Sphere { radius } => Shape::sphere(*radius),
        ShapeFile::Box { half_extents } => Shape::cuboid(Vec3::from_array(*half_extents)),
        ShapeFile::Capsule {
            radius,
            half_height,
        } => Shape::capsule(*radius, *half_height),
        ShapeFile::Plane { normal, offset } => Shape::plane(Vec3::from_array(*normal), *offset),
        ShapeFile::ConvexHull { points } => {
            let points: Vec<Vec3> = points.iter().map(|&p| Vec3::from_array(p)).collect();
            Shape::convex_hull(&points)
                .map_err(|error| ("shape.convex_hull.points".to_string(), error.to_string()))?
        }
        ShapeFile::Compound { children } => compound(children)?,
    };
    // `World::add_body` normalizes a rotation that is off unit length.
    let rotation = Quat::from_array(body.rotation);
    let desc = BodyDesc {
        shape,
        position: Vec3::from_array(body.position),
        rotation,
        mass: body.mass,
        linear_velocity: Vec3::from_array(body.linear_velocity),
        angular_velocity: Vec3::from_array(body.angular_velocity),
        friction: body.friction,
        restitution: body.restitution,
        name: body.name.clone(),
    };
    desc.validate()
        .map_err(|error| (field_of(&body.shape, &error), error.requirement()))?;
    Ok(desc)
}

/// The compound of `children`, or (field, message) of the first bad child.
fn compound(children: &[CompoundChildFile]) -> Result<Shape, (String, String)> {
    let field = |index: usize, part: &str| format!("shape.compound.children[{index}].{part}");
    let mut parts = Vec::with_capacity(children.len());
    for (index, child) in children.iter().enumerate() {
        let shape = match &child.shape {
            ShapeFile::Sphere { radius } => Shape::sphere(*radius),
            ShapeFile::Box { half_extents } => Shape::cuboid(Vec3::from_array(*half_extents)),
            ShapeFile::Capsule {
                radius,
                half_height,
            } => Shape::capsule(*radius, *half_height),
            ShapeFile::ConvexHull { points } => {
                let points: Vec<Vec3> = points.iter().map(|&p| Vec3::from_array(p)).collect();
                Shape::convex_hull(&points).map_err(|error| {
                    (field(index, "shape.convex_hull.points"), error.to_string())
                })?
            }
            other @ (ShapeFile::Plane { .. }
            | ShapeFile::Trimesh { .. }
            | ShapeFile::Obj { .. }
            | ShapeFile::Compound { .. }) => {
                return Err((
                    field(index, "shape"),
                    format!(
                        "a compound's children must be convex (sphere, box, capsule, \
                         convex_hull), not {}",
                        shape_name(other)
                    ),
                ));
            }
        };
        parts.push(CompoundChild {
            shape,
            pose: Transform::new(
                Vec3::from_array(child.position),
                Quat::from_array(child.rotation),
            ),
        });
    }
    Shape::compound(parts).map_err(|error| {
        let at = match &error {
            CompoundError::Empty | CompoundError::TooManyChildren { .. } => {
                "shape.compound.children".to_string()
            }
            CompoundError::UnsupportedChild { index, .. }
            | CompoundError::BadChildSize { index, .. } => field(*index, "shape"),
            CompoundError::PositionNotFinite { index } => field(*index, "position"),
            CompoundError::RotationNotFinite { index } | CompoundError::ZeroRotation { index } => {
                field(*index, "rotation")
            }
        };
        (at, error.to_string())
    })
}

/// The cache of a contact file's `points` points, checked.
fn manifold_cache(file: &ContactCacheFile, points: usize) -> Result<ManifoldCache, String> {
    let numbers = (file.position.iter())
        .chain(&file.rotation)
        .chain(&file.normal)
        .chain(&file.separations)
        .chain([&file.margin]);
    if !numbers.into_iter().all(|v| v.is_finite()) {
        return Err("every number must be finite".into());
    }
    if file.separations.len() != points {
        return Err(format!(
            "{} separations for {points} points: one per point",
            file.separations.len()
        ));
    }
    let rotation = Quat::from_array(file.rotation);
    let normal = Vec3::from_array(file.normal);
    // The narrowphase turns points by the rotation and measures along the normal, unnormalized:
    // 1e-5 off unit moves a point 1 m away by 0.01 mm, a hundredth of the cache's tolerance.
    if (rotation.length() - 1.0).abs() > 1.0e-5 || (normal.length() - 1.0).abs() > 1.0e-5 {
        return Err("rotation and normal must be unit".into());
    }
    let mut separations = [0.0; crate::collision::manifold::MAX_MANIFOLD_POINTS];
    separations[..points].copy_from_slice(&file.separations);
    Ok(ManifoldCache {
        position: Vec3::from_array(file.position),
        margin: file.margin,
        rotation,
        normal,
        valid: 1,
        separations,
    })
}

fn contact_file(bodies: [usize; 2], child: Option<u32>, contact: &PairContact) -> ContactFile {
    let cache = &contact.cache;
    let count = contact.manifold.count as usize;
    ContactFile {
        bodies,
        child,
        cache: (cache.valid != 0).then(|| ContactCacheFile {
            position: cache.position.to_array(),
            rotation: cache.rotation.to_array(),
            normal: cache.normal.to_array(),
            margin: cache.margin,
            separations: cache.separations[..count].to_vec(),
        }),
        points: contact
            .manifold
            .points()
            .iter()
            .zip(&contact.impulses)
            .map(|(point, impulse)| ContactPointFile {
                id: point.id,
                anchor: point.anchor.to_array(),
                normal_impulse: impulse.normal,
                tangent_impulse: impulse.tangent,
            })
            .collect(),
    }
}

/// Parses scene JSON; errors name the field.
fn parse(text: &str) -> Result<SceneFile, SceneError> {
    let deserializer = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(deserializer).map_err(|error| {
        let path = error.path().to_string();
        let inner = error.into_inner();
        // A syntax error before any field was reached: the file is not JSON at all.
        let at_root = path == ".";
        let field = if at_root { "scene".to_string() } else { path };
        let syntax = matches!(
            inner.classify(),
            serde_json::error::Category::Syntax | serde_json::error::Category::Eof
        );
        let message = if at_root && syntax {
            format!("not valid JSON: {inner}")
        } else {
            inner.to_string()
        };
        SceneError::Parse { field, message }
    })
}

/// All objects of an OBJ file as one triangle mesh (polygons fanned into triangles), or a
/// message naming the file and the problem.
fn load_obj(path: &Path) -> Result<TriMesh, String> {
    let (vertices, triangles) = read_obj(path)?;
    TriMesh::new(vertices, triangles).map_err(|error| format!("{}: {error}", path.display()))
}

/// The vertices and triangles of all objects of an OBJ file, or a message naming the file.
fn read_obj(path: &Path) -> Result<(Vec<Vec3>, Vec<[u32; 3]>), String> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _materials) =
        tobj::load_obj(path, &options).map_err(|error| format!("{}: {error}", path.display()))?;
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    for model in &models {
        let base = vertices.len() as u32;
        let mesh = &model.mesh;
        vertices.extend(
            mesh.positions
                .chunks_exact(3)
                .map(|p| Vec3::new(p[0], p[1], p[2])),
        );
        triangles.extend(
            mesh.indices
                .chunks_exact(3)
                .map(|t| [base + t[0], base + t[1], base + t[2]]),
        );
    }
    Ok((vertices, triangles))
}

/// The shape's key in a scene file.
fn shape_name(shape: &ShapeFile) -> &'static str {
    match shape {
        ShapeFile::Sphere { .. } => "sphere",
        ShapeFile::Box { .. } => "box",
        ShapeFile::Capsule { .. } => "capsule",
        ShapeFile::Plane { .. } => "plane",
        ShapeFile::Trimesh { .. } => "trimesh",
        ShapeFile::Obj { .. } => "obj",
        ShapeFile::ConvexHull { .. } => "convex_hull",
        ShapeFile::Compound { .. } => "compound",
    }
}

/// The scene-file field a body error is about.
fn field_of(shape: &ShapeFile, error: &BodyError) -> String {
    let shape_name = shape_name(shape);
    match error {
        BodyError::NotFinite { field }
        | BodyError::NotPositive { field, .. }
        | BodyError::Negative { field, .. } => match *field {
            "radius" | "half_extents" | "half_height" => format!("shape.{shape_name}.{field}"),
            "plane" => "shape.plane".into(),
            other => other.into(),
        },
        BodyError::RestitutionOutOfRange(_) => "restitution".into(),
        BodyError::ZeroRotation => "rotation".into(),
        BodyError::ZeroNormal => "shape.plane.normal".into(),
        BodyError::DynamicPlane | BodyError::DynamicTriMesh => "mass".into(),
        BodyError::StaleHandle | BodyError::DuplicateName(_) => "name".into(),
        BodyError::CompoundMeshKeys { .. } => format!("shape.{shape_name}"),
        BodyError::ContactsReadback(_) => "contacts".into(),
        BodyError::BodiesReadback(_) => "bodies".into(),
    }
}

fn body_file(desc: &BodyDesc) -> BodyFile {
    BodyFile {
        name: desc.name.clone(),
        shape: shape_file(&desc.shape),
        mass: desc.mass,
        position: desc.position.to_array(),
        rotation: desc.rotation.to_array(),
        linear_velocity: desc.linear_velocity.to_array(),
        angular_velocity: desc.angular_velocity.to_array(),
        friction: desc.friction,
        restitution: desc.restitution,
        sleep_timer: 0.0,
        island: None,
    }
}

fn shape_file(shape: &Shape) -> ShapeFile {
    match shape {
        Shape::Sphere(s) => ShapeFile::Sphere { radius: s.radius },
        Shape::Cuboid(c) => ShapeFile::Box {
            half_extents: c.half_extents.to_array(),
        },
        Shape::Capsule(c) => ShapeFile::Capsule {
            radius: c.radius,
            half_height: c.half_height,
        },
        Shape::Plane(p) => ShapeFile::Plane {
            normal: p.normal.to_array(),
            offset: p.offset,
        },
        // An OBJ mesh is written out as its triangles: the dump stands alone.
        Shape::TriMesh(mesh) => ShapeFile::Trimesh {
            vertices: mesh.vertices().iter().map(|v| v.to_array()).collect(),
            indices: mesh.triangles().iter().flatten().copied().collect(),
        },
        // The stored vertices, in the hull frame the body's pose refers to (a body's hull
        // has the identity local frame, so the points load back to the same hull).
        Shape::ConvexHull(hull) => ShapeFile::ConvexHull {
            points: hull.vertices().iter().map(|v| v.to_array()).collect(),
        },
        // The children in the compound frame the body's pose refers to, as for hulls.
        Shape::Compound(compound) => ShapeFile::Compound {
            children: compound
                .children()
                .iter()
                .map(|child| CompoundChildFile {
                    shape: shape_file(&child.shape),
                    position: child.pose.position.to_array(),
                    rotation: child.pose.rotation.to_array(),
                })
                .collect(),
        },
    }
}

/// A joint of the file with its bodies resolved against `bodies`, or (field after `joints[i]`,
/// message) of the first problem.
fn scene_joint(joint: &JointFile, bodies: &[BodyDesc]) -> Result<SceneJoint, (String, String)> {
    let resolve = |field: &str, reference: &BodyReference| match reference {
        BodyReference::Index(index) if *index < bodies.len() => Ok(*index),
        BodyReference::Index(index) => Err((
            format!(".{field}"),
            format!(
                "body index {index} is out of range: the scene has {} bodies",
                bodies.len()
            ),
        )),
        BodyReference::Name(name) => bodies
            .iter()
            .position(|body| body.name.as_deref() == Some(name.as_str()))
            .ok_or_else(|| (format!(".{field}"), format!("no body is named {name:?}"))),
    };
    let body_a = resolve("body_a", &joint.body_a)?;
    let body_b = resolve("body_b", &joint.body_b)?;
    if bodies[body_a].is_static() && bodies[body_b].is_static() {
        return Err((
            String::new(),
            "both bodies are static (mass 0); a joint needs at least one dynamic body".into(),
        ));
    }

    // Which optional fields each kind takes: a field the kind does not use is an error rather
    // than silently ignored, and a field it needs must be there.
    let kind_name = joint.kind.name();
    let unused = |field: &str, present: bool| {
        if present {
            Err((
                format!(".{field}"),
                format!("a {kind_name} joint has no {field}; remove it"),
            ))
        } else {
            Ok(())
        }
    };
    let required = |field: &str| {
        (
            format!(".{field}"),
            format!("a {kind_name} joint needs {field}"),
        )
    };
    let pair = |values: [f32; 2]| (values[0], values[1]);
    let kind = match joint.kind {
        JointKindFile::Point | JointKindFile::Fixed => {
            unused("axis", joint.axis.is_some())?;
            unused("limits", joint.limits.is_some())?;
            unused("motor", joint.motor.is_some())?;
            unused("swing_limit", joint.swing_limit.is_some())?;
            unused("twist_limits", joint.twist_limits.is_some())?;
            if joint.kind == JointKindFile::Point {
                JointKind::Point
            } else {
                JointKind::Fixed
            }
        }
        JointKindFile::Hinge => {
            unused("swing_limit", joint.swing_limit.is_some())?;
            unused("twist_limits", joint.twist_limits.is_some())?;
            JointKind::Hinge {
                axis: Vec3::from_array(joint.axis.ok_or_else(|| required("axis"))?),
                limits: joint.limits.map(pair),
                motor: joint.motor.as_ref().map(|motor| Motor {
                    target_speed: motor.target_speed,
                    max_torque: motor.max_torque,
                }),
            }
        }
        JointKindFile::ConeTwist => {
            unused("limits", joint.limits.is_some())?;
            unused("motor", joint.motor.is_some())?;
            JointKind::ConeTwist {
                axis: Vec3::from_array(joint.axis.ok_or_else(|| required("axis"))?),
                swing_limit: joint.swing_limit.ok_or_else(|| required("swing_limit"))?,
                twist_limits: pair(joint.twist_limits.ok_or_else(|| required("twist_limits"))?),
            }
        }
    };
    // The description's own checks, against stand-in handles: the bodies are known to exist.
    let handle = |index: usize| crate::BodyHandle {
        index: index as u32,
        generation: 0,
    };
    let mut desc = JointDesc::new(
        kind,
        handle(body_a),
        handle(body_b),
        Vec3::from_array(joint.anchor),
    );
    desc.break_impulse = joint.break_impulse;
    desc.validate().map_err(|error| {
        let field = error
            .field()
            .map(|field| format!(".{field}"))
            .unwrap_or_default();
        (field, error.requirement())
    })?;

    let state = joint.state.as_ref().map(|state| JointState {
        local_anchor_a: Vec3::from_array(state.local_anchor_a),
        local_anchor_b: Vec3::from_array(state.local_anchor_b),
        local_axis_a: Vec3::from_array(state.local_axis_a),
        local_axis_b: Vec3::from_array(state.local_axis_b),
        local_reference_a: Vec3::from_array(state.local_reference_a),
        local_reference_b: Vec3::from_array(state.local_reference_b),
        relative_rotation: Quat::from_array(state.relative_rotation),
        point_impulse: Vec3::from_array(state.point_impulse),
        angular_impulse: state.angular_impulse,
        broken: state.broken,
    });
    if state.is_some_and(|state| !state.is_finite()) {
        return Err((
            ".state".into(),
            "must be finite (no NaN or infinity)".into(),
        ));
    }
    Ok(SceneJoint {
        kind,
        body_a,
        body_b,
        anchor: desc.anchor,
        break_impulse: joint.break_impulse,
        state,
    })
}

fn joint_file(joint: &SceneJoint, bodies: &[BodyDesc]) -> JointFile {
    // Named bodies are written by name, which reads better and survives reordering.
    let reference = |index: usize| match &bodies[index].name {
        Some(name) => BodyReference::Name(name.clone()),
        None => BodyReference::Index(index),
    };
    let mut file = JointFile {
        kind: JointKindFile::Point,
        body_a: reference(joint.body_a),
        body_b: reference(joint.body_b),
        anchor: joint.anchor.to_array(),
        axis: None,
        limits: None,
        motor: None,
        swing_limit: None,
        twist_limits: None,
        break_impulse: joint.break_impulse,
        state: joint.state.as_ref().map(|state| JointStateFile {
            local_anchor_a: state.local_anchor_a.to_array(),
            local_anchor_b: state.local_anchor_b.to_array(),
            local_axis_a: state.local_axis_a.to_array(),
            local_axis_b: state.local_axis_b.to_array(),
            local_reference_a: state.local_reference_a.to_array(),
            local_reference_b: state.local_reference_b.to_array(),
            relative_rotation: state.relative_rotation.to_array(),
            point_impulse: state.point_impulse.to_array(),
            angular_impulse: state.angular_impulse,
            broken: state.broken,
        }),
    };
    match joint.kind {
        JointKind::Point => {}
        JointKind::Fixed => file.kind = JointKindFile::Fixed,
        JointKind::Hinge {
            axis,
            limits,
            motor,
        } => {
            file.kind = JointKindFile::Hinge;
            file.axis = Some(axis.to_array());
            file.limits = limits.map(|(lower, upper)| [lower, upper]);
            file.motor = motor.map(|motor| MotorFile {
                target_speed: motor.target_speed,
                max_torque: motor.max_torque,
            });
        }
        JointKind::ConeTwist {
            axis,
            swing_limit,
            twist_limits: (lower, upper),
        } => {
            file.kind = JointKindFile::ConeTwist;
            file.axis = Some(axis.to_array());
            file.swing_limit = Some(swing_limit);
            file.twist_limits = Some([lower, upper]);
        }
    }
    file
}
