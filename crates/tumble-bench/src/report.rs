//! The table on stdout and the CSV file. Columns are documented in the crate docs and in
//! BENCHMARKS.md; a test keeps the three lists the same.

use crate::BenchError;
use crate::measure::CaseResult;
use std::path::Path;

/// CSV header, in order.
pub const CSV_COLUMNS: &[&str] = &[
    "scene",
    "scale",
    "bodies",
    "engine",
    "threads",
    "status",
    "warmup_steps",
    "timed_steps",
    "ms_median",
    "ms_p10",
    "ms_p90",
    "ms_min",
    "ms_max",
    "stage_ms",
    "max_penetration_m",
    "drift_kind",
    "drift_mean",
    "drift_max",
    "kinetic_energy_j",
    "pairs",
    "contacts",
    "dt",
    "solver_iterations",
    "substeps",
    "solver",
];

/// The cells of a result's row, in [`CSV_COLUMNS`] order (empty where there is no figure).
pub fn csv_row(result: &CaseResult) -> Vec<String> {
    let key = &result.key;
    let figures = result.figures.as_ref();
    let spread = figures.and_then(|f| f.step_ms);
    let number = |value: Option<f64>| value.map_or(String::new(), |v| format!("{v:.6}"));
    let count = |value: Option<usize>| value.map_or(String::new(), |v| v.to_string());
    vec![
        key.scene.clone(),
        key.scale.to_string(),
        key.bodies.to_string(),
        key.engine.name().to_string(),
        key.threads.to_string(),
        result.status.to_string(),
        count(figures.map(|f| f.warmup_steps)),
        count(figures.map(|f| f.timed_steps)),
        number(spread.map(|s| s.median)),
        number(spread.map(|s| s.p10)),
        number(spread.map(|s| s.p90)),
        number(spread.map(|s| s.min)),
        number(spread.map(|s| s.max)),
        figures.map_or(String::new(), |f| {
            f.stage_ms
                .iter()
                .map(|(name, ms)| format!("{name}={ms:.6}"))
                .collect::<Vec<_>>()
                .join(";")
        }),
        number(figures.map(|f| f.max_penetration as f64)),
        figures.map_or(String::new(), |f| f.drift.kind.name().to_string()),
        number(figures.map(|f| f.drift.mean)),
        number(figures.map(|f| f.drift.max)),
        number(figures.map(|f| f.kinetic_energy)),
        count(figures.map(|f| f.pairs)),
        count(figures.map(|f| f.contacts)),
        result.dt.to_string(),
        result.solver_iterations.to_string(),
        result.substeps.to_string(),
        result.solver.map_or(String::new(), |s| s.to_string()),
    ]
}

/// The whole CSV document: header, then one row per result.
pub fn csv(results: &[CaseResult]) -> String {
    let mut text = CSV_COLUMNS.join(",");
    text.push('\n');
    for result in results {
        let cells: Vec<String> = csv_row(result).iter().map(|c| csv_cell(c)).collect();
        text.push_str(&cells.join(","));
        text.push('\n');
    }
    text
}

/// Writes (replaces) the CSV file with all results so far.
pub fn write_csv(path: &Path, results: &[CaseResult]) -> Result<(), BenchError> {
    std::fs::write(path, csv(results)).map_err(|e| BenchError::Write {
        path: path.display().to_string(),
        message: e.to_string(),
    })
}

/// RFC 4180 quoting: only cells with a comma, quote or line break (scene file paths, reasons).
fn csv_cell(cell: &str) -> String {
    if cell.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", cell.replace('"', "\"\""))
    } else {
        cell.to_string()
    }
}

/// The table's header line.
pub fn table_header() -> String {
    format!(
        "{:<16} {:>9} {:>8} {:<15} {:>3} {:>9} {:>9} {:>9} {:>9} {:>10} {:>10} {:>12} {:>8} {:>8}  status",
        "scene",
        "scale",
        "bodies",
        "engine",
        "thr",
        "ms/step",
        "p10",
        "p90",
        "max pen m",
        "drift mean",
        "drift max",
        "kinetic J",
        "pairs",
        "contacts",
    )
}

