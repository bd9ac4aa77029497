//! Bad scene input gets a typed error naming the field, never a panic.
use tumble::scene::{Scene, SceneError};

fn error_of(json: &str) -> String {
    match Scene::from_json(json) {
        Ok(_) => panic!("accepted a bad scene: {json}"),
        Err(error) => error.to_string(),
    }
}

fn scene_with_body(body: &str) -> String {
    format!(
        r#"{{ "bodies": [ {{ "shape": {{ "plane": {{ "normal": [0, 1, 0] }} }}, "mass": 0 }}, {body} ] }}"#
    )
}

/// A box on the ground with one contact point whose narrowphase cache has `fields` after its
/// position, normal and margin (all good).
fn contact_with_cache(fields: &str) -> String {
    let body = r#"{ "shape": { "box": { "half_extents": [0.5, 0.5, 0.5] } } }"#;
    let contact = format!(
        r#""contacts": [ {{ "bodies": [0, 1], "points": [ {{ "id": 3, "anchor": [0.5, 0, 0.5],
        "normal_impulse": 1, "tangent_impulse": [0, 0] }} ], "cache": {{ "position": [0, 0.5, 0],
        "normal": [0, 1, 0], "margin": 0.02, {fields} }} }} ]"#
    );
    let scene = scene_with_body(body);
    format!("{}, {contact} }}", scene.trim_end().trim_end_matches('}'))
}

