//! Triangle meshes in scene files: `trimesh {vertices, indices}` and `obj {path}` load as
//! static meshes, bad meshes are errors naming the field (and the file), and a dump writes a
//! mesh back as its triangles; `obj` with `hull: true` loads the convex hull of the file.
use tumble::Shape;
use tumble::scene::{Scene, SceneError};

fn scene_with(shape: &str, extra: &str) -> String {
    format!(r#"{{ "bodies": [ {{ "shape": {shape}, "mass": 0 {extra} }} ] }}"#)
}

const SQUARE: &str = r#"{ "trimesh": { "vertices": [[0,0,0],[0,0,1],[1,0,0],[1,0,1]],
    "indices": [0,1,2, 2,1,3] } }"#;

#[test]
fn a_trimesh_loads_and_dumps_back_as_itself() {
    let scene = Scene::from_json(&scene_with(SQUARE, "")).unwrap();
    let Shape::TriMesh(mesh) = &scene.bodies[0].shape else {
        panic!("not a mesh: {:?}", scene.bodies[0].shape)
    };
    assert_eq!(mesh.triangles(), [[0, 1, 2], [2, 1, 3]]);
    let dumped = Scene::from_json(&scene.to_json()).unwrap();
    assert_eq!(dumped.bodies[0].shape, scene.bodies[0].shape);
}

#[test]
fn bad_meshes_name_the_field_and_the_problem() {
    let error = |json: String| Scene::from_json(&json).unwrap_err().to_string();
    let cases = [
        (
            scene_with(SQUARE, r#", "mass": 1"#).replace(r#""mass": 0 ,"#, ""),
            "bodies[0].mass",
        ),
        (
            scene_with(
                r#"{ "trimesh": { "vertices": [[0,0,0]], "indices": [] } }"#,
                "",
            ),
            "bodies[0].shape.trimesh: the mesh has no triangles",
        ),
        (
            scene_with(
                r#"{ "trimesh": { "vertices": [[0,0,0],[1,0,0],[0,0,1]], "indices": [0,1,7] } }"#,
                "",
            ),
            "triangle 0 refers to vertex 7, but there are only 3",
        ),
        (
            scene_with(
                r#"{ "trimesh": { "vertices": [[0,0,0],[1,0,0],[2,0,0]], "indices": [0,1,2] } }"#,
                "",
            ),
            "triangle 0 has zero area",
        ),
        (
            scene_with(
                r#"{ "trimesh": { "vertices": [[0,0,0],[1,0,0]], "indices": [0,1] } }"#,
                "",
            ),
            "not a multiple of 3",
        ),
    ];
    for (json, expected) in cases {
        let message = error(json.clone());
        assert!(
            message.contains(expected),
            "{message:?} should contain {expected:?} ({json})"
        );
    }
}

#[test]
fn obj_files_load_relative_to_the_scene_and_errors_name_the_file() {
    let folder = std::env::temp_dir().join(format!("tumble-obj-{}", std::process::id()));
    std::fs::create_dir_all(folder.join("meshes")).unwrap();
    // A unit quad as one polygon (fanned into two triangles) and a second object.
    std::fs::write(
        folder.join("meshes/ground.obj"),
        "o quad\nv 0 0 0\nv 0 0 1\nv 1 0 1\nv 1 0 0\nf 1 2 3 4\no tri\nv 5 0 0\nv 5 0 1\nv 6 0 0\nf 5 6 7\n",
    )
    .unwrap();
    let scene_path = folder.join("scene.json");
    std::fs::write(
        &scene_path,
        scene_with(r#"{ "obj": { "path": "meshes/ground.obj" } }"#, ""),
    )
    .unwrap();
    let scene = Scene::load(&scene_path).unwrap();
    let Shape::TriMesh(mesh) = &scene.bodies[0].shape else {
        panic!("not a mesh")
    };
    assert_eq!(mesh.triangles().len(), 3);
    assert_eq!(mesh.vertices().len(), 7);
    // Every triangle faces +y, as the OBJ's counter-clockwise faces do.
    for index in 0..3 {
        assert!((mesh.triangle(index).normal.y - 1.0).abs() < 1e-6);
    }

    std::fs::write(
        &scene_path,
        scene_with(r#"{ "obj": { "path": "meshes/missing.obj" } }"#, ""),
    )
    .unwrap();
    let error = Scene::load(&scene_path).unwrap_err();
    assert!(matches!(error, SceneError::Invalid { .. }));
    let message = error.to_string();
    assert!(
        message.starts_with("bodies[0].shape.obj.path: ") && message.contains("missing.obj"),
        "{message}"
    );
    std::fs::remove_dir_all(&folder).unwrap();
}

/// `obj` with `hull: true`: the convex hull of the file's vertices, a body that may move; an
/// OBJ with too few or only coplanar vertices is an error naming the field, the file and why.
#[test]
fn obj_hulls_load_and_bad_ones_say_why() {
    let folder = std::env::temp_dir().join(format!("tumble-obj-hull-{}", std::process::id()));
    std::fs::create_dir_all(&folder).unwrap();
    // A unit cube's 8 corners in 6 quads, and an interior vertex the hull leaves out.
    let mut cube = String::new();
    for i in 0..8 {
        cube += &format!("v {} {} {}\n", i & 1, (i >> 1) & 1, i >> 2);
    }
    cube += "v 0.5 0.5 0.5\n";
    cube += "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\nf 1 2 9\n";
    std::fs::write(folder.join("cube.obj"), cube).unwrap();
    std::fs::write(
        folder.join("flat.obj"),
        "v 0 0 0\nv 0 0 1\nv 1 0 1\nv 1 0 0\nf 1 2 3 4\n",
    )
    .unwrap();
    std::fs::write(folder.join("empty.obj"), "# nothing\n").unwrap();
    let load = |file: &str, extra: &str| {
        let scene_path = folder.join("scene.json");
        std::fs::write(
            &scene_path,
            format!(
                r#"{{ "bodies": [ {{ "shape": {{ "obj": {{ "path": "{file}", "hull": true }} }} {extra} }} ] }}"#
            ),
        )
        .unwrap();
        Scene::load(&scene_path)
    };

    let scene = load("cube.obj", r#", "mass": 2, "position": [0, 3, 0]"#).unwrap();
    let Shape::ConvexHull(hull) = &scene.bodies[0].shape else {
        panic!("not a hull: {:?}", scene.bodies[0].shape)
    };
    assert_eq!(
        hull.vertices().len(),
        8,
        "the interior vertex is not on the hull"
    );
    assert_eq!(
        hull.faces().len(),
        6,
        "coplanar triangles merge into the cube's 6 faces"
    );
    assert!((hull.volume() - 1.0).abs() < 1e-5);
    let world = scene.build().unwrap();
    assert_eq!(world.bodies().count(), 1);

    for (file, expected) in [
        ("flat.obj", "all points are coplanar"),
        ("empty.obj", "a hull needs at least 4 points, got 0"),
    ] {
        let error = load(file, "").unwrap_err();
        assert!(matches!(error, SceneError::Invalid { .. }));
        let message = error.to_string();
        assert!(
            message.starts_with("bodies[0].shape.obj.hull: ")
                && message.contains(file)
                && message.contains(expected),
            "{message}"
        );
    }
    let message = load("missing.obj", "").unwrap_err().to_string();
    assert!(
        message.starts_with("bodies[0].shape.obj.path: "),
        "{message}"
    );
    std::fs::remove_dir_all(&folder).unwrap();
}
