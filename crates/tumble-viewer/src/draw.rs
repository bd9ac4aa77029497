//! What to draw, read from a [`World`]: instances grouped by mesh, contact markers, joints and
//! the mouse drag, ground quads. Built on the CPU each frame; the renderer uploads and draws it.

use crate::input::BatchView;
use std::collections::BTreeMap;

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};
use std::sync::Arc;
use tumble::World;
use tumble::math::{Aabb, Transform, tangent_basis};
use tumble::shape::{ConvexHull, Shape, TriMesh};

use crate::camera::{dynamic_bounds, finite_bounds};

/// Clear colour where nothing is drawn (linear RGB).
pub const BACKGROUND: [f32; 3] = [0.30, 0.40, 0.55];
/// Bodies that never move (boxes, spheres, capsules with mass 0), linear RGB.
pub const STATIC_COLOUR: [f32; 3] = [0.45, 0.45, 0.45];
/// Static triangle meshes (landscapes, floors), linear RGB: a muted earth tone, darker and warmer
/// than the grey of static bodies and the grid of ground planes, so bodies stand out on it.
pub const TRIMESH_COLOUR: [f32; 3] = [0.30, 0.26, 0.18];
/// Contact points and their normals (linear RGB).
pub const CONTACT_POINT_COLOUR: [f32; 3] = [1.0, 0.15, 0.05];
pub const CONTACT_NORMAL_COLOUR: [f32; 3] = [1.0, 0.9, 0.1];
/// Joints: lines from each body's centre to its anchor and between the two anchors, a cross at
/// each anchor (linear RGB). A channel at 0, which no lit body colour has, so it stands out.
pub const JOINT_COLOUR: [f32; 3] = [0.0, 0.8, 1.0];
/// The mouse drag: a line from the dragged point to its target, a cross at the target.
pub const DRAG_COLOUR: [f32; 3] = [1.0, 0.0, 1.0];

/// One instance of a mesh: where it is and its colour.
// repr(C) + Pod: uploaded as is into the instance buffer the mesh shader reads.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Instance {
    /// Mesh to world, column-major (glam's and WGSL's order).
    pub model: [[f32; 4]; 4],
    /// Linear RGB, alpha unused (1).
    pub colour: [f32; 4],
}

const _: () = assert!(size_of::<Instance>() == 80);

/// Where an instance's model comes from when the renderer draws from the physics' device
/// buffers (renderer.rs, pose.wgsl): its body's pose at the end of the step times `local`.
// repr(C) + Pod: uploaded as is into the storage buffer pose.wgsl reads.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct PoseLink {
    /// Mesh to body frame, column-major: the shape's scale, and a compound child's pose.
    pub local: [[f32; 4]; 4],
    /// The body's slot ([`tumble::BodyHandle::index`]), or [`NO_BODY`] for an instance that
    /// keeps its model (contact markers).
    pub body: u32,
    pub _pad: [u32; 3],
}

const _: () = assert!(size_of::<PoseLink>() == 80);

/// `PoseLink::body` of an instance that belongs to no body.
pub const NO_BODY: u32 = u32::MAX;

impl PoseLink {
    const NONE: Self = Self {
        local: [[0.0; 4]; 4],
        body: NO_BODY,
        _pad: [0; 3],
    };

    fn new(body: u32, local: Mat4) -> Self {
        Self {
            local: local.to_cols_array_2d(),
            body,
            _pad: [0; 3],
        }
    }
}

impl Instance {
    fn new(model: Mat4, colour: [f32; 3]) -> Self {
        Self {
            model: model.to_cols_array_2d(),
            colour: [colour[0], colour[1], colour[2], 1.0],
        }
    }
}

/// The meshes instances refer to. A capsule mesh is built per distinct size: the f32 bits are
/// the key, so equal sizes share a mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum MeshKey {
    Cube,
    Sphere,
    /// A coarser sphere for the particle demo's particles.
    Particle,
    Capsule {
        radius: u32,
        half_height: u32,
    },
    /// The unit segment: contact normals.
    Segment,
    /// A convex hull, named by a hash of its vertices' bits (equal hulls share a mesh);
    /// [`DrawList::hulls`] holds its geometry.
    Hull(u64),
    /// A static triangle mesh, named by a hash of its vertices' bits and its triangles (equal
    /// meshes share one); [`DrawList::trimeshes`] holds its geometry.
    TriMesh(u64),
    /// The unit segment drawn over the scene ([`MeshKey::over_scene`]): joints and the drag.
    ConstraintSegment,
    /// Three unit segments from -1 to 1 along the axes, drawn over the scene: a constraint's
    /// anchor points.
    ConstraintPoint,
}

