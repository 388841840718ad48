//! How much a video's light drifts over the turn, measured from the frames themselves: per frame,
//! the mean luminance and the grey-world colour of the part of the scene that stands still (the
//! room, not the turning car). A camera on automatic exposure or white balance follows the car as
//! it turns, and the detectors' scores then move for reasons that have nothing to do with the
//! texture: a video whose drift passes the limits is flagged, and its A_physical carries the flag.
//!
//! Which part stands still is read from the video alone, never from the detectors' boxes, so the
//! flag is a property of the video, the same whichever detectors score it: on a 16 × 16 grid of
//! cell means, the half of the cells whose luminance moves least once each frame's overall level
//! is taken out ([`still_cells`]). A change of exposure or white balance moves every cell by one
//! factor and is kept; the car's cells change with its pose and are left out. A car that fills
//! more than half the frame is partly counted.

use pav_core::image::Frame;

/// Cells per side of the grid a frame's light is kept at.
const CELLS: usize = 16;

/// A frame's light on a coarse grid: each cell's mean blue, green and red (0–255), so that the
/// light outside any box can be read after the detectors have run.
#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    width: usize,
    height: usize,
    cells: Vec<[f32; 3]>,
}

impl Light {
    /// The light of `f`.
    pub fn of(f: &Frame) -> Light {
        let mut sum = vec![[0f64; 3]; CELLS * CELLS];
        let mut n = vec![0u32; CELLS * CELLS];
        // About 320 pixels across whatever the frame's size: a cell's mean barely moves, and the
        // decoder thread, which measures it, stays fast.
        let step = (f.width / 320).max(1);
        for y in (0..f.height).step_by(step) {
            let cy = y * CELLS / f.height.max(1);
            for x in (0..f.width).step_by(step) {
                let c = cy * CELLS + x * CELLS / f.width.max(1);
                let p = &f.bgr[(y * f.width + x) * 3..][..3];
                (0..3).for_each(|k| sum[c][k] += f64::from(p[k]));
                n[c] += 1;
            }
        }
        let cells = sum.iter().zip(&n).map(|(s, &n)| s.map(|v| (v / f64::from(n.max(1))) as f32)).collect();
        Light { width: f.width, height: f.height, cells }
    }

    /// Cell `i`'s luminance (Rec. 601, 0–255).
    fn luminance(&self, i: usize) -> f64 {
        let [b, g, r] = self.cells[i].map(f64::from);
        0.299 * r + 0.587 * g + 0.114 * b
    }

    /// Mean luminance (Rec. 601, 0–255) and grey-world chromaticity `(r, b)` = (R, B) / (R + G + B)
    /// over `cells` (every cell when none is given).
    pub fn over(&self, cells: &[usize]) -> (f64, f64, f64) {
        let all: Vec<usize>;
        let keep = if cells.is_empty() {
            all = (0..self.cells.len()).collect();
            &all
        } else {
            cells
        };
        let mut bgr = [0f64; 3];
        for &i in keep {
            (0..3).for_each(|k| bgr[k] += f64::from(self.cells[i][k]));
        }
        let [b, g, r] = bgr.map(|v| v / keep.len() as f64);
        let total = (r + g + b).max(1e-9);
        (0.299 * r + 0.587 * g + 0.114 * b, r / total, b / total)
    }
}

/// The half of the grid's cells where the scene of `lights` (one video's frames) stands still.
/// Per cell, its log luminance over the frames less its own mean and less each frame's offset
/// (the median over cells of the same): what is left is what the cell does that the whole frame
/// does not. The cells with the least of it, ties to the lower index, are the still half.
pub fn still_cells(lights: &[&Light]) -> Vec<usize> {
    let n = lights.first().map_or(0, |l| l.cells.len());
    if lights.len() < 2 || lights.iter().any(|l| l.cells.len() != n) {
        return (0..n).collect();
    }
    let logs: Vec<Vec<f64>> = lights.iter().map(|l| (0..n).map(|i| (l.luminance(i) + 1.0).ln()).collect()).collect();
    let mean: Vec<f64> = (0..n).map(|i| logs.iter().map(|f| f[i]).sum::<f64>() / logs.len() as f64).collect();
    let mut moved = vec![0f64; n];
    for f in &logs {
        let mut centred: Vec<f64> = (0..n).map(|i| f[i] - mean[i]).collect();
        let offset = {
            let mut v = centred.clone();
            v.sort_by(f64::total_cmp);
            v[n / 2]
        };
        centred.iter_mut().for_each(|c| *c -= offset);
        (0..n).for_each(|i| moved[i] += centred[i] * centred[i]);
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| moved[a].total_cmp(&moved[b]).then(a.cmp(&b)));
    let mut keep = order[..n.div_ceil(2)].to_vec();
    keep.sort_unstable();
    keep
}

/// Each frame's light over the still half of the video's scene ([`still_cells`]).
pub fn frame_lights(lights: &[(usize, Light)]) -> Vec<FrameLight> {
    let still = still_cells(&lights.iter().map(|(_, l)| l).collect::<Vec<_>>());
    lights
        .iter()
        .map(|(frame, light)| {
            let (luminance, r, b) = light.over(&still);
            FrameLight { frame: *frame, luminance, r, b }
        })
        .collect()
}

/// One frame's light over the still part of the scene.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameLight {
    /// 0-based frame index.
    pub frame: usize,
    /// Mean luminance, 0–255.
    pub luminance: f64,
    /// Grey-world red share.
    pub r: f64,
    /// Grey-world blue share.
    pub b: f64,
}

