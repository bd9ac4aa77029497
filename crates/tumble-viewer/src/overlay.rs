//! On-screen text: the profile overlay (`p`: stage times, pair and contact counts, the batch
//! histogram, as on the talk's profile slides) and the help overlay (`h`: the keys).
//!
//! The lines are pure functions of what they show, so they are unit-tested; [`layout`] turns
//! lines into screen quads in pixels (a dark panel, then one quad per character) that the
//! renderer draws over the frame with the [`font`](crate::font).

use bytemuck::{Pod, Zeroable};
use tumble::StepStats;
use tumble::profile::{ProfileLine, ProfileReport};

use crate::font::{CELL_HEIGHT, CELL_WIDTH, glyph_index};
use crate::input::HELP;

/// Which overlay is drawn over the scene.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum OverlayKind {
    #[default]
    Off,
    /// Stage times, counts and the batch histogram.
    Profile,
    /// The key list.
    Help,
}

/// Stage lines go this deep below the step (stages, then their copies and kernels).
const PROFILE_DEPTH: usize = 2;
/// The batch histogram wraps after this many characters.
const HISTOGRAM_WIDTH: usize = 64;

/// The help overlay: the key list `h` shows.
pub fn help_lines() -> Vec<String> {
    lines_of(HELP)
}

/// The lines of a help text.
pub fn lines_of(help: &str) -> Vec<String> {
    help.lines().map(str::to_owned).collect()
}

/// The profile overlay: the step's time per frame, each stage's (and, indented, its copies and
/// kernels') time and share of the step, the counts, and the batch histogram as the talk
/// prints it ("0: 4931, 1: 4836, ..."), wrapped.
pub fn profile_lines(report: &ProfileReport, bodies: usize, stats: &StepStats) -> Vec<String> {
    let mut lines = stage_report_lines(report);
    lines.push(format!(
        "bodies {bodies}  pairs {}  manifolds {}  contacts {}",
        stats.pairs, stats.manifolds, stats.contacts
    ));
    if stats.joints > 0 || stats.sleeping > 0 {
        lines.push(format!(
            "joints {}  sleeping {}",
            stats.joints, stats.sleeping
        ));
    }
    lines.push(format!("batches: {}", stats.batch_histogram.len()));
    let mut line = String::new();
    for (batch, count) in stats.batch_histogram.iter().enumerate() {
        let entry = format!("{batch}: {count}");
        if !line.is_empty() && line.len() + 2 + entry.len() > HISTOGRAM_WIDTH {
            lines.push(format!("  {line},"));
            line.clear();
        }
        if !line.is_empty() {
            line.push_str(", ");
        }
        line.push_str(&entry);
    }
    if !line.is_empty() {
        lines.push(format!("  {line}"));
    }
    lines
}

/// The step's time per frame, then each stage's (and, indented, its copies' and kernels')
/// time and share of the step.
pub fn stage_report_lines(report: &ProfileReport) -> Vec<String> {
    let mut lines = vec![format!(
        "{}: {:.3} ms / frame over {} frames",
        report.root.name, report.root.ms_per_frame, report.frames
    )];
    stage_lines(&report.root, report.root.ms_per_frame, 1, &mut lines);
    lines
}

fn stage_lines(parent: &ProfileLine, step_ms: f64, depth: usize, lines: &mut Vec<String>) {
    for line in &parent.children {
        let percent = if step_ms > 0.0 {
            100.0 * line.ms_per_frame / step_ms
        } else {
            0.0
        };
        let tag = line.kind.tag();
        let name = format!("{}{}{tag}", "  ".repeat(depth), line.name);
        lines.push(format!(
            "{name:<30} {:>8.3} ms {percent:>5.1} %",
            line.ms_per_frame
        ));
        if depth < PROFILE_DEPTH {
            stage_lines(line, step_ms, depth + 1, lines);
        }
    }
}

/// A quad of the overlay, in pixels from the top-left corner of the picture.
// repr(C) + Pod: uploaded as is into the instance buffer text.wgsl reads.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TextQuad {
    /// Top-left corner and size (pixels).
    pub position: [f32; 2],
    pub size: [f32; 2],
    /// Linear RGB and opacity.
    pub colour: [f32; 4],
    /// The glyph's slot in the font atlas, or [`PANEL`] for a filled rectangle.
    pub glyph: u32,
    pub _pad: [u32; 3],
}