impl MeshKey {
    /// Drawn over everything else, not hidden by it: a joint's anchors lie inside the bodies
    /// it joins, where the depth test would hide every line and cross of it.
    pub fn over_scene(self) -> bool {
        matches!(self, Self::ConstraintSegment | Self::ConstraintPoint)
    }
}

/// A finite square of an infinite plane, drawn as a grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroundQuad {
    /// The point of the plane nearest to the scene's centre (m).
    pub center: Vec3,
    /// Unit normal (out of the solid half-space) and two unit tangents.
    pub normal: Vec3,
    pub tangents: [Vec3; 2],
    /// Half the side of the square (m).
    pub half_size: f32,
}

/// How to draw, from the viewer's keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DrawSettings {
    /// Contacts and constraints (`c`): contact points and normals, joints and the drag.
    pub contacts: bool,
    pub wireframe: bool,
    /// Colour bodies by constraint batch (the talk's "colored batches").
    pub batches: BatchView,
}

impl Default for DrawSettings {
    fn default() -> Self {
        Self {
            contacts: false,
            wireframe: false,
            batches: BatchView::Off,
        }
    }
}

/// Colour of bodies while batches are shown: light grey, so the constraint colours stand out.
const BATCH_BODY_COLOUR: [f32; 3] = [0.55, 0.55, 0.55];

/// Everything one frame draws.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DrawList {
    pub instances: BTreeMap<MeshKey, Vec<Instance>>,
    pub grounds: Vec<GroundQuad>,
    pub wireframe: bool,
    /// The hulls that `MeshKey::Hull` keys name.
    pub hulls: BTreeMap<u64, Arc<ConvexHull>>,
    /// The triangle meshes that `MeshKey::TriMesh` keys name.
    pub trimeshes: BTreeMap<u64, Arc<TriMesh>>,
    /// The sphere (centre, radius in m) the shadow map covers: the dynamic bodies' bounds, as
    /// the default camera frames them (else every finite body's), so the map's texels go to
    /// what moves and not to a landscape a hundred times larger. `None`: nothing casts.
    pub shadow_bounds: Option<(Vec3, f32)>,
    /// Overlay text, drawn over the top-left corner (overlay.rs); the caller fills it.
    pub overlay: Vec<String>,
    /// For each instance in `instances`, in the same order, the body it is drawn at.
    pub links: BTreeMap<MeshKey, Vec<PoseLink>>,
}

/// FNV-1a over 32-bit words: a key that is the same for equal geometry in every run.
fn fnv1a(words: impl IntoIterator<Item = u32>) -> u64 {
    words
        .into_iter()
        .fold(0xcbf2_9ce4_8422_2325u64, |hash, word| {
            (hash ^ u64::from(word)).wrapping_mul(0x0100_0000_01b3)
        })
}

fn hull_key(hull: &ConvexHull) -> u64 {
    fnv1a(
        hull.vertices()
            .iter()
            .flat_map(|v| v.to_array().map(f32::to_bits)),
    )
}

/// Hashes the whole mesh every frame: about 0.5 M words for the 100k-triangle landscapes, well
/// under a millisecond in a release build, and it keeps the key a pure function of the shape.
fn trimesh_key(trimesh: &TriMesh) -> u64 {
    let vertices = trimesh
        .vertices()
        .iter()
        .flat_map(|v| v.to_array().map(f32::to_bits));
    fnv1a(vertices.chain(trimesh.triangles().iter().flatten().copied()))
}

impl DrawList {
    /// The instanced mesh and its scale for a convex shape (a hull's mesh is kept once per
    /// hull); `None` for planes, meshes and compounds, which are drawn otherwise.
    fn convex_mesh(&mut self, shape: &Shape) -> Option<(MeshKey, Vec3)> {
        Some(match shape {
            Shape::Cuboid(cuboid) => (MeshKey::Cube, cuboid.half_extents),
            Shape::Sphere(sphere) => (MeshKey::Sphere, Vec3::splat(sphere.radius)),
            Shape::Capsule(capsule) => (
                MeshKey::Capsule {
                    radius: capsule.radius.to_bits(),
                    half_height: capsule.half_height.to_bits(),
                },
                Vec3::ONE,
            ),
            Shape::ConvexHull(hull) => {
                let key = hull_key(hull);
                self.hulls.entry(key).or_insert_with(|| hull.clone());
                (MeshKey::Hull(key), Vec3::ONE)
            }
            Shape::Plane(_) | Shape::TriMesh(_) | Shape::Compound(_) => return None,
        })
    }

