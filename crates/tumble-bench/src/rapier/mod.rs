//! The peer: rapier3d 0.36, fed the same [`Scene`] as Tumble through one translation
//! ([`translate`]), so any scene Tumble loads runs on both.
//!
//! # What is kept and what differs
//!
//! - Shapes: sphere → `ball`, box → `cuboid` (same half extents), capsule → `capsule_y` (same
//!   `half_height` and `radius`, axis Y in both), plane → rapier's `halfspace` (infinite, as
//!   Tumble's plane), its boundary moved to `offset` along the normal by the collider's local
//!   translation.
//! - Body frame: position, rotation, linear and angular (world frame) velocities as given.
//!   Primitives are centred on the body frame in both engines, so centres of mass coincide.
//! - Mass: the collider gets the body's `mass` (kg); rapier turns it into a uniform density, as
//!   Tumble does, so total mass and inertia match. `mass: 0` → a fixed body.
//! - Materials: friction combines as `GeometricMean` = sqrt(a·b), restitution as `Max`, both
//!   exactly Tumble's rules. Rapier bounces a contact only on the step it appears (or
//!   always, for restitution ≥ 1); Tumble bounces any contact approaching faster than
//!   `restitution_threshold` (1 m/s). Friction: rapier's `Coulomb` model (two friction rows
//!   per point, like Tumble), not its default `Simplified` one (one row per manifold plus a
//!   twist row), so both solve the same friction problem.
//! - Step: same gravity and dt; speculative contact distance = Tumble's `contact_margin` (both
//!   0.02 m by default); the cap on the push-out speed = `max_push_velocity`.
//! - Sleeping is off on both (`can_sleep(false)`); CCD is off (`ccd_enabled(false)` and
//!   `max_ccd_substeps = 0`, which also turns off rapier's automatic CCD against fixed bodies).
//! - Rapier's own speed features stay on, as a user gets them: contact recycling (a pair that
//!   barely moved keeps its contacts without a narrowphase update) and contact clustering.
//! - Joints: each Tumble joint becomes the rapier joint of the same kind with the same frames,
//!   contacts between its bodies off; a joint rapier cannot hold as Tumble does refuses the
//!   scene instead of being dropped ([`joints`]).
//!
//! # Solver settings
//!
//! Both engines run the same kind of solver: one collision pass per step, then sub-steps that
//! each integrate velocities, run biased sweeps with soft contacts, integrate positions and run
//! an unbiased relax sweep (Box2D v3's soft step; rapier's TGS-soft). So the mapping is exact:
//!
//! - [`SolverSettings::Matched`] (engine `rapier`): `num_solver_iterations` = Tumble's
//!   `substeps`, `num_internal_pgs_iterations` = `solver_iterations`, one stabilization (relax)
//!   sweep, contact softness = Tumble's `contact_hertz` and damping ratio (twice the frequency
//!   against fixed bodies, as both engines do). The like-for-like comparison of work.
//! - [`SolverSettings::RapierDefault`] (engine `rapier-default`): rapier's own defaults for the
//!   solver (4 sub-steps, 30 Hz contacts with ζ = 10) with the same dt, materials and margins.

pub mod joints;

use crate::engine::{BodyState, ContactSample, Simulation};
use rapier3d::prelude::*;
use tumble::dynamics::body::BodyDesc;
use tumble::scene::Scene;

/// Which solver settings rapier runs with (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolverSettings {
    /// Tumble's: same sub-steps, sweeps and softness.
    Matched,
    /// Rapier's defaults.
    RapierDefault,
}

/// Rapier's step parameters for a Tumble scene.
pub fn integration_parameters(scene: &Scene, settings: SolverSettings) -> IntegrationParameters {
    let config = &scene.config;
    let common = IntegrationParameters {
        dt: config.dt,
        normalized_prediction_distance: config.contact_margin,
        normalized_max_corrective_velocity: config.max_push_velocity,
        max_ccd_substeps: 0,
        friction_model: FrictionModel::Coulomb,
        ..IntegrationParameters::default()
    };
    match settings {
        SolverSettings::RapierDefault => common,
        SolverSettings::Matched => IntegrationParameters {
            // Zero sub-steps or iterations are refused by Tumble; rapier needs at least one too.
            num_solver_iterations: config.substeps.max(1) as usize,
            num_internal_pgs_iterations: config.solver_iterations.max(1) as usize,
            num_internal_stabilization_iterations: 1,
            contact_softness: SpringCoefficients::new(
                config.contact_hertz,
                config.contact_damping_ratio,
            ),
            static_contact_softness: SpringCoefficients::new(
                2.0 * config.contact_hertz,
                config.contact_damping_ratio,
            ),
            ..common
        },
    }
}

