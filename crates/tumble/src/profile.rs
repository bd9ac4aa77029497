//! Hierarchical stage timer with a Bullet-style report, as on the talk's screens:
//!
//! ```text
//! --- Profiling: step (total running time: 1.234 ms / frame over 100 frames) ---
//! 1 -- broadphase (21.30 %) :: 0.263 ms / frame (1 calls)
//!    1.1 -- query (90.00 %) :: 0.237 ms / frame (1 calls)
//! Unaccounted (0.40 %) :: 0.005 ms
//! ```
//!
//! CPU stages open and close scopes around their work; GPU stages and host↔device copies are
//! recorded as finished spans (their time comes from timestamp queries resolved after the
//! frame), under a path of scope names, so both land in one tree.

use serde::Serialize;
use std::time::Instant;

/// What a line of the report measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SpanKind {
    /// Wall time on the host, around CPU work (or around encoding GPU work).
    Cpu,
    /// Time on the device, from timestamp queries.
    Gpu,
    /// A host↔device copy.
    Copy,
}

impl SpanKind {
    /// What a report writes after a line's name: nothing for host time.
    pub fn tag(self) -> &'static str {
        match self {
            SpanKind::Cpu => "",
            SpanKind::Gpu => " [gpu]",
            SpanKind::Copy => " [copy]",
        }
    }
}

#[derive(Clone, Debug)]
struct Node {
    name: &'static str,
    kind: SpanKind,
    children: Vec<usize>,
    total_ms: f64,
    calls: u64,
}

/// Collects timings over frames. Node 0 is the frame (root).
#[derive(Clone, Debug)]
pub struct Profiler {
    nodes: Vec<Node>,
    /// Open scopes: node index and start instant.
    open: Vec<(usize, Instant)>,
    frame_start: Option<Instant>,
    /// Wall time of each finished frame (ms), for medians.
    frame_ms: Vec<f64>,
}

impl Default for Profiler {
    fn default() -> Self {
        Self::new("step")
    }
}

impl Profiler {
    /// A profiler whose root line is called `root` ("step" for the physics step).
    pub fn new(root: &'static str) -> Self {
        let root = Node {
            name: root,
            kind: SpanKind::Cpu,
            children: Vec::new(),
            total_ms: 0.0,
            calls: 0,
        };
        Self {
            nodes: vec![root],
            open: Vec::new(),
            frame_start: None,
            frame_ms: Vec::new(),
        }
    }

    /// Starts a frame; scopes opened until [`end_frame`](Self::end_frame) belong to it.
    pub fn begin_frame(&mut self) {
        debug_assert!(
            self.open.is_empty(),
            "a scope was left open in the last frame"
        );
        self.open.clear();
        self.frame_start = Some(Instant::now());
    }

    pub fn end_frame(&mut self) {
        if let Some(start) = self.frame_start.take() {
            let ms = start.elapsed().as_secs_f64() * 1e3;
            self.nodes[0].total_ms += ms;
            self.nodes[0].calls += 1;
            self.frame_ms.push(ms);
        }
    }

    /// Opens a CPU scope under the innermost open one.
    pub fn begin(&mut self, name: &'static str) {
        let parent = self.open.last().map_or(0, |&(node, _)| node);
        let node = self.child(parent, name, SpanKind::Cpu);
        self.open.push((node, Instant::now()));
    }

    /// Closes the innermost scope.
    pub fn end(&mut self) {
        if let Some((node, start)) = self.open.pop() {
            self.nodes[node].total_ms += start.elapsed().as_secs_f64() * 1e3;
            self.nodes[node].calls += 1;
        }
    }

    /// Runs `f` inside a scope named `name`.
    pub fn scope<R>(&mut self, name: &'static str, f: impl FnOnce() -> R) -> R {
        self.begin(name);
        let result = f();
        self.end();
        result
    }