    /// Adds an instance of `key` and where its model comes from, keeping the two lists in step.
    fn push(&mut self, key: MeshKey, instance: Instance, link: PoseLink) {
        self.instances.entry(key).or_default().push(instance);
        self.links.entry(key).or_default().push(link);
    }

    /// The particle demo: a sphere of `radius` per particle, coloured by its index as bodies
    /// are, on the floor of the box `container` (its bottom face as a ground), with the
    /// shadow map over the particles.
    pub fn particles(positions: &[[f32; 3]], radius: f32, container: Aabb) -> Self {
        Self::particles_coloured(positions, |index| index, radius, container)
    }

    /// [`particles`](Self::particles) with particle `i` in the colour of `colour_of(i)`
    /// (e.g. its rigid body's index: a body's particles share a colour).
    pub fn particles_coloured(
        positions: &[[f32; 3]],
        colour_of: impl Fn(usize) -> usize,
        radius: f32,
        container: Aabb,
    ) -> Self {
        let mut list = DrawList::default();
        let scale = Mat4::from_scale(Vec3::splat(radius));
        for (index, &position) in positions.iter().enumerate() {
            let model = Mat4::from_translation(Vec3::from(position)) * scale;
            list.push(
                MeshKey::Particle,
                Instance::new(model, body_colour(colour_of(index))),
                PoseLink::NONE,
            );
        }
        let center = container.center();
        list.grounds.push(GroundQuad {
            center: Vec3::new(center.x, container.min.y, center.z),
            normal: Vec3::Y,
            tangents: [Vec3::X, Vec3::Z],
            half_size: container.half_extents().max_element().max(1.0) * 4.0,
        });
        let bounds = positions
            .iter()
            .map(|&p| Aabb::from_center_half_extents(Vec3::from(p), Vec3::splat(radius)))
            .reduce(|a, b| a.union(&b));
        list.shadow_bounds = bounds.map(|b| (b.center(), b.half_extents().length()));
        list
    }

    pub fn build(world: &World, settings: DrawSettings) -> Self {
        let mut list = DrawList {
            wireframe: settings.wireframe,
            ..Default::default()
        };
        let bounds = finite_bounds(world);
        let (scene_center, scene_radius) = bounds.map_or((Vec3::ZERO, 5.0), |aabb| {
            (aabb.center(), aabb.half_extents().length())
        });
        list.shadow_bounds = dynamic_bounds(world)
            .or(bounds)
            .map(|aabb| (aabb.center(), aabb.half_extents().length()));
        // Contact markers scale with the smallest body so they never hide one.
        let mut smallest = f32::MAX;
        for handle in world.bodies() {
            let (Ok(desc), Ok(pose), Ok(dynamic)) = (
                world.body_desc(handle),
                world.pose(handle),
                world.is_dynamic(handle),
            ) else {
                continue;
            };
            // With batches shown, bodies step back to grey and the constraints carry the colour.
            let colour = match (dynamic, settings.batches) {
                (false, _) => STATIC_COLOUR,
                (true, BatchView::Off) => body_colour(handle.index() as usize),
                (true, _) => BATCH_BODY_COLOUR,
            };
            // A compound is drawn as its children, each at its pose in the body frame.
            let parts: Vec<(&Shape, Transform)> = match &desc.shape {
                Shape::Plane(plane) => {
                    let normal = pose.rotation * plane.normal;
                    let origin = pose.position + normal * plane.offset;
                    let center = scene_center - normal * normal.dot(scene_center - origin);
                    let (u, v) = tangent_basis(normal);
                    list.grounds.push(GroundQuad {
                        center,
                        normal,
                        tangents: [u, v],
                        // Far enough that the edge is rarely in view, close enough that the
                        // depth range stays useful.
                        half_size: (10.0 * scene_radius).max(50.0),
                    });
                    continue;
                }
                // One mesh per distinct triangle mesh, uploaded once and drawn at its body's pose.
                Shape::TriMesh(trimesh) => {
                    let key = trimesh_key(trimesh);
                    list.trimeshes.entry(key).or_insert_with(|| trimesh.clone());
                    let model = Mat4::from_rotation_translation(pose.rotation, pose.position);
                    list.push(
                        MeshKey::TriMesh(key),
                        Instance::new(model, TRIMESH_COLOUR),
                        PoseLink::new(handle.index(), Mat4::IDENTITY),
                    );
                    continue;
                }
                Shape::Compound(compound) => compound
                    .children()
                    .iter()
                    .map(|child| (&child.shape, child.pose))
                    .collect(),
                shape => vec![(shape, Transform::IDENTITY)],
            };
            for (shape, local) in parts {
                let Some((key, scale)) = list.convex_mesh(shape) else {
                    continue;
                };
                let part_pose = pose.mul_transform(&local);
                let local =
                    Mat4::from_scale_rotation_translation(scale, local.rotation, local.position);
                smallest = smallest.min(shape.aabb(&part_pose).half_extents().min_element());
                let model = Mat4::from_scale_rotation_translation(
                    scale,
                    part_pose.rotation,
                    part_pose.position,
                );
                list.push(
                    key,
                    Instance::new(model, colour),
                    PoseLink::new(handle.index(), local),
                );
            }
        }
        let marker_size = 0.15 * smallest.min(1.0);
        if settings.contacts || settings.batches != BatchView::Off {
            list.add_contacts(world, marker_size, settings.batches);
        }
        if settings.contacts {
            list.add_constraints(world, 2.0 * marker_size);
        }
        list
    }