/// A result as a table line, then a line with its stage breakdown when it ran.
pub fn table_row(result: &CaseResult) -> String {
    let key = &result.key;
    let figures = result.figures.as_ref();
    let spread = figures.and_then(|f| f.step_ms);
    let ms = |value: Option<f64>| value.map_or("-".to_string(), |v| format!("{v:.3}"));
    let small = |value: Option<f64>| value.map_or("-".to_string(), |v| format!("{v:.4}"));
    let count = |value: Option<usize>| value.map_or("-".to_string(), |v| v.to_string());
    let drift_note = figures.map_or("", |f| match f.drift.kind {
        crate::measure::DriftKind::Displacement => " (drift: displacement, m)",
        crate::measure::DriftKind::Speed => " (drift: speed, m/s)",
    });
    let mut line = format!(
        "{:<16} {:>9.4} {:>8} {:<15} {:>3} {:>9} {:>9} {:>9} {:>9} {:>10} {:>10} {:>12} {:>8} {:>8}  {}{}",
        key.scene,
        key.scale,
        key.bodies,
        key.engine.name(),
        key.threads,
        ms(spread.map(|s| s.median)),
        ms(spread.map(|s| s.p10)),
        ms(spread.map(|s| s.p90)),
        small(figures.map(|f| f.max_penetration as f64)),
        small(figures.map(|f| f.drift.mean)),
        small(figures.map(|f| f.drift.max)),
        figures.map_or("-".to_string(), |f| format!("{:.3}", f.kinetic_energy)),
        count(figures.map(|f| f.pairs)),
        count(figures.map(|f| f.contacts)),
        result.status,
        drift_note,
    );
    if let Some(figures) = figures.filter(|f| !f.stage_ms.is_empty()) {
        let stages: Vec<String> = figures
            .stage_ms
            .iter()
            .map(|(name, ms)| format!("{name} {ms:.3}"))
            .collect();
        line.push_str(&format!("\n    stages (ms/step): {}", stages.join(" | ")));
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::EngineKind;
    use crate::measure::{CaseKey, Drift, DriftKind, Figures, Spread, Status};

    fn result(status: Status, figures: Option<Figures>) -> CaseResult {
        CaseResult {
            key: CaseKey {
                scene: "dir, with comma/scene.json".into(),
                scale: 0.5,
                bodies: 10,
                engine: EngineKind::Rapier,
                threads: 2,
            },
            status,
            figures,
            dt: 1.0 / 60.0,
            solver_iterations: 10,
            substeps: 1,
            solver: None,
        }
    }

    fn figures() -> Figures {
        Figures {
            warmup_steps: 3,
            timed_steps: 5,
            step_ms: Spread::of(&[1.0, 2.0, 3.0, 4.0, 5.0]),
            stage_ms: vec![("broadphase".into(), 0.25), ("solver".into(), 0.75)],
            max_penetration: 0.004,
            drift: Drift {
                kind: DriftKind::Speed,
                mean: 0.1,
                max: 0.2,
            },
            kinetic_energy: 12.5,
            pairs: 40,
            contacts: 80,
        }
    }

    /// Splits one CSV line into cells, honouring quotes.
    fn cells(line: &str) -> Vec<String> {
        let mut cells = vec![String::new()];
        let mut quoted = false;
        let mut chars = line.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
                '"' if quoted && chars.peek() == Some(&'"') => {
                    chars.next();
                    cells.last_mut().unwrap().push('"');
                }
                '"' => quoted = !quoted,
                ',' if !quoted => cells.push(String::new()),
                _ => cells.last_mut().unwrap().push(c),
            }
        }
        cells
    }

    #[test]
    fn csv_has_the_documented_columns() {
        let text = csv(&[
            result(Status::Ok, Some(figures())),
            result(Status::Skipped, None),
            result(Status::NotAvailable("no GPU, \"yet\"".into()), None),
        ]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0].split(',').collect::<Vec<_>>(), CSV_COLUMNS);
        for line in &lines[1..] {
            assert_eq!(cells(line).len(), CSV_COLUMNS.len(), "{line}");
        }
        let row = cells(lines[1]);
        let column = |name: &str| {
            let index = CSV_COLUMNS.iter().position(|c| *c == name).unwrap();
            row[index].as_str()
        };
        assert_eq!(column("scene"), "dir, with comma/scene.json");
        assert_eq!(column("engine"), "rapier");
        assert_eq!(column("ms_median"), "3.000000");
        assert_eq!(column("stage_ms"), "broadphase=0.250000;solver=0.750000");
        assert_eq!(column("drift_kind"), "speed_m_per_s");
        assert_eq!(cells(lines[3])[5], "not available: no GPU, \"yet\"");
        assert_eq!(cells(lines[2])[8], "", "a skipped case has no time");

        // The crate docs and BENCHMARKS.md document every column, in this order.
        for (document, text) in [
            ("lib.rs", include_str!("lib.rs")),
            ("BENCHMARKS.md", include_str!("../../../BENCHMARKS.md")),
        ] {
            let mut from = 0;
            for name in CSV_COLUMNS {
                let found = text[from..]
                    .find(&format!("`{name}`"))
                    .unwrap_or_else(|| panic!("{document} does not document `{name}` in order"));
                from += found;
            }
        }
    }

    #[test]
    fn table_rows_show_status_and_stages() {
        let row = table_row(&result(Status::Ok, Some(figures())));
        assert!(
            row.contains("3.000") && row.contains("ok (drift: speed, m/s)"),
            "{row}"
        );
        assert!(row.contains("stages (ms/step): broadphase 0.250 | solver 0.750"));
        let skipped = table_row(&result(Status::Skipped, None));
        assert!(skipped.ends_with("skipped") && !skipped.contains("stages"));
    }
}