    /// Records a finished span of `ms` milliseconds at `path` (scope names from the root's
    /// children down, the last one being the span itself). Used for GPU timestamps and copies,
    /// which are known only after the frame.
    pub fn record(&mut self, path: &[&'static str], kind: SpanKind, ms: f64) {
        let mut node = 0;
        for (depth, name) in path.iter().enumerate() {
            let is_leaf = depth + 1 == path.len();
            node = self.child(node, name, if is_leaf { kind } else { SpanKind::Cpu });
        }
        if node != 0 {
            self.nodes[node].total_ms += ms;
            self.nodes[node].calls += 1;
        }
    }

    /// Forgets all timings (e.g. after warm-up steps).
    pub fn reset(&mut self) {
        for node in &mut self.nodes {
            node.total_ms = 0.0;
            node.calls = 0;
        }
        self.frame_ms.clear();
    }

    /// Number of finished frames since the last reset.
    pub fn frames(&self) -> usize {
        self.frame_ms.len()
    }

    /// Median wall time of a frame (ms), or 0 with no frames.
    pub fn median_frame_ms(&self) -> f64 {
        median(&self.frame_ms)
    }

    /// The tree of average times per frame.
    pub fn report(&self) -> ProfileReport {
        let frames = self.frames().max(1) as f64;
        ProfileReport {
            frames: self.frames(),
            root: self.line(0, frames),
        }
    }

    fn line(&self, node: usize, frames: f64) -> ProfileLine {
        let n = &self.nodes[node];
        ProfileLine {
            name: n.name,
            kind: n.kind,
            ms_per_frame: n.total_ms / frames,
            calls_per_frame: n.calls as f64 / frames,
            children: n.children.iter().map(|&c| self.line(c, frames)).collect(),
        }
    }

    fn child(&mut self, parent: usize, name: &'static str, kind: SpanKind) -> usize {
        if let Some(&found) = self.nodes[parent]
            .children
            .iter()
            .find(|&&c| self.nodes[c].name == name)
        {
            return found;
        }
        let index = self.nodes.len();
        self.nodes.push(Node {
            name,
            kind,
            children: Vec::new(),
            total_ms: 0.0,
            calls: 0,
        });
        self.nodes[parent].children.push(index);
        index
    }
}

/// Median of a list of numbers (0 for an empty list).
pub fn median(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let mid = sorted.len() / 2;
    if sorted.len() % 2 == 1 {
        sorted[mid]
    } else {
        0.5 * (sorted[mid - 1] + sorted[mid])
    }
}

/// Average times per frame, as a tree.
#[derive(Clone, Debug, Serialize)]
pub struct ProfileReport {
    pub frames: usize,
    pub root: ProfileLine,
}

#[derive(Clone, Debug, Serialize)]
pub struct ProfileLine {
    pub name: &'static str,
    pub kind: SpanKind,
    pub ms_per_frame: f64,
    pub calls_per_frame: f64,
    pub children: Vec<ProfileLine>,
}

impl ProfileReport {
    /// Milliseconds per frame of each top-level stage, in step order.
    pub fn stage_ms(&self) -> Vec<(&'static str, f64)> {
        self.root
            .children
            .iter()
            .map(|c| (c.name, c.ms_per_frame))
            .collect()
    }
}

impl std::fmt::Display for ProfileReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "--- Profiling: {} (total running time: {:.3} ms / frame over {} frames) ---",
            self.root.name, self.root.ms_per_frame, self.frames
        )?;
        write_children(f, &self.root, "", 0)
    }
}

fn write_children(
    f: &mut std::fmt::Formatter<'_>,
    parent: &ProfileLine,
    prefix: &str,
    depth: usize,
) -> std::fmt::Result {
    let indent = "   ".repeat(depth);
    let mut accounted = 0.0;
    for (i, line) in parent.children.iter().enumerate() {
        let number = format!("{prefix}{}", i + 1);
        let percent = if parent.ms_per_frame > 0.0 {
            100.0 * line.ms_per_frame / parent.ms_per_frame
        } else {
            0.0
        };
        let tag = line.kind.tag();
        writeln!(
            f,
            "{indent}{number} -- {}{tag} ({percent:.2} %) :: {:.3} ms / frame ({} calls)",
            line.name,
            line.ms_per_frame,
            line.calls_per_frame.round()
        )?;
        // GPU spans overlap host time, so only host-side lines count towards the parent.
        if line.kind != SpanKind::Gpu {
            accounted += line.ms_per_frame;
        }
        write_children(f, line, &format!("{number}."), depth + 1)?;
    }
    if !parent.children.is_empty() && parent.kind == SpanKind::Cpu {
        let unaccounted = (parent.ms_per_frame - accounted).max(0.0);
        let percent = if parent.ms_per_frame > 0.0 {
            100.0 * unaccounted / parent.ms_per_frame
        } else {
            0.0
        };
        writeln!(
            f,
            "{indent}Unaccounted ({percent:.2} %) :: {unaccounted:.3} ms"
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nested_scopes_and_recorded_spans_form_one_tree() {
        let mut profiler = Profiler::new("step");
        for _ in 0..3 {
            profiler.begin_frame();
            profiler.begin("broadphase");
            profiler.scope("query", || std::hint::black_box(1 + 1));
            profiler.end();
            profiler.record(
                &["solver", "copy velocities to device"],
                SpanKind::Copy,
                0.5,
            );
            profiler.end_frame();
        }
        let report = profiler.report();
        assert_eq!(report.frames, 3);
        let names: Vec<_> = report.root.children.iter().map(|c| c.name).collect();
        assert_eq!(names, ["broadphase", "solver"]);
        assert_eq!(report.root.children[0].children[0].name, "query");
        let copy = &report.root.children[1].children[0];
        assert_eq!(
            (copy.kind, copy.ms_per_frame, copy.calls_per_frame),
            (SpanKind::Copy, 0.5, 1.0)
        );
        let text = report.to_string();
        assert!(
            text.contains("1 -- broadphase")
                && text.contains("1.1 -- query")
                && text.contains("[copy]")
        );
    }

    #[test]
    fn median_of_odd_even_and_empty() {
        assert_eq!(median(&[]), 0.0);
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
    }
}
