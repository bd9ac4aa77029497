//! `tumble view`: headless pictures from the command line, and clear one-line errors when
//! there is neither a display nor --png, no adapter matches, or the picture is larger than the
//! adapter renders.
use std::path::PathBuf;
use std::process::{Command, Output};

/// Runs `tumble` with no display: DISPLAY and WAYLAND_DISPLAY removed from its environment.
fn tumble_without_display(args: &[&str], env: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tumble"))
        .args(args)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        // Mesa's device-select Vulkan layer looks for a display and, finding none, has
        // libwayland print "XDG_RUNTIME_DIR is invalid" on stderr: not ours to test.
        .env("NODEVICE_SELECT", "1")
        .envs(env.iter().copied())
        .output()
        .expect("tumble runs")
}

fn one_line_error(output: &Output) -> String {
    let message = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(!output.status.success(), "succeeded: {message}");
    assert!(!message.contains("panicked"), "panicked: {message}");
    assert_eq!(
        message.trim_end().lines().count(),
        1,
        "not one line: {message}"
    );
    message
}

fn scratch(name: &str) -> PathBuf {
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&path);
    std::fs::create_dir_all(&path).expect("scratch folder");
    path
}

#[test]
fn no_display_and_no_png_says_how_to_run_headless() {
    let output = tumble_without_display(&["view", "falling-boxes", "--scale", "0.01"], &[]);
    let message = one_line_error(&output);
    assert!(message.contains("no display"), "{message}");
    assert!(
        message.contains("tumble view falling-boxes --steps 120 --png"),
        "{message}"
    );
}