/// The limits past which a video's drift is flagged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriftLimits {
    /// Luminance: the spread between the 5th and 95th percentile over the turn, as a share of
    /// the median.
    pub luminance: f64,
    /// Colour: the spread between the 5th and 95th percentile of the red or the blue share.
    pub colour: f64,
}

impl Default for DriftLimits {
    /// 5 % of luminance and 0.01 of colour share: above what the turntable fixture and a
    /// simulated turn without automatic exposure move (nothing: their rooms are rendered), below
    /// what a simulated automatic exposure that follows the car does (7.0 % at full strength;
    /// tests/it/cli_rig.rs).
    fn default() -> Self {
        DriftLimits { luminance: 0.05, colour: 0.01 }
    }
}

/// A video's drift over the turn.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Drift {
    /// Luminance spread (5th to 95th percentile) as a share of the median.
    pub luminance: f64,
    /// The larger spread (5th to 95th percentile) of the red and the blue share.
    pub colour: f64,
    /// Whether either passes its limit.
    pub flagged: bool,
}

impl Drift {
    /// The drift of `frames` (none when there are fewer than two).
    pub fn of(frames: &[FrameLight], limits: &DriftLimits) -> Option<Drift> {
        if frames.len() < 2 {
            return None;
        }
        let spread = |f: &dyn Fn(&FrameLight) -> f64| {
            let mut v: Vec<f64> = frames.iter().map(f).collect();
            v.sort_by(f64::total_cmp);
            let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
            (at(0.95) - at(0.05), at(0.5))
        };
        let (l, median) = spread(&|f| f.luminance);
        let luminance = l / median.max(1.0);
        let colour = spread(&|f| f.r).0.max(spread(&|f| f.b).0);
        let flagged = luminance > limits.luminance || colour > limits.colour;
        Some(Drift { luminance, colour, flagged })
    }

    /// The drift of videos pooled under one label: the largest of each, flagged when any is.
    pub fn pooled(a: Option<Drift>, b: Option<Drift>) -> Option<Drift> {
        match (a, b) {
            (Some(a), Some(b)) => Some(Drift {
                luminance: a.luminance.max(b.luminance),
                colour: a.colour.max(b.colour),
                flagged: a.flagged || b.flagged,
            }),
            (a, b) => a.or(b),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(w: usize, h: usize, bgr: [u8; 3]) -> Frame {
        Frame { width: w, height: h, bgr: bgr.repeat(w * h) }
    }

    /// A grey room whose exposure rises by a fifth over the turn, and a "car" in one corner
    /// (a quarter of the frame) whose pattern changes every frame.
    fn turn(frames: usize) -> Vec<(usize, Light)> {
        (0..frames)
            .map(|t| {
                let gain = 1.0 + 0.2 * t as f64 / (frames - 1) as f64;
                let mut f = frame(64, 32, [0, 0, 0]);
                for y in 0..32 {
                    for x in 0..64 {
                        let v = if x < 32 && y < 16 { ((x * 7 + y * 3 + t * 40) % 200 + 20) as f64 } else { 100.0 };
                        f.bgr[(y * 64 + x) * 3..][..3].fill((v * gain).round() as u8);
                    }
                }
                (t, Light::of(&f))
            })
            .collect()
    }

    #[test]
    fn the_still_half_is_the_room_and_keeps_its_exposure_change() {
        let lights = turn(12);
        let still = still_cells(&lights.iter().map(|(_, l)| l).collect::<Vec<_>>());
        assert_eq!(still.len(), 128);
        // No still cell lies in the car's quarter (cells x < 8, y < 8 of the 16 × 16 grid).
        assert!(still.iter().all(|&i| !(i % 16 < 8 && i / 16 < 8)), "{still:?}");
        let fl = frame_lights(&lights);
        assert!((fl[0].luminance - 100.0).abs() < 0.5 && (fl[11].luminance - 120.0).abs() < 0.5, "{fl:?}");
        // The whole frame moves with the car as well.
        let (first, _, _) = lights[0].1.over(&[]);
        assert!((first - fl[0].luminance).abs() > 1.0, "{first}");
        // A single frame has no still part to find: every cell.
        assert_eq!(still_cells(&[&lights[0].1]).len(), 256);
    }

    #[test]
    fn drift_is_the_spread_over_the_turn_and_flags_past_its_limits() {
        // A spread of 2 % stays under the 5 % limit.
        let steady: Vec<FrameLight> =
            (0..40).map(|i| FrameLight { frame: i, luminance: 100.0 + (i % 3) as f64, r: 0.33, b: 0.33 }).collect();
        let d = Drift::of(&steady, &DriftLimits::default()).unwrap();
        assert!((d.luminance - 2.0 / 101.0).abs() < 1e-9 && d.colour == 0.0 && !d.flagged, "{d:?}");
        // Brightening by a quarter over the turn, and a blue cast of 0.02.
        let ramp: Vec<FrameLight> = (0..40)
            .map(|i| FrameLight { frame: i, luminance: 100.0 + i as f64 * 25.0 / 39.0, r: 0.33, b: 0.33 })
            .collect();
        let d = Drift::of(&ramp, &DriftLimits::default()).unwrap();
        assert!(d.flagged && d.luminance > 0.18, "{d:?}");
        let cast: Vec<FrameLight> = (0..40)
            .map(|i| FrameLight { frame: i, luminance: 100.0, r: 0.33, b: 0.32 + (i / 20) as f64 * 0.02 })
            .collect();
        assert!(Drift::of(&cast, &DriftLimits::default()).unwrap().flagged);
        assert!(Drift::of(&steady[..1], &DriftLimits::default()).is_none());
        let p = Drift::pooled(Drift::of(&steady, &DriftLimits::default()), Drift::of(&cast, &DriftLimits::default()));
        assert!(p.unwrap().flagged);
    }
}