    /// A small cube at each contact point (12 triangles: thousands of contacts stay cheap on a
    /// CPU rasterizer) and a segment along its normal (from B to A).
    /// With `batches` shown, each manifold's markers take its batch's colour (the talk's
    /// "colored batches"), and manifolds outside a single shown batch are left out.
    fn add_contacts(&mut self, world: &World, marker_size: f32, batches: BatchView) {
        let normal_length = 4.0 * marker_size;
        for ((_, _, contact), (_, _, batch)) in world.contacts().zip(world.contact_batches()) {
            let marker_colour = match batches {
                BatchView::Off => CONTACT_POINT_COLOUR,
                BatchView::All => body_colour(batch as usize),
                BatchView::One(shown) if batch as usize == shown => body_colour(batch as usize),
                BatchView::One(_) => continue,
            };
            let normal = contact.manifold.normal;
            let (u, v) = tangent_basis(normal);
            for point in contact.manifold.points() {
                let marker = Mat4::from_scale_rotation_translation(
                    Vec3::splat(marker_size),
                    glam::Quat::IDENTITY,
                    point.position,
                );
                self.push(
                    MeshKey::Cube,
                    Instance::new(marker, marker_colour),
                    PoseLink::NONE,
                );
                // Maps the segment's +Y onto the normal; u and v only keep the matrix regular.
                let segment = Mat4::from_cols(
                    u.extend(0.0),
                    (normal * normal_length).extend(0.0),
                    v.extend(0.0),
                    point.position.extend(1.0),
                );
                self.push(
                    MeshKey::Segment,
                    Instance::new(segment, CONTACT_NORMAL_COLOUR),
                    PoseLink::NONE,
                );
            }
        }
    }

    /// Joints and the mouse drag, drawn over the scene ([`MeshKey::over_scene`]), with crosses
    /// of half-size `cross_size` (m). For each unbroken joint, as Box2D draws one: a line from
    /// each body's centre to its anchor, one between the two anchors (the joint's error: none
    /// while it holds) and a cross at each anchor. For the drag: a line from the dragged point
    /// to its target and a cross at the target. Broken joints act no more and are left out.
    fn add_constraints(&mut self, world: &World, cross_size: f32) {
        // Joints name their bodies by slot.
        let centres: BTreeMap<u32, Vec3> = world
            .bodies()
            .filter_map(|handle| Some((handle.index(), world.pose(handle).ok()?.position)))
            .collect();
        for (handle, joint) in world.joints().filter(|(_, joint)| !joint.broken) {
            let Ok((anchor_a, anchor_b)) = world.joint_anchors(handle) else {
                continue;
            };
            for (body, anchor) in [(joint.body_a, anchor_a), (joint.body_b, anchor_b)] {
                if let Some(&centre) = centres.get(&body) {
                    self.push_constraint_line(centre, anchor, JOINT_COLOUR);
                }
                self.push_constraint_point(anchor, cross_size, JOINT_COLOUR);
            }
            self.push_constraint_line(anchor_a, anchor_b, JOINT_COLOUR);
        }
        if let Some((point, target)) = world.drag_anchors() {
            self.push_constraint_line(point, target, DRAG_COLOUR);
            self.push_constraint_point(target, cross_size, DRAG_COLOUR);
        }
    }

