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
