//! The `tumble` binary: its contract from DESIGN.md (exit codes, one-line errors, --json, --dump).
use std::process::{Command, Output};

fn tumble(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tumble"))
        .args(args)
        .output()
        .expect("tumble runs")
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Fails unless the command exited non-zero with one line on stderr mentioning `expected`.
fn assert_user_error(args: &[&str], expected: &str) {
    let output = tumble(args);
    let message = stderr(&output);
    assert!(!output.status.success(), "{args:?} succeeded");
    assert!(
        !message.contains("panicked"),
        "{args:?} panicked: {message}"
    );
    assert_eq!(
        message.trim_end().lines().count(),
        1,
        "{args:?}: not one line: {message}"
    );
    assert!(
        message.contains(expected),
        "{args:?}: {message:?} should mention {expected:?}"
    );
}

#[test]
fn scenes_lists_the_builtins() {
    let output = tumble(&["scenes"]);
    assert!(output.status.success());
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(text.contains("falling-boxes") && text.contains("stacked-boxes"));
}

#[test]
fn bad_input_is_a_one_line_error_with_non_zero_exit() {
    let dir = std::env::temp_dir().join(format!("tumble-cli-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.json");
    std::fs::write(
        &bad,
        r#"{ "bodies": [ { "shape": { "box": { "half_extents": [1, 0, 1] } } } ] }"#,
    )
    .unwrap();
    assert_user_error(
        &["run", bad.to_str().unwrap(), "--steps", "1"],
        "bodies[0].shape.box.half_extents",
    );
    assert_user_error(&["run", "/no/such/scene.json"], "/no/such/scene.json");
    assert_user_error(&["run", "no-such-scene"], "unknown scene");
    assert_user_error(&["run", "falling-boxes", "--scale", "-1"], "scale");
    assert_user_error(
        &["run", "falling-boxes", "--stages", "warp=cpu"],
        "unknown stage",
    );
    assert_user_error(
        &["run", "falling-boxes", "--batcher", "greedy"],
        "unknown batcher",
    );
    assert_user_error(
        &["run", "falling-boxes", "--solver", "sor"],
        "--solver: unknown solver \"sor\"; solvers are pgs, jacobi",
    );
    assert_user_error(
        &["view", "falling-boxes", "--solver", "gs", "--png", "x.png"],
        "unknown solver",
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn json_summary_and_dump_that_loads_back() {
    let dir = std::env::temp_dir().join(format!("tumble-cli-dump-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let dump = dir.join("dump.json");
    let output = tumble(&[
        "run",
        "stacked-boxes",
        "--scale",
        "0.02",
        "--steps",
        "20",
        "--device",
        "cpu",
        "--json",
        "--profile",
        "--dump",
        dump.to_str().unwrap(),
    ]);
    assert!(output.status.success(), "{}", stderr(&output));
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        stdout.contains("--- Profiling: step") && stdout.contains("-- solver"),
        "profile report: {stdout}"
    );
    // The first step is reported alone; the profile averages the other 19.
    assert!(
        stdout.contains("first step: ") && stdout.contains("over 19 frames"),
        "profile report: {stdout}"
    );
    let last = stdout.lines().last().unwrap();
    let summary: serde_json::Value = serde_json::from_str(last).unwrap();
    for key in [
        "scene",
        "bodies",
        "steps",
        "device",
        "adapter",
        "ms_per_step",
        "stage_ms",
        "pairs",
        "contacts",
        "max_penetration",
        "kinetic_energy",
        "batching_rounds",
    ] {
        assert!(summary.get(key).is_some(), "--json lacks {key}: {last}");
    }
    assert_eq!(summary["steps"], 20);
    // The dump is a scene file: it runs.
    let output = tumble(&[
        "run",
        dump.to_str().unwrap(),
        "--steps",
        "5",
        "--device",
        "cpu",
    ]);
    assert!(output.status.success(), "{}", stderr(&output));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn run_on_the_gpu_shows_stages_and_copies() {
    let output = tumble(&[
        "run",
        "stacked-boxes",
        "--scale",
        "0.02",
        "--steps",
        "5",
        "--device",
        "gpu",
        "--profile",
    ]);
    assert!(output.status.success(), "{}", stderr(&output));
    let stdout = String::from_utf8_lossy(&output.stdout);
    // Stages 1 to 4 run as one submission, under one line.
    for line in [
        "-- collision",
        "-- batching",
        "copy to gpu [copy]",
        "copy to cpu [copy]",
    ] {
        assert!(
            stdout.contains(line),
            "no {line:?} in the profile: {stdout}"
        );
    }
    // "N batches by colors in R rounds on <devices>", R > 0.
    let batches = stdout
        .lines()
        .find(|line| line.contains(" batches by colors in "));
    let rounds = batches.and_then(|line| line.split(" in ").nth(1)?.split(' ').next());
    assert!(
        rounds.is_some_and(|r| r.parse::<usize>().is_ok_and(|r| r > 0)),
        "{stdout}"
    );
    assert!(
        stdout.contains(
            "rounds on aabb=gpu,broadphase=gpu,narrowphase=gpu,constraints=gpu,batching=gpu,solver=gpu"
        ),
        "{stdout}"
    );
}

#[test]
fn bench_broadphase_runs_on_a_tiny_scene() {
    let output = tumble(&[
        "bench",
        "broadphase",
        "--count",
        "200",
        "--moving",
        "0.5",
        "--frames",
        "3",
    ]);
    assert!(output.status.success(), "{}", stderr(&output));
    let text = String::from_utf8_lossy(&output.stdout);
    // Every exact broadphase reports the same pair count as brute force.
    let pairs: Vec<(&str, &str)> = text
        .lines()
        .filter_map(|line| {
            let fields: Vec<&str> = line.split_whitespace().collect();
            (fields.len() == 6 && fields[0] != "broadphase").then(|| (fields[0], fields[5]))
        })
        .collect();
    let names: Vec<&str> = pairs.iter().map(|p| p.0).collect();
    let mut expected = vec!["dbvt", "dbvt-exact", "grid", "sap", "brute-force"];
    // The GPU broadphase's two traversals, wherever there is an adapter (tests have one).
    if !text.contains("no GPU adapter") {
        expected.extend(["lbvh-history", "lbvh-ropes"]);
        assert!(text.contains("# GPU time alone"), "{text}");
    }
    assert_eq!(names, expected);
    let exact: Vec<&str> = pairs[1..].iter().map(|p| p.1).collect();
    assert!(exact.iter().all(|&count| count == exact[0]), "{text}");
    // A flag clap rejects: its own error (with a usage hint, so not one line), no panic.
    let refused = tumble(&["bench", "broadphase", "--moving", "2"]);
    assert!(!refused.status.success());
    let message = stderr(&refused);
    assert!(
        message.contains("0..=1") && !message.contains("panicked"),
        "{message}"
    );
}

#[test]
fn raycast_scene_reports_rays_in_the_profile() {
    let output = tumble(&[
        "run",
        "raycast",
        "--scale",
        "0.02",
        "--steps",
        "3",
        "--device",
        "cpu",
        "--profile",
    ]);
    assert!(output.status.success(), "{}", stderr(&output));
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(text.contains("raycast"), "no raycast scope: {text}");
    assert!(text.contains("# rays = 20  # hits = 20"), "{text}");
    let listed = tumble(&["scenes"]);
    assert!(String::from_utf8_lossy(&listed.stdout).contains("raycast"));
}

/// `--device auto` (the default) is the CPU for small scenes, and every stage on a hardware GPU
/// for scenes of 100 bodies or more when there is one (not on Mesa's CPU drivers).
#[test]
fn auto_runs_large_scenes_on_a_hardware_gpu() {
    let device_of = |scene: &str, scale: &str| {
        let output = tumble(&["run", scene, "--scale", scale, "--steps", "1", "--json"]);
        assert!(output.status.success(), "{}", stderr(&output));
        let stdout = String::from_utf8_lossy(&output.stdout);
        let summary: serde_json::Value =
            serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
        summary["device"].as_str().unwrap().to_owned()
    };
    // 77 bodies.
    assert_eq!(device_of("stacked-boxes", "0.02"), "cpu");
    let hardware = tumble::gpu::GpuContext::shared().is_ok_and(|context| !context.is_cpu_driver());
    let expected = if hardware {
        "aabb=gpu,broadphase=gpu,narrowphase=gpu,constraints=gpu,batching=gpu,solver=gpu"
    } else {
        "cpu"
    };
    // 0.1 × 3008 boxes and the ground: 305 bodies.
    assert_eq!(device_of("falling-boxes", "0.1"), expected);
}

#[test]
fn a_closed_pipe_ends_the_output_quietly() {
    // `tumble run ... | head -1`: the reader is gone before tumble writes. A closed pipe
    // read end, made before the child starts, makes every write fail, with no race.
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let output = Command::new(env!("CARGO_BIN_EXE_tumble"))
        .args([
            "run",
            "falling-boxes",
            "--scale",
            "0.01",
            "--steps",
            "5",
            "--device",
            "cpu",
        ])
        .stdout(writer)
        .stderr(std::process::Stdio::piped())
        .output()
        .expect("tumble runs");
    let message = stderr(&output);
    assert!(!message.contains("panicked"), "{message}");
    assert!(message.is_empty(), "{message}");
    // Ended by SIGPIPE, as `yes | head -1` ends `yes` (no exit code), or exited successfully.
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        assert!(
            output.status.success() || output.status.signal() == Some(13),
            "{:?}",
            output.status
        );
    }
}

/// `--solver jacobi` runs the Jacobi solver, and the profile and the JSON say so.
#[test]
fn run_with_the_jacobi_solver_says_so() {
    let output = tumble(&[
        "run",
        "stacked-boxes",
        "--scale",
        "0.02",
        "--steps",
        "10",
        "--device",
        "cpu",
        "--solver",
        "jacobi",
        "--profile",
        "--json",
    ]);
    assert!(output.status.success(), "{}", stderr(&output));
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        stdout.contains("solver: jacobi") && stdout.contains("jacobi (cpu)"),
        "profile report: {stdout}"
    );
    let summary: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    assert_eq!(summary["solver"], "jacobi");
}

#[test]
fn bunnies_run_at_a_tiny_scale_on_both_devices() {
    let listed = tumble(&["scenes"]);
    assert!(String::from_utf8_lossy(&listed.stdout).contains("bunnies"));
    for device in ["cpu", "gpu"] {
        let args = [
            "run", "bunnies", "--scale", "0.001", "--steps", "30", "--device", device, "--json",
        ];
        let output = tumble(&args);
        assert!(output.status.success(), "{device}: {}", stderr(&output));
        let stdout = String::from_utf8_lossy(&output.stdout);
        let summary: serde_json::Value =
            serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
        assert_eq!(summary["scene"], "bunnies");
        assert_eq!(summary["device"], device);
        assert_eq!(summary["bodies"], 4, "{summary}");
        assert_eq!(summary["particles"], 4 * 238, "{summary}");
        assert!(
            summary["first_step_ms"].as_f64().unwrap() > 0.0,
            "{summary}"
        );
        // Falling for 30 steps: moving.
        assert!(
            summary["kinetic_energy"].as_f64().unwrap() > 0.0,
            "{summary}"
        );
        let profile = tumble(&[&args[..8], &["--profile"]].concat());
        let text = String::from_utf8_lossy(&profile.stdout);
        for stage in ["world particles", "sort", "collide", "bodies"] {
            assert!(
                text.contains(stage),
                "{device} profile lacks {stage}: {text}"
            );
        }
    }
    assert_user_error(&["run", "bunnies", "--scale", "0"], "scale");
    assert_user_error(&["run", "bunnies", "--scale", "-1"], "scale");
    assert_user_error(&["run", "bunnies", "--scale", "1e9"], "bodies");
}

/// Bunnies beyond the host's memory (scale 300: 68 GB, most of it the grid's cells; at 1000
/// the grid has too many cells): one error line naming the bunnies and the bytes, a failing
/// exit, no abort. The child's address space is capped (RLIMIT_AS, 2 GiB) so that on a
/// machine with the 68 GB free the allocator refuses instead of the arrays being made.
#[cfg(target_os = "linux")]
#[test]
fn bunnies_beyond_host_memory_are_an_error() {
    use std::os::unix::process::CommandExt;
    let args = ["run", "bunnies", "--scale", "300", "--device", "cpu"];
    let mut command = Command::new(env!("CARGO_BIN_EXE_tumble"));
    command.args(args);
    // SAFETY: setrlimit is async-signal-safe and touches nothing of the parent.
    unsafe {
        command.pre_exec(|| {
            let mut limit = libc::rlimit {
                rlim_cur: 0,
                rlim_max: 0,
            };
            // The soft limit only, within the hard one.
            if libc::getrlimit(libc::RLIMIT_AS, &mut limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            limit.rlim_cur = limit.rlim_max.min(2 << 30);
            if libc::setrlimit(libc::RLIMIT_AS, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let output = command.output().expect("tumble runs");
    let message = stderr(&output);
    assert!(!output.status.success(), "{args:?} succeeded");
    assert!(!message.contains("panicked"), "{args:?}: {message}");
    assert_eq!(message.trim_end().lines().count(), 1, "{message}");
    assert!(
        message.contains("1228800 bodies of 292454400 particles") && message.contains("bytes"),
        "{message}"
    );
}

/// `tumble run particles` on both devices: the profile shows the pipeline's stages (on the GPU
/// as timestamped kernel passes, with the copies), the JSON summary its fields, and the two
/// devices end in the same state.
#[test]
fn particles_run_at_a_tiny_scale_on_both_devices() {
    let mut energies = Vec::new();
    for device in ["cpu", "gpu"] {
        let args = [
            "run",
            "particles",
            "--scale",
            "0.001",
            "--steps",
            "20",
            "--device",
            device,
        ];
        let output = tumble(&[&args[..], &["--profile"]].concat());
        assert!(output.status.success(), "{device}: {}", stderr(&output));
        let text = String::from_utf8_lossy(&output.stdout);
        assert!(
            text.contains("--- Profiling: particles step")
                && text.contains("over 20 frames")
                && text.contains("particles: 1000 particles, 20 steps on "),
            "{device}: {text}"
        );
        let lines: &[&str] = if device == "cpu" {
            &[
                "-- hash (",
                "-- sort (",
                "-- cell start (",
                "-- collide (",
                "-- scatter (",
            ]
        } else {
            &[
                "-- encode and submit (",
                "-- hash [gpu] (",
                "-- sort [gpu] (",
                "-- cell start [gpu] (",
                "-- collide [gpu] (",
                "-- copy particles to gpu [copy] (",
                "-- copy particles to host [copy] (",
            ]
        };
        for line in lines {
            assert!(
                text.contains(line),
                "{device} profile lacks {line:?}: {text}"
            );
        }
        let output = tumble(&[&args[..], &["--json"]].concat());
        assert!(output.status.success(), "{device}: {}", stderr(&output));
        let stdout = String::from_utf8_lossy(&output.stdout);
        let last = stdout.lines().last().unwrap();
        let summary: serde_json::Value = serde_json::from_str(last).unwrap();
        assert_eq!(summary["scene"], "particles", "{last}");
        assert_eq!(summary["device"], device, "{last}");
        assert_eq!(summary["steps"], 20, "{last}");
        assert_eq!(summary["bodies"], 1000, "{last}");
        assert_eq!(summary["particles"], 1000, "{last}");
        assert!(!summary["adapter"].as_str().unwrap().is_empty(), "{last}");
        assert!(summary["ms_per_step"].as_f64().unwrap() > 0.0, "{last}");
        assert!(summary["stage_ms"].is_object(), "{last}");
        // Falling for 20 steps: moving.
        let energy = summary["kinetic_energy"].as_f64().unwrap();
        assert!(energy > 0.0, "{last}");
        energies.push(energy);
    }
    // Same arithmetic in the same order; a GPU may fuse multiply-adds (gpu_particles.rs allows
    // for that in positions), so allow 0.1 % (lavapipe agrees bitwise).
    let (cpu, gpu) = (energies[0], energies[1]);
    assert!(
        (cpu - gpu).abs() <= 1e-3 * cpu,
        "kinetic energy {cpu} J on the cpu, {gpu} J on the gpu"
    );
    assert_user_error(&["run", "particles", "--scale", "0"], "scale");
    assert_user_error(&["run", "particles", "--scale", "-1"], "scale");
    assert_user_error(&["run", "particles", "--scale", "nan"], "scale");
    // 10¹⁵ particles: past MAX_PARTICLES, on any device.
    assert_user_error(
        &["run", "particles", "--scale", "1e9", "--device", "cpu"],
        "1000000000000000 particles is more than",
    );
}

/// The rows of the section of `text` that starts with the line `title` (up to a blank line),
/// each row's fields separated by single spaces.
fn table_rows(text: &str, title: &str) -> Vec<String> {
    text.lines()
        .skip_while(|line| !line.starts_with(title))
        .skip(1)
        .take_while(|line| !line.trim().is_empty())
        .map(|line| line.split_whitespace().collect::<Vec<_>>().join(" "))
        .collect()
}

/// The talk's six-particle example (tumble::particles::explain, whose test checks the tables
/// against the slides): the same values reach the command line.
#[test]
fn particles_explain_prints_the_talks_tables() {
    let output = tumble(&["run", "particles", "--explain"]);
    assert!(output.status.success(), "{}", stderr(&output));
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(text.starts_with("Uniform grid (4 x 4 cells)\n"), "{text}");
    let cells = table_rows(&text, "Cell ID");
    assert_eq!(cells.len(), 16, "{text}");
    let occupied: Vec<&String> = cells.iter().filter(|row| !row.ends_with(" 0")).collect();
    assert_eq!(occupied, ["4 2 D,F", "6 3 B,C,E", "9 1 A"], "{text}");
    // Array index, unsorted (cell, particle), sorted (cell, particle).
    assert_eq!(
        table_rows(&text, "Array index"),
        [
            "0 9, A 4, D",
            "1 6, B 4, F",
            "2 6, C 6, B",
            "3 4, D 6, C",
            "4 6, E 6, E",
            "5 4, F 9, A"
        ],
        "{text}"
    );
    let starts = table_rows(&text, "Cell index");
    assert_eq!(starts.len(), 16, "{text}");
    let filled: Vec<&String> = starts.iter().filter(|row| row.contains(' ')).collect();
    assert_eq!(filled, ["4 0", "6 2", "9 5"], "{text}");
    assert_eq!(
        table_rows(&text, "Interacting particle pairs"),
        [
            "D,F", "B,C", "B,E", "C,E", "A,D", "A,F", "A,B", "A,C", "A,E"
        ],
        "{text}"
    );
}

/// `--sort bitonic` and `--search 14` reach the particle system on both devices, as its JSON
/// says; bitonic sort gives radix sort's order (the same run, bitwise) and the 14-cell search
/// sums the same forces in fixed point (close, not equal).
#[test]
fn particles_sort_and_search_flags() {
    let summary = |device: &str, flags: &[&str]| {
        let args = [
            "run",
            "particles",
            "--scale",
            "0.001",
            "--steps",
            "20",
            "--device",
            device,
            "--json",
        ];
        let output = tumble(&[&args[..], flags].concat());
        assert!(output.status.success(), "{device}: {}", stderr(&output));
        let stdout = String::from_utf8_lossy(&output.stdout);
        let last = stdout.lines().last().unwrap().to_owned();
        let summary: serde_json::Value = serde_json::from_str(&last).unwrap();
        (
            summary["sort"].as_str().unwrap().to_owned(),
            summary["search"].as_u64().unwrap(),
            summary["kinetic_energy"].as_f64().unwrap(),
        )
    };
    for device in ["cpu", "gpu"] {
        let (sort, search, default) = summary(device, &[]);
        assert_eq!((sort.as_str(), search), ("radix", 27), "{device}");
        let (sort, search, radix) = summary(device, &["--sort", "radix", "--search", "27"]);
        assert_eq!((sort.as_str(), search, radix), ("radix", 27, default));
        let (sort, search, bitonic) = summary(device, &["--sort", "bitonic"]);
        assert_eq!((sort.as_str(), search), ("bitonic", 27), "{device}");
        assert_eq!(bitonic, radix, "{device}: bitonic and radix runs differ");
        let (sort, search, symmetric) = summary(device, &["--search", "14"]);
        assert_eq!((sort.as_str(), search), ("radix", 14), "{device}");
        assert!(
            symmetric != radix && (symmetric - radix).abs() <= 1e-3 * radix,
            "{device}: 14-cell search {symmetric} J, 27-cell {radix} J"
        );
        let (sort, search, _) = summary(device, &["--sort", "bitonic", "--search", "14"]);
        assert_eq!((sort.as_str(), search), ("bitonic", 14), "{device}");
    }
    assert_user_error(
        &["run", "particles", "--sort", "merge"],
        "--sort: unknown sort \"merge\"; sorts are radix, bitonic",
    );
    assert_user_error(
        &["run", "particles", "--search", "26"],
        "--search: unknown search \"26\"; searches are 27, 14",
    );
    assert_user_error(
        &["run", "falling-boxes", "--sort", "bitonic"],
        "--sort is for the particles scene",
    );
    assert_user_error(
        &["run", "bunnies", "--search", "14"],
        "--search is for the particles scene",
    );
}