    /// A line from `from` to `to` over the scene; none where they coincide (nothing to see, and
    /// the segment's matrix would be singular).
    fn push_constraint_line(&mut self, from: Vec3, to: Vec3, colour: [f32; 3]) {
        let along = to - from;
        if along == Vec3::ZERO {
            return;
        }
        // Maps the segment's +Y onto `along`; u and v only keep the matrix regular.
        let (u, v) = tangent_basis(along.normalize());
        let model = Mat4::from_cols(
            u.extend(0.0),
            along.extend(0.0),
            v.extend(0.0),
            from.extend(1.0),
        );
        self.push(
            MeshKey::ConstraintSegment,
            Instance::new(model, colour),
            PoseLink::NONE,
        );
    }

    fn push_constraint_point(&mut self, at: Vec3, half_size: f32, colour: [f32; 3]) {
        let model =
            Mat4::from_scale_rotation_translation(Vec3::splat(half_size), glam::Quat::IDENTITY, at);
        self.push(
            MeshKey::ConstraintPoint,
            Instance::new(model, colour),
            PoseLink::NONE,
        );
    }
}

/// The colour of the body in slot `index`: hues a golden angle apart, so neighbours in creation
/// order (neighbours in space, in the built-in scenes) differ clearly. Linear RGB.
pub fn body_colour(index: usize) -> [f32; 3] {
    const GOLDEN: f32 = 0.618_034;
    let hue = (index as f32 * GOLDEN).fract();
    // Picked in sRGB, where saturation looks even, then made linear for the shading.
    hsv_to_rgb(hue, 0.65, 0.9).map(srgb_to_linear)
}

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// `hue` in [0, 1), saturation and value in [0, 1].
fn hsv_to_rgb(hue: f32, saturation: f32, value: f32) -> [f32; 3] {
    let h = hue * 6.0;
    let chroma = value * saturation;
    let x = chroma * (1.0 - (h % 2.0 - 1.0).abs());
    let (r, g, b) = match h as u32 {
        0 => (chroma, x, 0.0),
        1 => (x, chroma, 0.0),
        2 => (0.0, chroma, x),
        3 => (0.0, x, chroma),
        4 => (x, 0.0, chroma),
        _ => (chroma, 0.0, x),
    };
    let m = value - chroma;
    [r + m, g + m, b + m]
}

#[cfg(test)]
mod tests {
    use super::*;
    use tumble::{BodyDesc, StepConfig};

    fn world() -> World {
        let mut world = World::new(StepConfig::default()).unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
        world
            .add_body(
                BodyDesc::dynamic(Shape::cuboid(Vec3::new(0.5, 0.25, 1.0)))
                    .position(Vec3::new(0.0, 0.25, 0.0)),
            )
            .unwrap();
        world
            .add_body(
                BodyDesc::dynamic(Shape::capsule(0.2, 0.5)).position(Vec3::new(2.0, 0.7, 0.0)),
            )
            .unwrap();
        world
    }

    #[test]
    fn one_instance_per_body_and_a_ground_per_plane() {
        let list = DrawList::build(&world(), DrawSettings::default());
        assert_eq!(list.grounds.len(), 1);
        assert_eq!(list.grounds[0].normal, Vec3::Y);
        assert_eq!(list.grounds[0].center.y, 0.0);
        assert_eq!(list.instances[&MeshKey::Cube].len(), 1);
        let capsule = MeshKey::Capsule {
            radius: 0.2f32.to_bits(),
            half_height: 0.5f32.to_bits(),
        };
        assert_eq!(list.instances[&capsule].len(), 1);
        // Every instance knows its body: the box is body 1, drawn at its pose times its scale.
        assert_eq!(list.links[&MeshKey::Cube].len(), 1);
        assert_eq!(list.links[&MeshKey::Cube][0].body, 1);
        let local = Mat4::from_cols_array_2d(&list.links[&MeshKey::Cube][0].local);
        assert_eq!(local, Mat4::from_scale(Vec3::new(0.5, 0.25, 1.0)));
        // The box's model matrix scales the unit cube to its half extents.
        let model = Mat4::from_cols_array_2d(&list.instances[&MeshKey::Cube][0].model);
        let corner = model.transform_point3(Vec3::ONE);
        assert!((corner - Vec3::new(0.5, 0.5, 1.0)).length() < 1e-6);
    }