/// The scene as a rapier world; the handles are the scene's bodies, in order. `Err` says why
/// the scene cannot go to rapier faithfully (a joint rapier lacks, [`joints`]).
pub fn translate(
    scene: &Scene,
    settings: SolverSettings,
) -> Result<(PhysicsWorld, Vec<RigidBodyHandle>), String> {
    let mut world = PhysicsWorld {
        gravity: vector(scene.config.gravity),
        integration_parameters: integration_parameters(scene, settings),
        ..PhysicsWorld::default()
    };
    let handles: Vec<_> = scene
        .bodies
        .iter()
        .map(|desc| {
            let (body, collider) = body_and_collider(desc);
            world.insert(body, collider).0
        })
        .collect();
    joints::insert_joints(&mut world, scene, &handles, settings)?;
    Ok((world, handles))
}

fn vector(v: tumble::math::Vec3) -> Vector {
    Vector::new(v.x, v.y, v.z)
}

/// A compound's child as a parry shape: `Compound::new` admits only these four kinds.
fn convex_child(shape: &tumble::Shape) -> SharedShape {
    match shape {
        tumble::Shape::Sphere(sphere) => SharedShape::ball(sphere.radius),
        tumble::Shape::Cuboid(cuboid) => {
            let h = cuboid.half_extents;
            SharedShape::cuboid(h.x, h.y, h.z)
        }
        tumble::Shape::Capsule(capsule) => {
            SharedShape::capsule_y(capsule.half_height, capsule.radius)
        }
        tumble::Shape::ConvexHull(hull) => {
            let points: Vec<_> = hull.vertices().iter().map(|&v| vector(v)).collect();
            SharedShape::convex_hull(&points).expect("a tumble hull is a valid parry hull")
        }
        tumble::Shape::Plane(_) | tumble::Shape::TriMesh(_) | tumble::Shape::Compound(_) => {
            unreachable!("Compound::new refuses {:?} children", shape.kind())
        }
    }
}

fn body_and_collider(desc: &BodyDesc) -> (RigidBodyBuilder, ColliderBuilder) {
    let q = desc.rotation.normalize();
    let pose = Pose::from_parts(
        vector(desc.position),
        Rotation::from_xyzw(q.x, q.y, q.z, q.w),
    );
    let body = if desc.is_static() {
        RigidBodyBuilder::fixed()
    } else {
        RigidBodyBuilder::dynamic()
            .linvel(vector(desc.linear_velocity))
            .angvel(vector(desc.angular_velocity))
    }
    .pose(pose)
    .can_sleep(false)
    .ccd_enabled(false);
    let collider = match &desc.shape {
        tumble::Shape::Sphere(sphere) => ColliderBuilder::ball(sphere.radius),
        tumble::Shape::Cuboid(cuboid) => {
            let h = cuboid.half_extents;
            ColliderBuilder::cuboid(h.x, h.y, h.z)
        }
        tumble::Shape::Capsule(capsule) => {
            ColliderBuilder::capsule_y(capsule.half_height, capsule.radius)
        }
        // Tumble's plane is n·x <= offset; rapier's halfspace is n·x <= 0 in the collider
        // frame, so the collider sits at offset·n.
        tumble::Shape::Plane(plane) => {
            ColliderBuilder::new(SharedShape::halfspace(vector(plane.normal)))
                .translation(vector(plane.normal * plane.offset))
        }
        // Rapier's internal-edge fix, the counterpart of Tumble's active edges; it needs a
        // manifold mesh, so a mesh it refuses goes in without it.
        tumble::Shape::TriMesh(mesh) => {
            let vertices: Vec<Vector> = mesh.vertices().iter().map(|&v| vector(v)).collect();
            let indices = mesh.triangles().to_vec();
            ColliderBuilder::trimesh_with_flags(
                vertices.clone(),
                indices.clone(),
                TriMeshFlags::FIX_INTERNAL_EDGES,
            )
            .or_else(|_| ColliderBuilder::trimesh(vertices, indices))
            .expect("rapier refuses only empty meshes, and TriMesh::new refused those")
        }
        // The body frame is the hull's frame (its centroid), so the points go in as stored.
        tumble::Shape::ConvexHull(hull) => {
            let points: Vec<_> = hull.vertices().iter().map(|&v| vector(v)).collect();
            // A ConvexHull encloses volume by construction, so parry's hull of it exists.
            ColliderBuilder::convex_hull(&points).expect("a tumble hull is a valid parry hull")
        }
        // The body frame is the compound's (its centroid), so the children go in at their
        // stored poses; rapier weighs them by volume as Tumble does.
        tumble::Shape::Compound(compound) => ColliderBuilder::compound(
            compound
                .children()
                .iter()
                .map(|child| {
                    let q = child.pose.rotation;
                    let pose = Pose::from_parts(
                        vector(child.pose.position),
                        Rotation::from_xyzw(q.x, q.y, q.z, q.w),
                    );
                    (pose, convex_child(&child.shape))
                })
                .collect(),
        ),
    }
    .friction(desc.friction)
    .friction_combine_rule(CoefficientCombineRule::GeometricMean)
    .restitution(desc.restitution)
    .restitution_combine_rule(CoefficientCombineRule::Max);
    // A fixed body ignores mass; a dynamic one gets the scene's mass at uniform density.
    let collider = if desc.is_static() {
        collider
    } else {
        collider.mass(desc.mass)
    };
    (body, collider)
}

