//! Triangle meshes in scene files: `trimesh {vertices, indices}` and `obj {path}` load as
//! static meshes, bad meshes are errors naming the field (and the file), and a dump writes a
//! mesh back as its triangles.
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