#[test]
fn a_display_that_does_not_answer_is_said_before_any_step() {
    // No X server listens on display 4095: the error must come at once, not after the hours
    // of steps asked for (or the particles' million being built).
    for args in [
        &["view", "falling-boxes", "--steps", "1000000"][..],
        &["view", "particles", "--steps", "1000000"],
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_tumble"))
            .args(args)
            .env("DISPLAY", ":4095")
            .env_remove("WAYLAND_DISPLAY")
            .env("NODEVICE_SELECT", "1")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("tumble runs");
        let start = std::time::Instant::now();
        while child.try_wait().expect("waits").is_none() {
            if start.elapsed() > std::time::Duration::from_secs(30) {
                child.kill().expect("kills");
                panic!("{args:?}: still running after 30 s");
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        let message = one_line_error(&child.wait_with_output().expect("output"));
        assert!(message.contains("no display"), "{message}");
        assert!(message.contains("--png"), "{message}");
    }
}

#[test]
fn unknown_adapter_is_a_clear_error() {
    let dir = scratch("view-adapter");
    let png = dir.join("out.png");
    let output = tumble_without_display(
        &[
            "view",
            "falling-boxes",
            "--scale",
            "0.01",
            "--png",
            png.to_str().unwrap(),
        ],
        &[("TUMBLE_ADAPTER", "no-such-adapter")],
    );
    let message = one_line_error(&output);
    assert!(message.contains("TUMBLE_ADAPTER"), "{message}");
    assert!(!png.exists());
}

#[test]
fn a_picture_larger_than_the_adapter_renders_is_a_clear_error() {
    let dir = scratch("view-too-large");
    let png = dir.join("out.png");
    let output = tumble_without_display(
        &[
            "view",
            "falling-boxes",
            "--scale",
            "0.01",
            "--size",
            "100000x100000",
            "--png",
            png.to_str().unwrap(),
        ],
        &[],
    );
    let message = one_line_error(&output);
    assert!(
        message.contains("cannot render a 100000x100000 image (largest: "),
        "{message}"
    );
    assert!(message.contains("use a smaller --size"), "{message}");
    assert!(!png.exists());
}

#[test]
fn png_and_frames_are_written_headless() {
    let dir = scratch("view-frames");
    let png = dir.join("out.png");
    let frames = dir.join("frames");
    let output = tumble_without_display(
        &[
            "view",
            "falling-boxes",
            "--scale",
            "0.01",
            "--steps",
            "2",
            "--size",
            "64x48",
            // A leading minus is a coordinate, not a flag.
            "--camera",
            "-20,10,30,0,1,0",
            "--png",
            png.to_str().unwrap(),
            "--frames",
            frames.to_str().unwrap(),
        ],
        &[],
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    for path in [
        png,
        frames.join("frame_00000.png"),
        frames.join("frame_00002.png"),
    ] {
        let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}", path.display());
    }
    assert!(!frames.join("frame_00003.png").exists());
    // With frames, the medians: the step, the draw, and each pass's GPU time (all positive)
    // or why there are none.
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("per frame (medians): step"), "{stdout}");
    let passes = stdout
        .lines()
        .find(|line| line.starts_with("GPU per pass"))
        .unwrap_or_else(|| panic!("no GPU pass line in {stdout}"));
    if !passes.ends_with("no timestamps (the adapter has no TIMESTAMP_QUERY)") {
        let (_, times) = passes.split_once("): ").expect("name ms, ...");
        let names: Vec<&str> = times
            .split(", ")
            .map(|pass| {
                let (name, ms) = pass.trim_end_matches(" ms").rsplit_once(' ').unwrap();
                let ms: f64 = ms.parse().unwrap_or_else(|e| panic!("{pass}: {e}"));
                assert!(ms > 0.0, "{passes}");
                name
            })
            .collect();
        assert_eq!(names, ["shadow", "meshes", "ground"], "{passes}");
    }
}

#[test]
fn the_particle_demo_is_drawn_headless() {
    let dir = scratch("view-particles");
    let png = dir.join("particles.png");
    let args = ["view", "particles", "--scale", "0.0005", "--steps", "20"];
    let output = tumble_without_display(
        &[
            &args[..],
            &["--size", "160x90", "--png", png.to_str().unwrap()],
        ]
        .concat(),
        &[],
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("500 particles after 20 steps"), "{stdout}");
    let bytes = std::fs::read(&png).expect("the picture is written");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    // Without --png or --frames it opens a window; with no display, how to draw it instead.
    let message = one_line_error(&tumble_without_display(&args, &[]));
    assert!(message.contains("no display"), "{message}");
    assert!(message.contains("--png"), "{message}");
    // The profile overlay shows the demo's stages.
    let png = png.to_str().unwrap();
    let profiled = [&args[..], &["--png", png, "--overlay", "profile"]].concat();
    let output = tumble_without_display(&profiled, &[]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    // Batch colours, contacts and joints only mean something for a rigid-body world:
    // refused by name.
    for flag in ["--batches", "--contacts"] {
        let refused = [&args[..], &["--png", png, flag]].concat();
        let message = one_line_error(&tumble_without_display(&refused, &[]));
        assert!(message.contains(flag), "{message}");
    }
}

#[test]
fn contacts_and_constraints_are_drawn_headless() {
    // One ragdoll (ten joints), fallen onto the ground: contacts and joints to draw.
    let dir = scratch("view-contacts");
    let picture = |name: &str, flags: &[&str]| {
        let png = dir.join(name);
        let args = ["view", "ragdolls", "--scale", "0.01", "--steps", "30"];
        let size = ["--size", "96x64", "--png", png.to_str().unwrap()];
        let output = tumble_without_display(&[&args[..], &size, flags].concat(), &[]);
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        std::fs::read(&png).expect("the picture is written")
    };
    let plain = picture("plain.png", &[]);
    let with = picture("contacts.png", &["--contacts"]);
    assert_eq!(&with[..8], b"\x89PNG\r\n\x1a\n");
    // The same world and camera: only what --contacts adds differs.
    assert_ne!(plain, with, "--contacts drew nothing");
}

#[test]
fn the_bunnies_are_drawn_headless() {
    let dir = scratch("view-bunnies");
    let png = dir.join("bunnies.png");
    let output = tumble_without_display(
        &[
            "view",
            "bunnies",
            "--scale",
            "0.001",
            "--steps",
            "10",
            "--size",
            "160x90",
            "--png",
            png.to_str().unwrap(),
        ],
        &[],
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("952 particles after 10 steps"), "{stdout}");
    let bytes = std::fs::read(&png).expect("the picture is written");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
}