    #[test]
    fn a_trimesh_is_one_mesh_drawn_at_its_pose() {
        let mut world = world();
        let floor = TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::NEG_Z], vec![[0, 1, 2]]).unwrap();
        let shape = Shape::trimesh(floor);
        for x in [5.0, 9.0] {
            world
                .add_body(BodyDesc::fixed(shape.clone()).position(Vec3::new(x, 0.0, 0.0)))
                .unwrap();
        }
        let list = DrawList::build(&world, DrawSettings::default());
        // Both bodies share the one mesh, each drawn at its own position.
        assert_eq!(list.trimeshes.len(), 1);
        let key = MeshKey::TriMesh(*list.trimeshes.keys().next().unwrap());
        let xs: Vec<f32> = list.instances[&key]
            .iter()
            .map(|instance| instance.model[3][0])
            .collect();
        assert_eq!(xs, [5.0, 9.0]);
        assert_eq!(list.instances[&key][0].colour[..3], TRIMESH_COLOUR);
    }

    #[test]
    fn contacts_add_markers_once_bodies_touch() {
        let mut world = world();
        world.step();
        let without = DrawList::build(&world, DrawSettings::default());
        assert!(!without.instances.contains_key(&MeshKey::Segment));
        let with = DrawList::build(
            &world,
            DrawSettings {
                contacts: true,
                ..Default::default()
            },
        );
        let points: usize = world
            .contacts()
            .map(|(_, _, c)| c.manifold.points().len())
            .sum();
        assert!(points > 0, "the box rests on the ground");
        assert_eq!(with.instances[&MeshKey::Segment].len(), points);
        // One cube is the box itself, the others mark the points, which belong to no body.
        assert_eq!(with.instances[&MeshKey::Cube].len(), 1 + points);
        let bodies: Vec<u32> = with.links[&MeshKey::Cube].iter().map(|l| l.body).collect();
        assert_eq!(
            bodies.iter().filter(|&&body| body == NO_BODY).count(),
            points
        );
        assert_eq!(with.links[&MeshKey::Segment].len(), points);
    }

    #[test]
    fn a_compound_is_an_instance_per_child_at_the_childs_world_pose() {
        use tumble::math::Quat;
        use tumble::shape::CompoundChild;
        // A box and a sphere beside it: the centre of mass is off the children's origin, so
        // the compound is stored in another frame (compound.rs), which the drawing must undo.
        let (box_at, sphere_at) = (Vec3::new(-0.3, 0.0, 0.0), Vec3::new(0.9, 0.2, 0.0));
        let box_rotation = Quat::from_rotation_z(0.4);
        let compound = Shape::compound(vec![
            CompoundChild {
                shape: Shape::cuboid(Vec3::new(0.5, 0.25, 0.25)),
                pose: Transform::new(box_at, box_rotation),
            },
            CompoundChild {
                shape: Shape::sphere(0.3),
                pose: Transform::new(sphere_at, Quat::IDENTITY),
            },
        ])
        .unwrap();
        let (position, rotation) = (Vec3::new(2.0, 1.0, -1.0), Quat::from_rotation_y(0.7));
        let mut world = World::new(StepConfig::default()).unwrap();
        let body = world
            .add_body(
                BodyDesc::dynamic(compound)
                    .position(position)
                    .rotation(rotation),
            )
            .unwrap();
        let moved = world.pose(body).unwrap().position - position;
        assert!(moved.length() > 0.05, "not re-framed: {moved}");
        let list = DrawList::build(&world, DrawSettings::default());
        assert_eq!(list.instances.values().map(Vec::len).sum::<usize>(), 2);
        let given = Transform::new(position, rotation);
        for (key, child, child_rotation, scale) in [
            (
                MeshKey::Cube,
                box_at,
                box_rotation,
                Vec3::new(0.5, 0.25, 0.25),
            ),
            (MeshKey::Sphere, sphere_at, Quat::IDENTITY, Vec3::splat(0.3)),
        ] {
            let model = Mat4::from_cols_array_2d(&list.instances[&key][0].model);
            let (drawn_scale, drawn_rotation, drawn_at) = model.to_scale_rotation_translation();
            let expected_at = given.transform_point(child);
            assert!(
                (drawn_at - expected_at).length() < 1e-5,
                "{key:?}: {drawn_at} {expected_at}"
            );
            assert!(
                (drawn_scale - scale).length() < 1e-5,
                "{key:?}: {drawn_scale}"
            );
            let expected_rotation = rotation * child_rotation;
            assert!(
                drawn_rotation.dot(expected_rotation).abs() > 1.0 - 1e-5,
                "{key:?}: {drawn_rotation} {expected_rotation}"
            );
            // The link rebuilds the same model from the body's pose, as the GPU path does.
            let link = list.links[&key][0];
            assert_eq!(link.body, body.index());
            let pose = world.pose(body).unwrap();
            let from_link = Mat4::from_rotation_translation(pose.rotation, pose.position)
                * Mat4::from_cols_array_2d(&link.local);
            assert!(from_link.abs_diff_eq(model, 1e-5), "{key:?}");
        }
        // Both children in the body's colour.
        let colour = body_colour(body.index() as usize);
        assert_eq!(list.instances[&MeshKey::Cube][0].colour[..3], colour);
        assert_eq!(list.instances[&MeshKey::Sphere][0].colour[..3], colour);
    }

    /// The colours of the contact markers: the cubes that belong to no body, in order.
    fn marker_colours(list: &DrawList) -> Vec<[f32; 3]> {
        list.instances[&MeshKey::Cube]
            .iter()
            .zip(&list.links[&MeshKey::Cube])
            .filter(|(_, link)| link.body == NO_BODY)
            .map(|(instance, _)| [0, 1, 2].map(|c| instance.colour[c]))
            .collect()
    }

    #[test]
    fn batches_colour_each_contact_by_its_batch_and_one_batch_shows_alone() {
        // A tower of three boxes on the ground: the middle contacts share a box, so they are
        // solved in different batches.
        let mut world = World::new(StepConfig::default()).unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
        for level in 0..3 {
            world
                .add_body(
                    BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(
                        0.0,
                        0.5 + level as f32,
                        0.0,
                    )),
                )
                .unwrap();
        }
        world.step();
        // Each manifold's batch and point count, in the order markers are drawn.
        let manifolds: Vec<(usize, usize)> = world
            .contacts()
            .zip(world.contact_batches())
            .map(|((_, _, contact), (_, _, batch))| {
                (batch as usize, contact.manifold.points().len())
            })
            .collect();
        let mut batches: Vec<usize> = manifolds.iter().map(|&(batch, _)| batch).collect();
        batches.sort_unstable();
        batches.dedup();
        assert!(batches.len() >= 2, "{manifolds:?}");
        let build = |batches| {
            DrawList::build(
                &world,
                DrawSettings {
                    batches,
                    ..Default::default()
                },
            )
        };

        // All batches: every marker in its manifold's batch colour, the bodies in grey.
        let all = build(BatchView::All);
        let expected: Vec<[f32; 3]> = manifolds
            .iter()
            .flat_map(|&(batch, points)| std::iter::repeat_n(body_colour(batch), points))
            .collect();
        assert_eq!(marker_colours(&all), expected);
        let bodies = all.instances[&MeshKey::Cube]
            .iter()
            .zip(&all.links[&MeshKey::Cube])
            .filter(|(_, link)| link.body != NO_BODY);
        for (instance, _) in bodies {
            assert_eq!(instance.colour[..3], BATCH_BODY_COLOUR);
        }
        // The normals keep their colour.
        let normals = &all.instances[&MeshKey::Segment];
        assert_eq!(normals.len(), expected.len());
        assert!(
            normals
                .iter()
                .all(|n| n.colour[..3] == CONTACT_NORMAL_COLOUR)
        );

        // One batch: only its manifolds' markers and normals.
        for &shown in &batches {
            let one = build(BatchView::One(shown));
            let points: usize = manifolds
                .iter()
                .filter(|&&(batch, _)| batch == shown)
                .map(|&(_, points)| points)
                .sum();
            assert!(points > 0);
            assert_eq!(marker_colours(&one), vec![body_colour(shown); points]);
            assert_eq!(one.instances[&MeshKey::Segment].len(), points);
        }
        // A batch with no contacts in it draws no markers (the bodies stay).
        let none = build(BatchView::One(batches[batches.len() - 1] + 1));
        assert!(marker_colours(&none).is_empty());
        assert!(!none.instances.contains_key(&MeshKey::Segment));
    }

    /// The ends of each `key` instance's unit segment in the world, and its colour.
    fn segments(list: &DrawList, key: MeshKey) -> Vec<(Vec3, Vec3, [f32; 3])> {
        list.instances.get(&key).map_or(Vec::new(), |instances| {
            instances
                .iter()
                .map(|instance| {
                    let model = Mat4::from_cols_array_2d(&instance.model);
                    let colour = [0, 1, 2].map(|c| instance.colour[c]);
                    (
                        model.transform_point3(Vec3::ZERO),
                        model.transform_point3(Vec3::Y),
                        colour,
                    )
                })
                .collect()
        })
    }

    fn near(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    #[test]
    fn constraints_draw_joints_and_the_drag() {
        // Two boxes hinged at the point between them, and a box on its own to drag.
        let mut world = World::new(StepConfig::default()).unwrap();
        let (centre_a, centre_b, anchor) = (
            Vec3::new(-1.0, 2.0, 0.0),
            Vec3::new(1.0, 2.0, 0.0),
            Vec3::new(0.0, 2.0, 0.0),
        );
        let cube = Shape::cuboid(Vec3::splat(0.5));
        let a = world
            .add_body(BodyDesc::dynamic(cube.clone()).position(centre_a))
            .unwrap();
        let b = world
            .add_body(BodyDesc::dynamic(cube.clone()).position(centre_b))
            .unwrap();
        let hinge = tumble::JointKind::Hinge {
            axis: Vec3::Z,
            limits: None,
            motor: None,
        };
        world
            .add_joint(tumble::JointDesc::new(hinge, a, b, anchor))
            .unwrap();
        let dragged = world
            .add_body(BodyDesc::dynamic(cube).position(Vec3::new(0.0, 0.5, 3.0)))
            .unwrap();
        let target = Vec3::new(0.0, 3.0, 3.0);
        world
            .set_drag_target(dragged, Vec3::new(0.0, 0.5, 0.0), target, 100.0)
            .unwrap();
        let constraint_keys = [MeshKey::ConstraintSegment, MeshKey::ConstraintPoint];

        // Off: neither joints nor the drag (nor with batches shown, which colour contacts).
        for batches in [BatchView::Off, BatchView::All] {
            let off = DrawList::build(
                &world,
                DrawSettings {
                    batches,
                    ..Default::default()
                },
            );
            assert!(
                constraint_keys
                    .iter()
                    .all(|key| !off.instances.contains_key(key))
            );
        }

        let on = DrawList::build(
            &world,
            DrawSettings {
                contacts: true,
                ..Default::default()
            },
        );
        // Each box's centre to the anchor (the anchors coincide: no line between them), and
        // the dragged point (the top of its box) to the target.
        let lines = segments(&on, MeshKey::ConstraintSegment);
        assert_eq!(lines.len(), 3, "{lines:?}");
        for (from, to, colour) in [
            (centre_a, anchor, JOINT_COLOUR),
            (centre_b, anchor, JOINT_COLOUR),
            (Vec3::new(0.0, 1.0, 3.0), target, DRAG_COLOUR),
        ] {
            assert!(
                lines
                    .iter()
                    .any(|&(f, t, c)| near(f, from) && near(t, to) && c == colour),
                "no line {from} -> {to} in {lines:?}"
            );
        }
        // A cross at each of the joint's two anchors and at the drag's target.
        let crosses: Vec<(Vec3, [f32; 3])> = segments(&on, MeshKey::ConstraintPoint)
            .into_iter()
            .map(|(centre, _, colour)| (centre, colour))
            .collect();
        assert_eq!(
            crosses,
            [
                (anchor, JOINT_COLOUR),
                (anchor, JOINT_COLOUR),
                (target, DRAG_COLOUR)
            ]
        );
        // They belong to no body (a GPU step does not move them) and are drawn over the scene.
        for key in constraint_keys {
            assert!(on.links[&key].iter().all(|link| link.body == NO_BODY));
            assert!(key.over_scene());
        }
        assert!(!MeshKey::Segment.over_scene() && !MeshKey::Cube.over_scene());

        // Once the hinge stretches, the line between its anchors shows how far.
        world
            .set_velocity(a, Vec3::new(0.0, -5.0, 0.0), Vec3::ZERO)
            .unwrap();
        world.step();
        let (anchor_a, anchor_b) = world
            .joint_anchors(world.joints().next().unwrap().0)
            .unwrap();
        assert_ne!(anchor_a, anchor_b);
        let stepped = DrawList::build(
            &world,
            DrawSettings {
                contacts: true,
                ..Default::default()
            },
        );
        let lines = segments(&stepped, MeshKey::ConstraintSegment);
        assert!(
            lines
                .iter()
                .any(|&(f, t, _)| near(f, anchor_a) && near(t, anchor_b)),
            "no line between the anchors {anchor_a} and {anchor_b}: {lines:?}"
        );
    }

    #[test]
    fn colours_are_in_range_and_differ() {
        for index in 0..100 {
            assert!(body_colour(index).iter().all(|c| (0.0..=1.0).contains(c)));
        }
        assert_ne!(body_colour(0), body_colour(1));
    }
}
