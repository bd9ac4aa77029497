//! The talk's uniform-grid example, computed by the CPU grid code: six particles A–F in a
//! 4 × 4 grid (one layer deep), their cells, the unsorted and sorted (cell, particle)
//! arrays, the cell-start table and the interacting pairs found by the symmetric search.

use std::fmt;

use crate::particles::cpu::Grid;
use crate::particles::{CellSort, EMPTY_CELL, NeighbourSearch, Particle, ParticleConfig};

/// Names of the example's particles, in input order.
pub const NAMES: [char; 6] = ['A', 'B', 'C', 'D', 'E', 'F'];

/// The tables of the talk's slides "Uniform Grid", "Sorting Particles per Cell" and
/// "Interacting Particle Pairs".
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExampleTables {
    /// For every cell: its id and the particles in it (input order).
    pub cells: Vec<(u32, Vec<char>)>,
    /// (cell id, particle) in input order.
    pub unsorted: Vec<(u32, char)>,
    /// (cell id, particle) sorted by cell.
    pub sorted: Vec<(u32, char)>,
    /// For every cell: the index of its first particle in `sorted`, if any.
    pub cell_start: Vec<(u32, Option<u32>)>,
    /// Pairs of particles in neighbouring cells (candidates for interaction), in the order
    /// the 14-cell symmetric search meets them.
    pub pairs: Vec<(char, char)>,
}

/// The example's configuration: cells of 1 m (radius 0.5 m), 4 × 4 × 1.
pub fn example_config() -> ParticleConfig {
    ParticleConfig {
        count: NAMES.len(),
        radius: 0.5,
        grid: [4, 4, 1],
        search: NeighbourSearch::Symmetric14,
        sort: CellSort::Radix,
        ..ParticleConfig::demo(NAMES.len())
    }
}

/// Positions matching the slide: A in cell 9, B, C, E in cell 6, D, F in cell 4.
pub fn example_particles() -> Vec<Particle> {
    let at = |x: f32, y: f32| Particle {
        position: [x, y, 0.5, 0.0],
        velocity: [0.0; 4],
    };
    vec![
        at(1.5, 2.5),
        at(2.3, 1.6),
        at(2.7, 1.2),
        at(0.4, 1.5),
        at(2.5, 1.8),
        at(0.7, 1.2),
    ]
}

/// Runs hash → sort → cell start → symmetric pair search on the example.
pub fn example_tables() -> ExampleTables {
    let config = example_config();
    let params = config.params();
    let particles = example_particles();
    let mut grid = Grid::default();
    grid.hash(&params, &particles);
    let name = |id: u32| NAMES[id as usize];
    let unsorted = grid
        .pairs
        .iter()
        .map(|&(cell, id)| (cell, name(id)))
        .collect();
    grid.sort();
    grid.find_cell_bounds(&params);
    let sorted: Vec<(u32, char)> = grid
        .pairs
        .iter()
        .map(|&(cell, id)| (cell, name(id)))
        .collect();
    let cells = (0..params.cell_count)
        .map(|cell| {
            // The sort is stable, so a cell lists its particles in input order.
            let inside: Vec<char> = sorted
                .iter()
                .filter(|&&(key, _)| key == cell)
                .map(|&(_, particle)| particle)
                .collect();
            (cell, inside)
        })
        .collect();
    let cell_start = grid
        .cell_start
        .iter()
        .enumerate()
        .map(|(cell, &start)| (cell as u32, (start != EMPTY_CELL).then_some(start)))
        .collect();
    let mut pairs = Vec::new();
    grid.for_each_symmetric_pair(&params, |index, other| {
        pairs.push((sorted[index].1, sorted[other].1));
    });
    ExampleTables {
        cells,
        unsorted,
        sorted,
        cell_start,
        pairs,
    }
}

impl fmt::Display for ExampleTables {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "Uniform grid (4 x 4 cells)")?;
        writeln!(f, "{:<8} {:<6} Particle ID", "Cell ID", "Count")?;
        for (cell, inside) in &self.cells {
            let names: Vec<String> = inside.iter().map(char::to_string).collect();
            writeln!(f, "{cell:<8} {:<6} {}", inside.len(), names.join(","))?;
        }
        writeln!(f)?;
        writeln!(
            f,
            "{:<12} {:<22} Sorted (cell ID, particle ID)",
            "Array index", "Unsorted (cell ID, particle ID)"
        )?;
        for (index, (unsorted, sorted)) in self.unsorted.iter().zip(&self.sorted).enumerate() {
            let unsorted = format!("{}, {}", unsorted.0, unsorted.1);
            writeln!(f, "{index:<12} {unsorted:<31} {}, {}", sorted.0, sorted.1)?;
        }
        writeln!(f)?;
        writeln!(f, "{:<11} Cell start", "Cell index")?;
        for (cell, start) in &self.cell_start {
            let start = start.map(|start| start.to_string()).unwrap_or_default();
            writeln!(f, "{cell:<11} {start}")?;
        }
        writeln!(f)?;
        writeln!(f, "Interacting particle pairs")?;
        for (a, b) in &self.pairs {
            writeln!(f, "{a},{b}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tables on the talk's slides.
    #[test]
    fn tables_match_the_slides() {
        let tables = example_tables();
        let occupied: Vec<(u32, Vec<char>)> = tables
            .cells
            .iter()
            .filter(|(_, inside)| !inside.is_empty())
            .cloned()
            .collect();
        assert_eq!(
            occupied,
            [
                (4, vec!['D', 'F']),
                (6, vec!['B', 'C', 'E']),
                (9, vec!['A'])
            ]
        );
        assert_eq!(tables.cells.len(), 16);
        assert_eq!(
            tables.unsorted,
            [(9, 'A'), (6, 'B'), (6, 'C'), (4, 'D'), (6, 'E'), (4, 'F')]
        );
        assert_eq!(
            tables.sorted,
            [(4, 'D'), (4, 'F'), (6, 'B'), (6, 'C'), (6, 'E'), (9, 'A')]
        );
        let starts: Vec<(u32, u32)> = tables
            .cell_start
            .iter()
            .filter_map(|&(cell, start)| start.map(|start| (cell, start)))
            .collect();
        assert_eq!(starts, [(4, 0), (6, 2), (9, 5)]);
        let pairs: Vec<String> = tables
            .pairs
            .iter()
            .map(|(a, b)| format!("{a},{b}"))
            .collect();
        assert_eq!(
            pairs,
            [
                "D,F", "B,C", "B,E", "C,E", "A,D", "A,F", "A,B", "A,C", "A,E"
            ]
        );
        let text = tables.to_string();
        assert!(text.contains("Interacting particle pairs") && text.contains("9, A"));
    }
}
