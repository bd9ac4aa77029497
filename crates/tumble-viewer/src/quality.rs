//! The renderer's cost knobs, so that a frame-rate run can compare them (`tumble view
//! --quality filter=tap1,prepass=on ...`). The default is the cheapest choice that draws the
//! same picture as the first renderer did (`legacy` draws it the first renderer's way).
//!
//! Where the pixels' time goes (issue 9: 13.9 ms per 1920x1080 frame on an H100, 1.6 ms at
//! 320x180): every lit fragment filters the shadow map, and before these knobs each ground
//! fragment under a box was shaded and then drawn over, as were boxes behind boxes.

use std::fmt;
use std::str::FromStr;

/// How a lit fragment reads the shadow map (common.wgsl's `light_reaching`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ShadowFilter {
    /// The 4 x 4 texels around the point in four gathers of 2 x 2 comparisons, weighted as
    /// `Taps9` weighs them: the same filter in 4 texture reads instead of 9.
    #[default]
    Gather4,
    /// Nine bilinear comparisons 3 x 3 texels apart (the first renderer's filter).
    Taps9,
    /// One bilinear comparison: 2 x 2 texels, a harder shadow edge.
    Tap1,
    /// No shadow lookups (everything lit), to measure what the shadows cost.
    Off,
}

impl ShadowFilter {
    /// The value of `SHADOW_FILTER` in common.wgsl.
    pub(crate) fn wgsl(self) -> u32 {
        match self {
            Self::Gather4 => 0,
            Self::Taps9 => 1,
            Self::Tap1 => 2,
            Self::Off => 3,
        }
    }
}

/// In what order the frame's surfaces are drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DrawOrder {
    /// Each mesh's instances nearest the camera first, then the ground planes: the depth
    /// test then rejects, before shading, the ground under the bodies and most bodies behind
    /// bodies.
    #[default]
    FrontToBack,
    /// The ground first, then the instances in body order (the first renderer's order).
    Submitted,
}

/// Every knob; `Quality::default()` is the renderer's choice.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Quality {
    pub shadow_filter: ShadowFilter,
    /// Side of the square shadow map in texels. The shadow pass's cost grows with its square,
    /// the frame's does not: on an H100 at 1920x1080 (falling-boxes) it took 2.67 ms at 2048
    /// and 0.95 ms at 1024, of a 7.3 and a 5.5 ms frame, and the two pictures look the same
    /// (their shadows' edges move by a texel of the map).
    pub shadow_map_size: u32,
    pub order: DrawOrder,
    /// Draw every surface's depth first (no shading), then shade only the nearest fragment
    /// of each pixel: each pixel is shaded once, for a second pass of vertices and rasterizing.
    pub depth_prepass: bool,
}

impl Default for Quality {
    fn default() -> Self {
        Self {
            shadow_filter: ShadowFilter::Gather4,
            shadow_map_size: 1024,
            order: DrawOrder::FrontToBack,
            depth_prepass: false,
        }
    }
}

impl Quality {
    /// The first renderer's choices: the reference the default's pictures are compared with.
    pub const LEGACY: Self = Self {
        shadow_filter: ShadowFilter::Taps9,
        shadow_map_size: 2048,
        order: DrawOrder::Submitted,
        depth_prepass: false,
    };
}

/// `legacy`, or comma-separated `key=value` changes to the default (an empty text is the
/// default): `filter=gather4|taps9|tap1|off`, `shadow-size=TEXELS` (64 to 8192),
/// `order=front-to-back|submitted`, `prepass=on|off`. After `legacy`, changes apply to it.
impl FromStr for Quality {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let mut quality = Self::default();
        for item in text
            .split(',')
            .map(str::trim)
            .filter(|item| !item.is_empty())
        {
            if item == "legacy" {
                quality = Self::LEGACY;
                continue;
            }
            let Some((key, value)) = item.split_once('=') else {
                return Err(format!("{item:?} is not KEY=VALUE or `legacy`"));
            };
            let bad = |expected: &str| format!("{key}={value:?}: expected {expected}");
            match key {
                "filter" => {
                    quality.shadow_filter = match value {
                        "gather4" => ShadowFilter::Gather4,
                        "taps9" => ShadowFilter::Taps9,
                        "tap1" => ShadowFilter::Tap1,
                        "off" => ShadowFilter::Off,
                        _ => return Err(bad("gather4, taps9, tap1 or off")),
                    }
                }
                "shadow-size" => {
                    quality.shadow_map_size = value
                        .parse()
                        .ok()
                        .filter(|size| (64..=8192).contains(size))
                        .ok_or_else(|| bad("a side in texels from 64 to 8192"))?;
                }
                "order" => {
                    quality.order = match value {
                        "front-to-back" => DrawOrder::FrontToBack,
                        "submitted" => DrawOrder::Submitted,
                        _ => return Err(bad("front-to-back or submitted")),
                    }
                }
                "prepass" => {
                    quality.depth_prepass = match value {
                        "on" => true,
                        "off" => false,
                        _ => return Err(bad("on or off")),
                    }
                }
                _ => {
                    return Err(format!(
                        "unknown quality knob {key:?} (filter, shadow-size, order, prepass)"
                    ));
                }
            }
        }
        Ok(quality)
    }
}

/// The form `from_str` reads, every knob spelled out (printed with frame-rate reports).
impl fmt::Display for Quality {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let filter = match self.shadow_filter {
            ShadowFilter::Gather4 => "gather4",
            ShadowFilter::Taps9 => "taps9",
            ShadowFilter::Tap1 => "tap1",
            ShadowFilter::Off => "off",
        };
        let order = match self.order {
            DrawOrder::FrontToBack => "front-to-back",
            DrawOrder::Submitted => "submitted",
        };
        let prepass = if self.depth_prepass { "on" } else { "off" };
        write!(
            f,
            "filter={filter},shadow-size={},order={order},prepass={prepass}",
            self.shadow_map_size
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_knobs_and_round_trips() {
        assert_eq!("".parse::<Quality>().unwrap(), Quality::default());
        assert_eq!("legacy".parse::<Quality>().unwrap(), Quality::LEGACY);
        let quality: Quality = "legacy, prepass=on,shadow-size=1024".parse().unwrap();
        assert_eq!(quality.shadow_filter, ShadowFilter::Taps9);
        assert!(quality.depth_prepass);
        assert_eq!(quality.shadow_map_size, 1024);
        for quality in [Quality::default(), Quality::LEGACY, quality] {
            assert_eq!(quality.to_string().parse::<Quality>().unwrap(), quality);
        }
    }

    #[test]
    fn bad_knobs_are_errors_that_name_them() {
        for (text, named) in [
            ("filter=pcf", "filter"),
            ("shadow-size=10", "shadow-size"),
            ("shadow-size=big", "shadow-size"),
            ("msaa=4", "msaa"),
            ("prepass", "prepass"),
        ] {
            let error = text.parse::<Quality>().unwrap_err();
            assert!(error.contains(named), "{text}: {error}");
        }
    }
}
