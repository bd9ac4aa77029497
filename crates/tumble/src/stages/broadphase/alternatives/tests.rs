//! Every finder against brute force on moving scenes, frame after frame.
//!
//! The DBVT of the step keeps fat AABBs and so reports pairs of boxes that do not overlap; for
//! the exact comparison it runs with no margin and no look-ahead ([`DbvtFinder::exact`]), and
//! the fat one is checked to find a superset. Comparing the fat DBVT's pairs filtered by tight
//! overlap would work too, but would not catch a bug that reports a wrong extra pair.

use super::scene::{MovingBoxes, MovingBoxesError};
use super::*;
use crate::math::Vec3;

fn finders() -> Vec<Box<dyn PairFinder>> {
    vec![
        Box::new(DbvtFinder::exact()),
        Box::new(UniformGrid::new(None)),
        // Cells smaller than the boxes: many boxes over the cell limit, the oversized path.
        Box::new(UniformGrid::new(Some(0.2))),
        Box::new(SweepAndPrune::new()),
    ]
}

#[test]
fn all_finders_find_the_brute_force_pairs_frame_after_frame() {
    for (count, moving, seed) in [
        (0, 0.5, 1),
        (1, 1.0, 2),
        (2, 1.0, 3),
        (300, 0.1, 4),
        (1000, 0.3, 5),
    ] {
        let mut scene = MovingBoxes::new(count, moving, seed).unwrap();
        let mut finders = finders();
        let mut fat = DbvtFinder::fat();
        let (mut aabbs, mut expected, mut found) = (Vec::new(), Vec::new(), Vec::new());
        let mut total = 0;
        for frame in 0..20 {
            scene.aabbs(&mut aabbs);
            BruteForce.update(&aabbs, &mut expected).unwrap();
            total += expected.len();
            for finder in &mut finders {
                finder.update(&aabbs, &mut found).unwrap();
                assert_eq!(found, expected, "{} at frame {frame}", finder.name());
            }
            fat.update(&aabbs, &mut found).unwrap();
            assert!(found.windows(2).all(|w| w[0] < w[1]));
            let mut missing = expected.clone();
            missing.retain(|key| found.binary_search(key).is_err());
            assert!(missing.is_empty(), "the fat DBVT missed {missing:?}");
            scene.advance();
        }
        if count >= 300 {
            assert!(
                total > count,
                "{total} pairs over 20 frames: too sparse to test"
            );
        }
    }
}

#[test]
fn body_count_changes_and_teleports() {
    let mut finders = finders();
    let (mut expected, mut found) = (Vec::new(), Vec::new());
    let scene = MovingBoxes::new(500, 0.2, 9).unwrap();
    let mut aabbs = Vec::new();
    scene.aabbs(&mut aabbs);
    for frame in 0..6 {
        match frame {
            1 => aabbs.truncate(200),
            2 => aabbs.extend_from_within(..150),
            // A big box over everything, and a box jumping across the scene.
            3 => aabbs.push(Aabb::new(Vec3::splat(-1.0), Vec3::splat(1e3))),
            4 => aabbs.swap(0, 300),
            _ => {}
        }
        BruteForce.update(&aabbs, &mut expected).unwrap();
        for finder in &mut finders {
            finder.update(&aabbs, &mut found).unwrap();
            assert_eq!(found, expected, "{} at frame {frame}", finder.name());
        }
    }
}

#[test]
fn bad_input_is_an_error() {
    let good = Aabb::new(Vec3::ZERO, Vec3::ONE);
    let nan = Aabb::new(Vec3::splat(f32::NAN), Vec3::ONE);
    let inverted = Aabb::new(Vec3::ONE, Vec3::ZERO);
    let mut pairs = Vec::new();
    let mut all = finders();
    all.push(Box::new(DbvtFinder::fat()));
    all.push(Box::new(BruteForce));
    for finder in &mut all {
        // NaN != NaN: match the variant and the body.
        assert!(matches!(
            finder.update(&[good, nan], &mut pairs),
            Err(AabbError::NotFinite { body: 1, .. })
        ));
        assert_eq!(
            finder.update(&[inverted], &mut pairs),
            Err(AabbError::Inverted {
                body: 0,
                aabb: inverted
            })
        );
    }
    assert_eq!(
        MovingBoxes::new(10, 1.5, 0).unwrap_err(),
        MovingBoxesError::BadFraction(1.5)
    );
}
