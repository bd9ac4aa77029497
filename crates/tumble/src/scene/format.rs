//! Scene file format v1 (DESIGN.md). Unknown fields are errors and every error names the field
//! (`bodies[3].shape.box.half_extents: must be > 0, got 0`).
//!
//! Beyond DESIGN.md's fields, a dumped scene carries `contacts`: the warm-start impulses of the
//! persistent contacts, so that loading a dump continues the run bitwise (the impulses are
//! solver state, as much a part of the world as the velocities).

use crate::dynamics::body::{BodyDesc, BodyError};
use crate::math::{Quat, Vec3};
use crate::pipeline::config::StepConfig;
use crate::pipeline::world::World;
use crate::shape::Shape;
use crate::stages::narrowphase::{PairContact, PointImpulse};
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
    /// Joints arrive with the joints issue; a scene with joints is refused until then.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub joints: Vec<serde_json::Value>,
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
}

/// One persistent contact: the two bodies (indices into `bodies`) and its points' impulses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactFile {
    pub bodies: [usize; 2],
    pub points: Vec<ContactPointFile>,
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

fn default_gravity() -> [f32; 3] {
    [0.0, -9.81, 0.0]
}
fn default_dt() -> f32 {
    1.0 / 60.0
}
fn default_substeps() -> u32 {
    1
}
fn default_solver_iterations() -> u32 {
    10
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

/// A validated scene: step settings, bodies, and warm-start contacts.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub config: StepConfig,
    pub bodies: Vec<BodyDesc>,
    /// (body index, body index, impulses by feature id).
    pub contacts: Vec<(usize, usize, PairContact)>,
}

impl Scene {
    /// An empty scene with the default settings.
    pub fn new(config: StepConfig) -> Self {
        Self {
            config,
            bodies: Vec::new(),
            contacts: Vec::new(),
        }
    }

    /// Reads and validates a scene file.
    pub fn load(path: &Path) -> Result<Self, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_json(&text)
    }

    /// Parses and validates scene JSON.
    pub fn from_json(text: &str) -> Result<Self, SceneError> {
        let deserializer = &mut serde_json::Deserializer::from_str(text);
        let file: SceneFile = serde_path_to_error::deserialize(deserializer).map_err(|error| {
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
        })?;
        Self::from_file(&file)
    }

    /// Validates a parsed scene file.
    pub fn from_file(file: &SceneFile) -> Result<Self, SceneError> {
        let invalid = |field: String, message: String| SceneError::Invalid { field, message };
        if !file.joints.is_empty() {
            return Err(invalid(
                "joints".into(),
                "joints are not supported yet; remove them to run this scene".into(),
            ));
        }
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
        for (i, body) in file.bodies.iter().enumerate() {
            let desc = body_desc(body)
                .map_err(|(field, message)| invalid(format!("bodies[{i}].{field}"), message))?;
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
        let mut contacts = Vec::with_capacity(file.contacts.len());
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
                        id: point.id,
                        ..Default::default()
                    });
                pair.impulses[j] = PointImpulse {
                    normal: point.normal_impulse,
                    tangent: point.tangent_impulse,
                };
                pair.anchors[j] = Vec3::from_array(point.anchor);
            }
            contacts.push((a, b, pair));
        }
        Ok(Scene {
            config,
            bodies,
            contacts,
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
        for (i, &(a, b, contact)) in self.contacts.iter().enumerate() {
            world
                .restore_contact(handles[a], handles[b], contact)
                .map_err(|e| SceneError::Invalid {
                    field: format!("contacts[{i}]"),
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
        for (i, &handle) in handles.iter().enumerate() {
            index_of.insert(handle, i);
            // Handles from `bodies()` are live, so `body_desc` cannot fail.
            if let Ok(desc) = world.body_desc(handle) {
                bodies.push(desc);
            }
        }
        let contacts = world
            .contacts()
            .filter_map(|(a, b, contact)| Some((*index_of.get(&a)?, *index_of.get(&b)?, *contact)))
            .collect();
        Scene {
            config: *world.config(),
            bodies,
            contacts,
        }
    }

    /// The scene as a JSON document.
    pub fn to_file(&self) -> SceneFile {
        SceneFile {
            gravity: self.config.gravity.to_array(),
            dt: self.config.dt,
            substeps: self.config.substeps,
            solver_iterations: self.config.solver_iterations,
            bodies: self.bodies.iter().map(body_file).collect(),
            joints: Vec::new(),
            contacts: self
                .contacts
                .iter()
                .map(|(a, b, contact)| ContactFile {
                    bodies: [*a, *b],
                    points: contact
                        .manifold
                        .points()
                        .iter()
                        .zip(contact.impulses.iter().zip(&contact.anchors))
                        .map(|(point, (impulse, anchor))| ContactPointFile {
                            id: point.id,
                            anchor: anchor.to_array(),
                            normal_impulse: impulse.normal,
                            tangent_impulse: impulse.tangent,
                        })
                        .collect(),
                })
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
fn body_desc(body: &BodyFile) -> Result<BodyDesc, (String, String)> {
    let shape = match &body.shape {
        ShapeFile::Sphere { radius } => Shape::sphere(*radius),
        ShapeFile::Box { half_extents } => Shape::cuboid(Vec3::from_array(*half_extents)),
        ShapeFile::Capsule {
            radius,
            half_height,
        } => Shape::capsule(*radius, *half_height),
        ShapeFile::Plane { normal, offset } => Shape::plane(Vec3::from_array(*normal), *offset),
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

/// The scene-file field a body error is about.
fn field_of(shape: &ShapeFile, error: &BodyError) -> String {
    let shape_name = match shape {
        ShapeFile::Sphere { .. } => "sphere",
        ShapeFile::Box { .. } => "box",
        ShapeFile::Capsule { .. } => "capsule",
        ShapeFile::Plane { .. } => "plane",
    };
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
        BodyError::DynamicPlane => "mass".into(),
        BodyError::StaleHandle | BodyError::DuplicateName(_) => "name".into(),
    }
}

fn body_file(desc: &BodyDesc) -> BodyFile {
    let shape = match desc.shape {
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
    };
    BodyFile {
        name: desc.name.clone(),
        shape,
        mass: desc.mass,
        position: desc.position.to_array(),
        rotation: desc.rotation.to_array(),
        linear_velocity: desc.linear_velocity.to_array(),
        angular_velocity: desc.angular_velocity.to_array(),
        friction: desc.friction,
        restitution: desc.restitution,
    }
}