const _: () = assert!(size_of::<TextQuad>() == 48);

/// `TextQuad::glyph` of a filled rectangle (the panel behind the text).
pub const PANEL: u32 = u32::MAX;
/// Text colour (linear RGB): near white, so it reads on the dark panel.
pub const TEXT_COLOUR: [f32; 3] = [1.0, 1.0, 0.85];
/// The panel: dark and mostly opaque, so text stays legible over any scene.
const PANEL_COLOUR: [f32; 4] = [0.0, 0.0, 0.0, 0.7];
/// Space between the picture's edge and the panel, and the panel's edge and the text, in font
/// pixels.
const MARGIN: u32 = 4;

/// Screen pixels per font pixel for a picture `height` pixels tall: 1 below 720 rows, 2 from
/// 720 (a 720p window), 3 from 1440, so the text keeps a similar share of the screen.
pub fn text_scale(height: u32) -> u32 {
    match height {
        0..720 => 1,
        720..1440 => 2,
        _ => 3,
    }
}

/// The panel and characters of `lines`, top-left in a picture `height` pixels tall. Spaces get
/// no quad. Empty when there are no lines.
pub fn layout(lines: &[String], height: u32) -> Vec<TextQuad> {
    if lines.is_empty() {
        return Vec::new();
    }
    let scale = text_scale(height) as f32;
    let (cell_w, cell_h) = (CELL_WIDTH as f32 * scale, CELL_HEIGHT as f32 * scale);
    let margin = MARGIN as f32 * scale;
    let columns = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0);
    let mut quads = vec![TextQuad {
        position: [margin, margin],
        size: [
            columns as f32 * cell_w + 2.0 * margin,
            lines.len() as f32 * cell_h + 2.0 * margin,
        ],
        colour: PANEL_COLOUR,
        glyph: PANEL,
        _pad: [0; 3],
    }];
    let [r, g, b] = TEXT_COLOUR;
    for (row, line) in lines.iter().enumerate() {
        for (column, c) in line.chars().enumerate() {
            if c == ' ' {
                continue;
            }
            quads.push(TextQuad {
                position: [
                    2.0 * margin + column as f32 * cell_w,
                    2.0 * margin + row as f32 * cell_h,
                ],
                size: [cell_w, cell_h],
                colour: [r, g, b, 1.0],
                glyph: glyph_index(c),
                _pad: [0; 3],
            });
        }
    }
    quads
}