/// A rapier world stepping a Tumble scene.
pub struct RapierSimulation {
    world: PhysicsWorld,
    /// Handles of the scene's dynamic bodies, in scene order.
    dynamic_bodies: Vec<RigidBodyHandle>,
    stage_totals: RapierStages,
    steps_since_reset: usize,
}

/// Rapier's stage timers summed over steps (ms), from its `profiler` counters.
#[derive(Clone, Copy, Debug, Default)]
struct RapierStages {
    user_changes: f64,
    broadphase: f64,
    narrowphase: f64,
    islands: f64,
    solver: f64,
    update: f64,
}

impl RapierSimulation {
    /// `Err` says why the scene cannot run on rapier faithfully ([`translate`]).
    pub fn new(scene: &Scene, settings: SolverSettings) -> Result<Self, String> {
        let (world, handles) = translate(scene, settings)?;
        let dynamic_bodies = handles
            .into_iter()
            .zip(&scene.bodies)
            .filter(|(_, desc)| !desc.is_static())
            .map(|(handle, _)| handle)
            .collect();
        Ok(Self {
            world,
            dynamic_bodies,
            stage_totals: RapierStages::default(),
            steps_since_reset: 0,
        })
    }
}

impl Simulation for RapierSimulation {
    fn step(&mut self) {
        self.world.step();
        // The counters hold the last rapier step only: add them up here.
        let counters = &self.world.physics_pipeline.counters;
        let totals = &mut self.stage_totals;
        totals.user_changes += counters.stages.user_changes.time_ms();
        totals.broadphase +=
            counters.cd.broad_phase_time.time_ms() + counters.cd.final_broad_phase_time.time_ms();
        totals.narrowphase += counters.cd.narrow_phase_time.time_ms();
        totals.islands += counters.stages.island_construction_time.time_ms();
        totals.solver += counters.stages.solver_time.time_ms();
        totals.update += counters.stages.update_time.time_ms();
        self.steps_since_reset += 1;
    }

    fn contact_sample(&self) -> ContactSample {
        let mut sample = ContactSample::default();
        for pair in self.world.narrow_phase.contact_pairs() {
            sample.pairs += 1;
            for manifold in pair.manifolds() {
                sample.contacts += manifold.points.len();
                for point in &manifold.points {
                    sample.max_penetration = sample.max_penetration.max(-point.dist);
                }
            }
        }
        sample
    }

    fn dynamic_states(&self) -> Vec<BodyState> {
        self.dynamic_bodies
            .iter()
            .filter_map(|&handle| {
                let body = self.world.bodies.get(handle)?;
                let (p, v) = (body.translation(), body.linvel());
                Some(BodyState {
                    position: tumble::math::Vec3::new(p.x, p.y, p.z),
                    linear_velocity: tumble::math::Vec3::new(v.x, v.y, v.z),
                })
            })
            .collect()
    }