#[test]
fn each_bad_input_names_its_field() {
    let cases = [
        (
            scene_with_body(r#"{ "shape": { "box": { "half_extents": [0.5, 0, 0.5] } } }"#),
            "bodies[1].shape.box.half_extents: must be > 0",
        ),
        (
            scene_with_body(r#"{ "shape": { "box": { "half_extents": [0.5, -1, 0.5] } } }"#),
            "bodies[1].shape.box.half_extents: must be > 0",
        ),
        (
            scene_with_body(r#"{ "shape": { "sphere": { "radius": -1 } } }"#),
            "bodies[1].shape.sphere.radius: must be > 0",
        ),
        (
            scene_with_body(r#"{ "shape": { "sphere": { "radius": 1 } }, "mass": -2 }"#),
            "bodies[1].mass: must be >= 0, got -2",
        ),
        (
            scene_with_body(
                r#"{ "shape": { "convex_hull": { "points": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]] } } }"#,
            ),
            "bodies[1].shape.convex_hull.points: all points are coplanar",
        ),
        (
            scene_with_body(
                r#"{ "shape": { "convex_hull": { "points": [[0, 0, 0], [1, 0, 0]] } } }"#,
            ),
            "bodies[1].shape.convex_hull.points: a hull needs at least 4 points, got 2",
        ),
        (
            scene_with_body(
                r#"{ "shape": { "sphere": { "radius": 1 } }, "position": [0, 1e39, 0] }"#,
            ),
            "bodies[1].position[1]: number out of range",
        ),
        (
            scene_with_body(
                r#"{ "shape": { "sphere": { "radius": 1 } }, "position": [0, 1e999, 0] }"#,
            ),
            "bodies[1].position",
        ),
        (
            scene_with_body(
                r#"{ "shape": { "sphere": { "radius": 1 } }, "position": [0, NaN, 0] }"#,
            ),
            "bodies[1].position",
        ),
        (
            scene_with_body(r#"{ "shape": { "cone": { "radius": 1 } } }"#),
            "bodies[1].shape: unknown variant `cone`",
        ),
        (
            scene_with_body(r#"{ "shape": { "sphere": { "radius": 1 } }, "colour": "red" }"#),
            "bodies[1].colour: unknown field `colour`",
        ),
        (
            scene_with_body(r#"{ "shape": { "sphere": { "radius": 1, "height": 2 } } }"#),
            "unknown field `height`",
        ),
        (
            scene_with_body(r#"{ "shape": { "plane": { "normal": [0, 1, 0] } }, "mass": 1 }"#),
            "bodies[1].mass: a plane is infinite and must be static",
        ),
        (
            scene_with_body(r#"{ "shape": { "plane": { "normal": [0, 0, 0] } }, "mass": 0 }"#),
            "bodies[1].shape.plane.normal",
        ),
        (
            scene_with_body(
                r#"{ "shape": { "sphere": { "radius": 1 } }, "rotation": [0, 0, 0, 0] }"#,
            ),
            "bodies[1].rotation",
        ),
        (
            scene_with_body(r#"{ "shape": { "sphere": { "radius": 1 } }, "restitution": 2 }"#),
            "bodies[1].restitution",
        ),
        (
            scene_with_body(r#"{ "name": "ground", "shape": { "sphere": { "radius": 1 } } }"#)
                .replace(r#""mass": 0 }"#, r#""mass": 0, "name": "ground" }"#),
            "bodies[1].name",
        ),
        (r#"{ "dt": 0, "bodies": [] }"#.to_string(), "dt must be > 0"),
        (
            r#"{ "bodies": [], "gravity": [0, -9.81] }"#.to_string(),
            "gravity",
        ),
        (
            r#"{ "bodies": [], "speed": 3 }"#.to_string(),
            "unknown field `speed`",
        ),
        (
            r#"{ "gravity": [0, -9.81, 0] }"#.to_string(),
            "missing field `bodies`",
        ),
        (
            r#"{ "bodies": [], "contacts": [ { "bodies": [0, 7], "points": [] } ] }"#.to_string(),
            "contacts[0].bodies",
        ),
        ("not json".to_string(), "scene: not valid JSON"),
        (
            contact_with_cache(r#""rotation": [0, 0, 0, 2], "separations": [-0.001]"#),
            "contacts[0].cache: rotation and normal must be unit",
        ),
        (
            contact_with_cache(r#""rotation": [0, 0, 0, 1], "separations": []"#),
            "contacts[0].cache: 0 separations for 1 points: one per point",
        ),
        (
            contact_with_cache(r#""rotation": [0, 0, 0, 1], "separations": [-0.001], "age": 3"#),
            "unknown field `age`",
        ),
        (
            contact_with_cache(r#""rotation": [0, 0, 0, 1], "separations": [-0.001]"#)
                .replace(r#""bodies": [0, 1],"#, r#""bodies": [0, 1], "child": 2,"#),
            "contacts[0].cache: a contact with a mesh triangle keeps no cache",
        ),
    ];
    for (json, expected) in cases {
        let message = error_of(&json);
        assert!(
            message.contains(expected),
            "error {message:?} should contain {expected:?}"
        );
        assert!(!message.contains('\n'), "one line: {message:?}");
    }
}

#[test]
fn a_missing_file_is_an_io_error_naming_the_path() {
    let error = Scene::load(std::path::Path::new("/no/such/scene.json")).unwrap_err();
    assert!(matches!(error, SceneError::Io { .. }));
    assert!(error.to_string().contains("/no/such/scene.json"));
}

#[test]
fn the_design_example_scene_loads() {
    let json = r#"{
      "gravity": [0, -9.81, 0], "dt": 0.016666667, "substeps": 1, "solver_iterations": 10,
      "bodies": [
        { "name": "ground", "shape": { "plane": { "normal": [0, 1, 0], "offset": 0 } }, "mass": 0,
          "friction": 0.5, "restitution": 0 },
        { "name": "box", "shape": { "box": { "half_extents": [0.5, 0.5, 0.5] } },
          "position": [0, 2, 0], "rotation": [0, 0, 0, 1], "mass": 1,
          "linear_velocity": [0, 0, 0], "angular_velocity": [0, 0, 0],
          "friction": 0.5, "restitution": 0 }
      ]
    }"#;
    let scene = Scene::from_json(json).unwrap();
    let mut world = scene.build().unwrap();
    world.step();
    let body = world.find("box").unwrap();
    assert!(world.pose(body).unwrap().position.y < 2.0);
}

#[test]
fn a_non_unit_rotation_is_normalized() {
    let json =
        scene_with_body(r#"{ "shape": { "sphere": { "radius": 1 } }, "rotation": [0, 0, 0, 2] }"#);
    let world = Scene::from_json(&json).unwrap().build().unwrap();
    let body = world.bodies().nth(1).unwrap();
    assert_eq!(world.pose(body).unwrap().rotation.w, 1.0);
}

/// A scene with a static ground, two dynamic bodies ("ball", index 1; a box, index 2) and a
/// static "post" (index 3), and the given joints.
fn scene_with_joints(joints: &str) -> String {
    format!(
        r#"{{ "bodies": [
            {{ "name": "ground", "shape": {{ "plane": {{ "normal": [0, 1, 0] }} }}, "mass": 0 }},
            {{ "name": "ball", "shape": {{ "sphere": {{ "radius": 0.2 }} }}, "position": [0, 2, 0] }},
            {{ "shape": {{ "box": {{ "half_extents": [0.2, 0.2, 0.2] }} }}, "position": [1, 2, 0] }},
            {{ "name": "post", "shape": {{ "sphere": {{ "radius": 0.1 }} }}, "position": [0, 3, 0],
               "mass": 0 }}
          ],
          "joints": [ {joints} ] }}"#
    )
}

#[test]
fn each_bad_joint_names_its_field() {
    let hinge = |extra: &str| {
        format!(r#"{{ "kind": "hinge", "body_a": 1, "body_b": 2, "anchor": [0.5, 2, 0] {extra} }}"#)
    };
    let cone = |extra: &str| {
        format!(
            r#"{{ "kind": "cone_twist", "body_a": "post", "body_b": "ball", "anchor": [0, 3, 0],
                 "axis": [0, -1, 0] {extra} }}"#
        )
    };
    let good = r#"{ "kind": "point", "body_a": "post", "body_b": "ball", "anchor": [0, 3, 0] }"#;
    let cases = [
        (
            r#"{ "kind": "point", "body_a": 7, "body_b": 1, "anchor": [0, 0, 0] }"#.to_string(),
            "joints[0].body_a: body index 7 is out of range: the scene has 4 bodies",
        ),
        (
            r#"{ "kind": "point", "body_a": 1, "body_b": "nobody", "anchor": [0, 0, 0] }"#
                .to_string(),
            r#"joints[0].body_b: no body is named "nobody""#,
        ),
        (
            r#"{ "kind": "point", "body_a": -1, "body_b": 1, "anchor": [0, 0, 0] }"#.to_string(),
            "joints[0].body_a: invalid type: integer `-1`, expected a body index",
        ),
        (
            r#"{ "kind": "point", "body_a": 1, "body_b": "ball", "anchor": [0, 0, 0] }"#
                .to_string(),
            "joints[0].body_b: is the same body as body_a",
        ),
        (
            r#"{ "kind": "point", "body_a": "ground", "body_b": 3, "anchor": [0, 0, 0] }"#
                .to_string(),
            "joints[0]: both bodies are static",
        ),
        (
            r#"{ "kind": "point", "body_a": 1, "body_b": 2 }"#.to_string(),
            "joints[0]: missing field `anchor`",
        ),
        (
            r#"{ "kind": "slider", "body_a": 1, "body_b": 2, "anchor": [0, 0, 0] }"#.to_string(),
            "joints[0].kind: unknown variant `slider`",
        ),
        (
            hinge(r#", "axis": [0, 0, 1], "stiffness": 3"#),
            "joints[0].stiffness: unknown field `stiffness`",
        ),
        (
            format!("{good}, {}", hinge(r#", "axis": [0, 0, 0]"#)),
            "joints[1].axis: must be non-zero",
        ),
        (hinge(""), "joints[0].axis: a hinge joint needs axis"),
        (
            hinge(r#", "axis": [0, 0, 1], "limits": [1, -1]"#),
            "joints[0].limits: [1, -1] must have lower <= upper, both within [-pi, pi] rad",
        ),
        (
            hinge(r#", "axis": [0, 0, 1], "limits": [-4, 0]"#),
            "joints[0].limits: [-4, 0] must have lower <= upper",
        ),
        (
            hinge(r#", "axis": [0, 0, 1], "motor": { "target_speed": 1, "max_torque": -1 }"#),
            "joints[0].motor.max_torque: must be >= 0, got -1",
        ),
        (
            hinge(r#", "axis": [0, 0, 1], "motor": { "target_speed": 1, "torque": 1 }"#),
            "joints[0].motor.torque: unknown field `torque`",
        ),
        (
            hinge(r#", "axis": [0, 0, 1], "swing_limit": 1"#),
            "joints[0].swing_limit: a hinge joint has no swing_limit; remove it",
        ),
        (
            hinge(r#", "axis": [0, 0, 1], "break_impulse": 0"#),
            "joints[0].break_impulse: must be > 0, got 0",
        ),
        (
            r#"{ "kind": "point", "body_a": 1, "body_b": 2, "anchor": [0, 0, 0], "axis": [1, 0, 0] }"#
                .to_string(),
            "joints[0].axis: a point joint has no axis; remove it",
        ),
        (
            r#"{ "kind": "fixed", "body_a": 1, "body_b": 2, "anchor": [0, 0, 0], "limits": [0, 1] }"#
                .to_string(),
            "joints[0].limits: a fixed joint has no limits; remove it",
        ),
        (
            cone(r#", "twist_limits": [-1, 1]"#),
            "joints[0].swing_limit: a cone_twist joint needs swing_limit",
        ),
        (
            cone(r#", "swing_limit": 1"#),
            "joints[0].twist_limits: a cone_twist joint needs twist_limits",
        ),
        (
            cone(r#", "swing_limit": 4, "twist_limits": [-1, 1]"#),
            "joints[0].swing_limit: must be within [0, pi] rad, got 4",
        ),
        (
            cone(r#", "swing_limit": 1, "twist_limits": [0.5, -0.5]"#),
            "joints[0].twist_limits: [0.5, -0.5] must have lower <= upper",
        ),
        (
            cone(
                r#", "swing_limit": 1, "twist_limits": [-1, 1], "motor": { "target_speed": 1, "max_torque": 1 }"#,
            ),
            "joints[0].motor: a cone_twist joint has no motor; remove it",
        ),
    ];
    for (joints, expected) in cases {
        let message = error_of(&scene_with_joints(&joints));
        assert!(
            message.contains(expected),
            "error {message:?} should contain {expected:?}"
        );
        assert!(!message.contains('\n'), "one line: {message:?}");
    }
}

#[test]
fn joints_load_by_index_and_by_name() {
    let joints = r#"
        { "kind": "point", "body_a": "post", "body_b": "ball", "anchor": [0, 3, 0] },
        { "kind": "hinge", "body_a": 1, "body_b": 2, "anchor": [0.5, 2, 0], "axis": [0, 0, 2],
          "limits": [-1, 1], "motor": { "target_speed": 1, "max_torque": 2 }, "break_impulse": 10 },
        { "kind": "cone_twist", "body_a": "ball", "body_b": 2, "anchor": [0.5, 2, 0],
          "axis": [1, 0, 0], "swing_limit": 0.5, "twist_limits": [-0.2, 0.3] },
        { "kind": "fixed", "body_a": 2, "body_b": "post", "anchor": [1, 2.5, 0] }"#;
    let scene = Scene::from_json(&scene_with_joints(joints)).unwrap();
    let pairs: Vec<_> = scene.joints.iter().map(|j| (j.body_a, j.body_b)).collect();
    assert_eq!(pairs, [(3, 1), (1, 2), (1, 2), (2, 3)]);
    let world = scene.build().unwrap();
    assert_eq!(world.joints().count(), 4);
    // The loader normalized the hinge axis.
    let hinge = world.joints().nth(1).unwrap().1;
    assert!((hinge.local_axis_a.length() - 1.0).abs() < 1e-6);
}

#[test]
fn a_scene_file_without_settings_gets_the_engine_defaults() {
    let scene = Scene::from_json(r#"{ "bodies": [] }"#).unwrap();
    assert_eq!(scene.config, tumble::StepConfig::default());
}

/// A body whose shape is a compound of `children` (JSON list items).
fn scene_with_compound(children: &str) -> String {
    scene_with_body(&format!(
        r#"{{ "shape": {{ "compound": {{ "children": [ {children} ] }} }} }}"#
    ))
}

#[test]
fn each_bad_compound_child_names_its_field() {
    let ball = r#"{ "shape": { "sphere": { "radius": 0.2 } }, "position": [0.5, 0, 0] }"#;
    let cases = [
        (
            scene_with_compound(""),
            "bodies[1].shape.compound.children: a compound needs at least one child shape",
        ),
        (
            scene_with_compound(&format!(
                r#"{ball}, {{ "shape": {{ "plane": {{ "normal": [0, 1, 0] }} }} }}"#
            )),
            "bodies[1].shape.compound.children[1].shape: a compound's children must be convex",
        ),
        (
            scene_with_compound(&format!(
                r#"{{ "shape": {{ "compound": {{ "children": [ {ball} ] }} }} }}"#
            )),
            "bodies[1].shape.compound.children[0].shape: a compound's children must be convex \
             (sphere, box, capsule, convex_hull), not compound",
        ),
        (
            scene_with_compound(r#"{ "shape": { "sphere": { "radius": 0 } } }"#),
            "bodies[1].shape.compound.children[0].shape: child 0: sizes must be finite and > 0",
        ),
        (
            scene_with_compound(&format!(
                r#"{ball}, {{ "shape": {{ "capsule": {{ "radius": 0.1, "half_height": -1 }} }} }}"#
            )),
            "bodies[1].shape.compound.children[1].shape: child 1: sizes must be finite and > 0",
        ),
        (
            scene_with_compound(
                r#"{ "shape": { "sphere": { "radius": 1 } }, "rotation": [0, 0, 0, 0] }"#,
            ),
            "bodies[1].shape.compound.children[0].rotation: child 0: rotation is the zero \
             quaternion",
        ),
        (
            scene_with_compound(
                r#"{ "shape": { "sphere": { "radius": 1 } }, "position": [0, 1e39, 0] }"#,
            ),
            "bodies[1].shape.compound.children[0].position[1]: number out of range",
        ),
        (
            scene_with_compound(r#"{ "shape": { "sphere": { "radius": 1 } }, "scale": 2 }"#),
            "bodies[1].shape.compound.children[0].scale: unknown field `scale`",
        ),
        (
            scene_with_compound(
                r#"{ "shape": { "convex_hull": { "points": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]] } } }"#,
            ),
            "bodies[1].shape.compound.children[0].shape.convex_hull.points: all points are \
             coplanar",
        ),
    ];
    for (json, expected) in cases {
        let message = error_of(&json);
        assert!(
            message.contains(expected),
            "error {message:?} should contain {expected:?}"
        );
        assert!(!message.contains('\n'), "one line: {message:?}");
    }
}

#[test]
fn a_compound_scene_loads_and_falls() {
    let json = scene_with_compound(
        r#"{ "shape": { "sphere": { "radius": 0.2 } }, "position": [-0.5, 1, 0] },
           { "shape": { "box": { "half_extents": [0.5, 0.05, 0.05] } }, "position": [0, 1, 0],
             "rotation": [0, 0, 0, 2] },
           { "shape": { "sphere": { "radius": 0.2 } }, "position": [0.5, 1, 0] }"#,
    );
    let mut world = Scene::from_json(&json).unwrap().build().unwrap();
    let body = world.bodies().nth(1).unwrap();
    // The body frame is the compound's centroid, between the balls.
    let start = world.pose(body).unwrap().position;
    assert!(
        (start - tumble::math::vec3(0.0, 1.0, 0.0)).length() < 1e-6,
        "{start}"
    );
    world.step();
    assert!(world.pose(body).unwrap().position.y < 1.0);
}