/// The pixels `layout(lines, height)` covers: (left, top, right, bottom), right and bottom
/// excluded; all zero with no lines.
pub fn panel_rect(lines: &[String], height: u32) -> (u32, u32, u32, u32) {
    match layout(lines, height).first() {
        Some(panel) => (
            panel.position[0] as u32,
            panel.position[1] as u32,
            (panel.position[0] + panel.size[0]) as u32,
            (panel.position[1] + panel.size[1]) as u32,
        ),
        None => (0, 0, 0, 0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tumble::profile::SpanKind;

    fn line(
        name: &'static str,
        kind: SpanKind,
        ms: f64,
        children: Vec<ProfileLine>,
    ) -> ProfileLine {
        ProfileLine {
            name,
            kind,
            ms_per_frame: ms,
            calls_per_frame: 1.0,
            children,
        }
    }

    fn report() -> ProfileReport {
        let solver_children = vec![
            line("copy to gpu", SpanKind::Copy, 0.5, vec![]),
            line(
                "kernels",
                SpanKind::Gpu,
                1.0,
                vec![line("too deep", SpanKind::Gpu, 0.1, vec![])],
            ),
        ];
        ProfileReport {
            frames: 60,
            root: line(
                "step",
                SpanKind::Cpu,
                4.0,
                vec![
                    line("broadphase", SpanKind::Cpu, 1.0, vec![]),
                    line("solver", SpanKind::Cpu, 2.0, solver_children),
                ],
            ),
        }
    }

    #[test]
    fn profile_lists_stages_counts_and_the_batch_histogram() {
        let stats = StepStats {
            pairs: 12,
            manifolds: 9,
            contacts: 30,
            batch_histogram: vec![4931, 4836, 7],
            ..Default::default()
        };
        let lines = profile_lines(&report(), 100, &stats);
        assert_eq!(
            lines,
            [
                "step: 4.000 ms / frame over 60 frames",
                "  broadphase                      1.000 ms  25.0 %",
                "  solver                          2.000 ms  50.0 %",
                "    copy to gpu [copy]            0.500 ms  12.5 %",
                "    kernels [gpu]                 1.000 ms  25.0 %",
                "bodies 100  pairs 12  manifolds 9  contacts 30",
                "batches: 3",
                "  0: 4931, 1: 4836, 2: 7",
            ]
        );
    }

    #[test]
    fn a_long_histogram_wraps_and_sleepers_and_joints_show() {
        let stats = StepStats {
            joints: 3,
            batch_histogram: vec![1000; 30],
            ..Default::default()
        };
        let lines = profile_lines(&report(), 0, &stats);
        assert!(lines.contains(&"joints 3  sleeping 0".to_owned()));
        let histogram: Vec<&String> = lines
            .iter()
            .skip_while(|l| !l.starts_with("batches"))
            .collect();
        assert_eq!(histogram[0], "batches: 30");
        assert!(histogram.len() > 3, "{histogram:?}");
        for row in &histogram[1..] {
            assert!(row.len() <= HISTOGRAM_WIDTH + 3, "{row:?}");
        }
        // Every batch is listed once, in order.
        let entries: Vec<String> = histogram[1..]
            .iter()
            .flat_map(|row| row.split(','))
            .map(|entry| entry.trim().to_owned())
            .filter(|entry| !entry.is_empty())
            .collect();
        let expected: Vec<String> = (0..30).map(|batch| format!("{batch}: 1000")).collect();
        assert_eq!(entries, expected);
    }

    #[test]
    fn help_lists_every_key() {
        let lines = help_lines();
        for key in [
            "space", "i ", "s ", "p ", "c ", "b ", "u ", "d ", "w ", "h ", "q,", "z / x",
        ] {
            assert!(
                lines
                    .iter()
                    .any(|l| l.trim_start().starts_with(key) || l.contains(key)),
                "{key:?} missing from {lines:?}"
            );
        }
    }

    #[test]
    fn layout_puts_a_panel_behind_one_quad_per_visible_character() {
        let lines = vec!["ab c".to_owned(), "d".to_owned()];
        let quads = layout(&lines, 480);
        // The panel, then a, b, c, d (no quad for the space).
        assert_eq!(quads.len(), 5);
        assert_eq!(quads[0].glyph, PANEL);
        let margin = MARGIN as f32;
        assert_eq!(quads[0].position, [margin, margin]);
        assert_eq!(
            quads[0].size,
            [
                4.0 * CELL_WIDTH as f32 + 2.0 * margin,
                2.0 * CELL_HEIGHT as f32 + 2.0 * margin
            ]
        );
        assert_eq!(quads[1].glyph, glyph_index('a'));
        assert_eq!(quads[3].glyph, glyph_index('c'));
        assert_eq!(quads[3].position[0], 2.0 * margin + 3.0 * CELL_WIDTH as f32);
        assert_eq!(quads[4].position[1], 2.0 * margin + CELL_HEIGHT as f32);
        // Every character lies inside the panel.
        let (left, top, right, bottom) = panel_rect(&lines, 480);
        for quad in &quads[1..] {
            assert!(quad.position[0] >= left as f32 && quad.position[1] >= top as f32);
            assert!(quad.position[0] + quad.size[0] <= right as f32);
            assert!(quad.position[1] + quad.size[1] <= bottom as f32);
        }
        assert!(layout(&[], 480).is_empty());
    }

    #[test]
    fn text_grows_with_the_picture() {
        assert_eq!(text_scale(96), 1);
        assert_eq!(text_scale(719), 1);
        assert_eq!(text_scale(720), 2);
        assert_eq!(text_scale(1080), 2);
        assert_eq!(text_scale(1440), 3);
        assert_eq!(text_scale(2160), 3);
    }
}
