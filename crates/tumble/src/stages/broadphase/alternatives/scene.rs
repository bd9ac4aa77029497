//! The benchmark's scene, after Bullet's CDTestFramework: boxes scattered in a cube, a fixed
//! fraction of them moving on smooth closed paths, the rest still. Seeded, so every finder and
//! every run sees the same frames.

use crate::math::{Aabb, Vec3};

/// Boxes of half-size 0.25..0.75 m (m); the cube is sized for about this many boxes per m³,
/// which gives about one overlap per box, as a settled pile or a crowd does.
const BOXES_PER_CUBIC_METRE: f32 = 0.15;

/// Moving boxes travel about this far per frame (m): a fifth of a typical box.
const SPEED_PER_FRAME: f32 = 0.1;

#[derive(Clone, Debug)]
pub struct MovingBoxes {
    centers: Vec<Vec3>,
    half_extents: Vec<Vec3>,
    /// Per moving box: its index, path radius (m) and phase (rad).
    movers: Vec<(usize, f32, f32)>,
    frame: u32,
}

/// Why a scene cannot be made.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum MovingBoxesError {
    #[error("moving fraction {0} is not in [0, 1]")]
    BadFraction(f32),
}

impl MovingBoxes {
    /// `count` boxes, of which `moving_fraction` (0..=1) move each frame, from `seed`.
    pub fn new(count: usize, moving_fraction: f32, seed: u64) -> Result<Self, MovingBoxesError> {
        if !(0.0..=1.0).contains(&moving_fraction) {
            return Err(MovingBoxesError::BadFraction(moving_fraction));
        }
        let mut rng = SplitMix64(seed);
        let side = (count as f32 / BOXES_PER_CUBIC_METRE).cbrt();
        let mut centers = Vec::with_capacity(count);
        let mut half_extents = Vec::with_capacity(count);
        for _ in 0..count {
            centers.push(Vec3::new(rng.unit(), rng.unit(), rng.unit()) * side);
            half_extents.push(Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 0.5 + 0.25);
        }
        // Every k-th box moves: spread over the volume, the same ones every frame.
        let moving = (count as f32 * moving_fraction).round() as usize;
        let movers = (0..moving)
            .map(|k| {
                let index = k * count / moving;
                (
                    index,
                    1.0 + 3.0 * rng.unit(),
                    std::f32::consts::TAU * rng.unit(),
                )
            })
            .collect();
        Ok(Self {
            centers,
            half_extents,
            movers,
            frame: 0,
        })
    }

    /// Advances one frame: each moving box goes a step along its circle-like path (a Lissajous
    /// curve through its start).
    pub fn advance(&mut self) {
        self.frame += 1;
        for &(index, radius, phase) in &self.movers {
            let angle = |frame: u32| phase + frame as f32 * SPEED_PER_FRAME / radius;
            let offset = |frame: u32| {
                let a = angle(frame);
                Vec3::new(a.cos(), (2.0 * a).sin() * 0.5, a.sin()) * radius
            };
            self.centers[index] += offset(self.frame) - offset(self.frame - 1);
        }
    }

    /// The boxes now, into `aabbs` (cleared first).
    pub fn aabbs(&self, aabbs: &mut Vec<Aabb>) {
        aabbs.clear();
        aabbs.extend(
            self.centers
                .iter()
                .zip(&self.half_extents)
                .map(|(&c, &h)| Aabb::from_center_half_extents(c, h)),
        );
    }

    pub fn moving(&self) -> usize {
        self.movers.len()
    }
}

/// SplitMix64 (Steele et al. 2014): seeded, tiny, the same numbers on every platform.
struct SplitMix64(u64);

impl SplitMix64 {
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}
