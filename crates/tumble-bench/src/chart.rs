//! The PNG chart: median ms/step against dynamic bodies, log-log, one line per scene, engine
//! and thread count, with a p10–p90 bar at each point. Text is drawn from a font compiled into
//! the binary (DejaVu Sans Mono, assets/), so the chart needs no system fonts.

use crate::BenchError;
use crate::measure::CaseResult;
use plotters::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

const FONT: &[u8] = include_bytes!("../assets/DejaVuSansMono.ttf");
/// The family plotters asks for by default (axis labels); the chart uses it everywhere.
const FAMILY: &str = "sans-serif";
/// Pixels of one scene's panel; panels stack vertically.
const PANEL_SIZE: (u32, u32) = (1280, 720);
/// Distinct on white, then repeated.
const COLORS: &[RGBColor] = &[
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// A timed case on the chart.
struct Point {
    bodies: f64,
    median: f64,
    p10: f64,
    p90: f64,
}

/// Draws the chart of `results` (cases with timed steps) into a PNG file at `path`: one panel
/// per scene, one line per engine and thread count.
pub fn draw(path: &Path, results: &[CaseResult]) -> Result<(), BenchError> {
    let error = |message: String| BenchError::Write {
        path: path.display().to_string(),
        message,
    };
    plotters::style::register_font(FAMILY, FontStyle::Normal, FONT)
        .map_err(|_| error("the chart's built-in font did not load".into()))?;
    draw_chart(path, results).map_err(error)
}

/// Lines of one scene's panel, keyed (and so ordered) by engine name and thread count.
type Panel = BTreeMap<(&'static str, usize), Vec<Point>>;

fn draw_chart(path: &Path, results: &[CaseResult]) -> Result<(), String> {
    let mut panels: BTreeMap<&str, Panel> = BTreeMap::new();
    for result in results {
        let spread = result.figures.as_ref().and_then(|f| f.step_ms);
        if let Some(spread) = spread.filter(|s| s.median > 0.0 && result.key.bodies > 0) {
            let key = &result.key;
            panels
                .entry(key.scene.as_str())
                .or_default()
                .entry((key.engine.name(), key.threads))
                .or_default()
                .push(Point {
                    bodies: key.bodies as f64,
                    median: spread.median,
                    // A log axis cannot show 0: clamp the spread to the median's decade.
                    p10: spread.p10.max(spread.median * 0.1),
                    p90: spread.p90,
                });
        }
    }
    if panels.is_empty() {
        panels.insert("no timed cases", Panel::new());
    }
    let (width, height) = (PANEL_SIZE.0, PANEL_SIZE.1 * panels.len() as u32);
    // 8-bit RGB, row after row: the layout plotters draws into and PNG stores.
    let mut pixels = vec![0u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let areas = root.split_evenly((panels.len(), 1));
        for (area, (scene, lines)) in areas.iter().zip(&panels) {
            draw_panel(area, scene, lines)?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    write_png(path, (width, height), &pixels).map_err(|e| e.to_string())
}

fn write_png(
    path: &Path,
    (width, height): (u32, u32),
    pixels: &[u8],
) -> Result<(), png::EncodingError> {
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut encoder = png::Encoder::new(file, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(pixels)?;
    writer.finish()
}

fn draw_panel(
    area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    scene: &str,
    lines: &Panel,
) -> Result<(), String> {
    let text = |e: &dyn std::fmt::Display| e.to_string();
    let points = || lines.values().flatten();
    let x_min = points().map(|p| p.bodies).fold(f64::INFINITY, f64::min);
    let x_max = points().map(|p| p.bodies).fold(0.0, f64::max);
    let y_min = points().map(|p| p.p10).fold(f64::INFINITY, f64::min);
    let y_max = points().map(|p| p.p90).fold(0.0, f64::max);
    // With nothing timed the axes still show a sensible empty range.
    let (x_range, y_range) = if x_min.is_finite() && y_min.is_finite() {
        (x_min / 1.5..x_max * 1.5, y_min / 1.5..y_max * 1.5)
    } else {
        (100.0..1e6, 0.01..1000.0)
    };
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!("{scene}: ms per step against dynamic bodies"),
            (FAMILY, 26),
        )
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(x_range.log_scale(), y_range.log_scale())
        .map_err(|e| text(&e))?;
    chart
        .configure_mesh()
        .x_desc("dynamic bodies")
        .y_desc("ms / step (median, bar: p10 to p90)")
        .x_label_formatter(&|&x| round_label(x))
        .y_label_formatter(&|&y| round_label(y))
        .label_style((FAMILY, 16))
        .axis_desc_style((FAMILY, 18))
        .draw()
        .map_err(|e| text(&e))?;
    for (index, ((engine, threads), points)) in lines.iter().enumerate() {
        let color = COLORS[index % COLORS.len()];
        chart
            .draw_series(LineSeries::new(
                points.iter().map(|p| (p.bodies, p.median)),
                color.stroke_width(2),
            ))
            .map_err(|e| text(&e))?
            .label(format!("{engine} {threads}t"))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(2))
            });
        chart
            .draw_series(
                points
                    .iter()
                    .map(|p| Circle::new((p.bodies, p.median), 4, color.filled())),
            )
            .map_err(|e| text(&e))?;
        chart
            .draw_series(
                points
                    .iter()
                    .map(|p| PathElement::new(vec![(p.bodies, p.p10), (p.bodies, p.p90)], color)),
            )
            .map_err(|e| text(&e))?;
    }
    if !lines.is_empty() {
        chart
            .configure_series_labels()
            .label_font((FAMILY, 16))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(|e| text(&e))?;
    }
    Ok(())
}

/// Labels a log axis at 1, 2 and 5 times a power of ten only (`2k`, `0.5`, `1M`); the other
/// grid lines stay unlabelled so the labels do not run into each other.
fn round_label(value: f64) -> String {
    let decade = 10f64.powf(value.log10().floor());
    let mantissa = value / decade;
    if ![1.0, 2.0, 5.0].iter().any(|m| (mantissa - m).abs() < 1e-3) {
        return String::new();
    }
    let rounded = mantissa.round() * decade;
    match rounded {
        v if v >= 1e6 => format!("{}M", v / 1e6),
        v if v >= 1e3 => format!("{}k", v / 1e3),
        v if v >= 1.0 => format!("{v}"),
        // Below 1, print as many decimals as the decade needs.
        v => format!("{v:.*}", (-v.log10().floor()) as usize),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_axis_labels_are_round() {
        let labels: Vec<String> = [1000.0, 2000.0, 3000.0, 5e5, 1e6, 0.05, 0.2, 1.0, 10.0]
            .into_iter()
            .map(round_label)
            .collect();
        assert_eq!(
            labels,
            ["1k", "2k", "", "500k", "1M", "0.05", "0.2", "1", "10"]
        );
    }

    #[test]
    fn draws_a_png_with_the_built_in_font() {
        use crate::engine::EngineKind;
        use crate::measure::{CaseKey, Drift, DriftKind, Figures, Spread, Status};
        let result = |bodies: usize, engine: EngineKind, ms: f64| CaseResult {
            key: CaseKey {
                scene: "falling-boxes".into(),
                scale: 1.0,
                bodies,
                engine,
                threads: 1,
            },
            status: Status::Ok,
            figures: Some(Figures {
                warmup_steps: 1,
                timed_steps: 3,
                step_ms: Spread::of(&[ms * 0.9, ms, ms * 1.2]),
                stage_ms: Vec::new(),
                max_penetration: 0.0,
                drift: Drift {
                    kind: DriftKind::Speed,
                    mean: 0.0,
                    max: 0.0,
                },
                kinetic_energy: 0.0,
                pairs: 0,
                contacts: 0,
            }),
            dt: 1.0 / 60.0,
            solver_iterations: 10,
            substeps: 1,
            solver: None,
        };
        let results = [
            result(1000, EngineKind::TumbleCpu, 0.4),
            result(3000, EngineKind::TumbleCpu, 1.3),
            result(1000, EngineKind::Rapier, 0.5),
        ];
        let directory = std::env::temp_dir().join(format!("tumble-bench-{}", std::process::id()));
        std::fs::create_dir_all(&directory).unwrap();
        for (name, results) in [("chart.png", &results[..]), ("empty.png", &[][..])] {
            let path = directory.join(name);
            draw(&path, results).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{name} is a PNG");
        }
        std::fs::remove_dir_all(&directory).unwrap();
    }
}