    fn kinetic_energy(&self) -> f64 {
        self.world
            .bodies
            .iter()
            .filter(|(_, body)| body.is_dynamic())
            .map(|(_, body)| body.kinetic_energy() as f64)
            .sum()
    }

    fn reset_stage_timers(&mut self) {
        self.stage_totals = RapierStages::default();
        self.steps_since_reset = 0;
    }

    fn stage_ms(&self) -> Vec<(String, f64)> {
        let steps = self.steps_since_reset.max(1) as f64;
        let totals = self.stage_totals;
        [
            ("user_changes", totals.user_changes),
            ("broadphase", totals.broadphase),
            ("narrowphase", totals.narrowphase),
            ("islands", totals.islands),
            ("solver", totals.solver),
            ("update", totals.update),
        ]
        .into_iter()
        .map(|(name, total)| (name.to_string(), total / steps))
        .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tumble::math::{Quat, Vec3};
    use tumble::{Shape, StepConfig};

    /// A ground plane, then one body of each primitive with its own mass and materials.
    fn scene() -> Scene {
        let mut scene = Scene::new(StepConfig {
            solver_iterations: 7,
            substeps: 2,
            ..StepConfig::default()
        });
        scene.bodies = vec![
            BodyDesc::fixed(Shape::plane(Vec3::Y, -0.25)).friction(0.9),
            BodyDesc::dynamic(Shape::sphere(0.3))
                .position(Vec3::new(-3.0, 1.0, 0.0))
                .mass(2.0)
                .friction(0.1)
                .restitution(0.6),
            BodyDesc::dynamic(Shape::cuboid(Vec3::new(0.5, 0.25, 1.0)))
                .position(Vec3::new(0.0, 1.0, 0.0))
                .rotation(Quat::from_rotation_z(0.3))
                .mass(3.0)
                .linear_velocity(Vec3::new(1.0, 0.0, 0.0))
                .angular_velocity(Vec3::new(0.0, 2.0, 0.0)),
            BodyDesc::dynamic(Shape::capsule(0.2, 0.7))
                .position(Vec3::new(3.0, 2.0, 0.0))
                .mass(1.5),
            BodyDesc::fixed(Shape::trimesh(
                tumble::shape::TriMesh::new(
                    vec![Vec3::ZERO, Vec3::Z, Vec3::X, Vec3::new(1.0, 0.0, 1.0)],
                    vec![[0, 1, 2], [2, 1, 3]],
                )
                .unwrap(),
            ))
            .position(Vec3::new(20.0, 0.0, 0.0)),
            BodyDesc::dynamic(Shape::convex_hull(&tumble::scene::barrel_points()).unwrap())
                .position(Vec3::new(0.0, 3.0, 2.0))
                .mass(2.5),
        ];
        scene
    }

    #[test]
    fn translation_keeps_shapes_masses_and_materials() {
        let scene = scene();
        let (world, handles) = translate(&scene, SolverSettings::Matched).unwrap();
        assert_eq!(handles.len(), scene.bodies.len());
        for (desc, &handle) in scene.bodies.iter().zip(&handles) {
            let body = &world.bodies[handle];
            assert_eq!(body.is_fixed(), desc.is_static());
            assert!(!body.is_ccd_enabled());
            let position = body.translation();
            assert_eq!(
                [position.x, position.y, position.z],
                desc.position.to_array()
            );
            let rotation = body.rotation();
            let expected = desc.rotation.normalize();
            assert!(
                (rotation.dot(Rotation::from_xyzw(
                    expected.x, expected.y, expected.z, expected.w
                )))
                .abs()
                    > 0.999_999
            );
            let velocity = body.linvel();
            assert_eq!(
                [velocity.x, velocity.y, velocity.z],
                desc.linear_velocity.to_array()
            );
            let omega = body.angvel();
            assert_eq!(
                [omega.x, omega.y, omega.z],
                desc.angular_velocity.to_array()
            );
            if !desc.is_static() {
                assert!((body.mass() - desc.mass).abs() < 1e-5 * desc.mass, "mass");
            }
            assert_eq!(body.colliders().len(), 1);
            let collider = &world.colliders[body.colliders()[0]];
            assert_eq!(collider.friction(), desc.friction);
            assert_eq!(collider.restitution(), desc.restitution);
            assert_eq!(
                collider.friction_combine_rule(),
                CoefficientCombineRule::GeometricMean
            );
            assert_eq!(
                collider.restitution_combine_rule(),
                CoefficientCombineRule::Max
            );
            let shape = collider.shape();
            match &desc.shape {
                Shape::Sphere(sphere) => assert_eq!(shape.as_ball().unwrap().radius, sphere.radius),
                Shape::Cuboid(cuboid) => {
                    let h = shape.as_cuboid().unwrap().half_extents;
                    assert_eq!([h.x, h.y, h.z], cuboid.half_extents.to_array());
                }
                Shape::Capsule(capsule) => {
                    let rapier_capsule = shape.as_capsule().unwrap();
                    assert_eq!(rapier_capsule.radius, capsule.radius);
                    assert_eq!(rapier_capsule.half_height(), capsule.half_height);
                    // Along the body's Y axis, centred.
                    let (a, b) = (rapier_capsule.segment.a, rapier_capsule.segment.b);
                    assert_eq!([a.x, a.z, b.x, b.z], [0.0; 4]);
                    assert_eq!(a.y + b.y, 0.0);
                }
                Shape::Plane(plane) => {
                    let normal = shape.as_halfspace().unwrap().normal;
                    assert_eq!([normal.x, normal.y, normal.z], plane.normal.to_array());
                    // The boundary passes through offset·n.
                    let boundary = collider.position().translation;
                    assert_eq!(boundary.dot(normal), plane.offset);
                }
                Shape::TriMesh(mesh) => {
                    let rapier_mesh = shape.as_trimesh().unwrap();
                    assert_eq!(rapier_mesh.indices(), mesh.triangles());
                }
                Shape::Compound(compound) => {
                    let parts = shape.as_compound().unwrap().shapes();
                    assert_eq!(parts.len(), compound.children().len());
                }
                Shape::ConvexHull(hull) => {
                    let points = shape.as_convex_polyhedron().unwrap().points();
                    assert_eq!(points.len(), hull.vertices().len());
                    for point in points {
                        assert!(
                            hull.vertices()
                                .iter()
                                .any(|v| v.to_array() == point.to_array())
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn solver_settings_match_tumbles_soft_step() {
        let scene = scene();
        let matched = integration_parameters(&scene, SolverSettings::Matched);
        let counts = |p: &IntegrationParameters| {
            (
                p.num_solver_iterations,
                p.num_internal_pgs_iterations,
                p.num_internal_stabilization_iterations,
            )
        };
        assert_eq!(counts(&matched), (scene.config.substeps as usize, 7, 1));
        assert_eq!(
            matched.contact_softness.natural_frequency,
            scene.config.contact_hertz
        );
        assert_eq!(
            matched.static_contact_softness.natural_frequency,
            2.0 * scene.config.contact_hertz
        );
        // One collision pass per step in both engines.
        assert_eq!(matched.dt, scene.config.dt);
        assert_eq!(matched.max_ccd_substeps, 0);
        assert_eq!(matched.prediction_distance(), scene.config.contact_margin);
        let default = integration_parameters(&scene, SolverSettings::RapierDefault);
        assert_eq!(counts(&default), counts(&IntegrationParameters::default()));
    }

    /// Rest height of a unit box dropped from 1.5 m onto the ground, after 2 s.
    fn rest_height(engine: crate::engine::EngineKind, config: StepConfig) -> f32 {
        let mut scene = Scene::new(config);
        scene.bodies = vec![
            BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)),
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(0.0, 2.0, 0.0)),
        ];
        let mut simulation = engine.build(&scene).unwrap();
        let steps = (2.0 / scene.config.dt).round() as usize;
        for _ in 0..steps {
            simulation.step();
        }
        let state = simulation.dynamic_states()[0];
        assert!(state.linear_velocity.length() < 0.01, "{engine:?} at rest");
        state.position.y
    }

    #[test]
    fn a_falling_box_rests_at_the_same_height_in_both_engines() {
        use crate::engine::EngineKind;
        let config = StepConfig::default();
        let tumble = rest_height(EngineKind::TumbleCpu, config);
        assert!((tumble - 0.5).abs() < 1e-3, "on the ground: {tumble}");
        for peer in [EngineKind::Rapier, EngineKind::RapierDefault] {
            let rapier = rest_height(peer, config);
            assert!(
                (tumble - rapier).abs() < 1e-3,
                "Tumble rests at {tumble} m, {peer:?} at {rapier} m"
            );
        }
    }
}
