//! Labels drawn into 8-bit RGB images: numbers and the letters F and U in a 5 × 7 bitmap font,
//! and arrows, for the printed pieces' pages and the placement guide, which a person reads at
//! a glance and which need no font stack.

/// A 5 × 7 bitmap font for what the pages say: digits, and F and U for the arrows; each row's
/// five bits, the leftmost the highest.
fn glyph(ch: char) -> Option<[u8; 7]> {
    Some(match ch {
        '0' => [0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e],
        '1' => [0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e],
        '2' => [0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f],
        '3' => [0x1f, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0e],
        '4' => [0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02],
        '5' => [0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e],
        '6' => [0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e],
        '7' => [0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e],
        '9' => [0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c],
        'F' => [0x1f, 0x10, 0x10, 0x1e, 0x10, 0x10, 0x10],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0e],
        _ => return None,
    })
}

/// Width in pixels of `text` drawn `height` pixels tall (six glyph columns a character).
pub fn text_width(text: &str, height: f64) -> f64 {
    text.chars().count() as f64 * 6.0 * height / 7.0
}

/// Draws `text` in black, `height` pixels tall, top-left at `at`.
pub fn draw_text(rgb: &mut [u8], w: usize, at: [usize; 2], text: &str, height: f64) {
    let h = rgb.len() / 3 / w;
    let cell = height / 7.0;
    for (k, ch) in text.chars().enumerate() {
        let Some(rows) = glyph(ch) else { continue };
        let x0 = at[0] as f64 + k as f64 * 6.0 * cell;
        for (r, bits) in rows.iter().enumerate() {
            for c in 0..5 {
                if bits & (0x10 >> c) == 0 {
                    continue;
                }
                let (xa, ya) = ((x0 + c as f64 * cell) as usize, (at[1] as f64 + r as f64 * cell) as usize);
                let (xb, yb) = ((x0 + (c + 1) as f64 * cell) as usize, (at[1] as f64 + (r + 1) as f64 * cell) as usize);
                for y in ya..yb.max(ya + 1).min(h) {
                    for x in xa..xb.max(xa + 1).min(w) {
                        rgb[(y * w + x) * 3..][..3].fill(0);
                    }
                }
            }
        }
    }
}

/// Draws a line `len` pixels long centred on `at` along `dir`, a pixel thick.
pub fn draw_line(rgb: &mut [u8], w: usize, at: [usize; 2], dir: [f64; 2], len: f64) {
    let h = rgb.len() / 3 / w;
    let steps = (len * 2.0).ceil() as i64;
    for i in 0..=steps {
        let t = i as f64 / steps.max(1) as f64 - 0.5;
        let (x, y) = ((at[0] as f64 + dir[0] * len * t).round(), (at[1] as f64 + dir[1] * len * t).round());
        if x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h {
            rgb[(y as usize * w + x as usize) * 3..][..3].fill(0);
        }
    }
}

/// Draws an arrow `len` pixels long centred on `at`, pointing `dir`: a shaft and a head.
pub fn draw_arrow(rgb: &mut [u8], w: usize, at: [usize; 2], dir: [f64; 2], len: f64) {
    let h = rgb.len() / 3 / w;
    let thick = (len / 12.0).max(1.0);
    let (cx, cy) = (at[0] as f64, at[1] as f64);
    let tip = [cx + dir[0] * len / 2.0, cy + dir[1] * len / 2.0];
    let tail = [cx - dir[0] * len / 2.0, cy - dir[1] * len / 2.0];
    // The head: two strokes back from the tip at ±30°.
    let back = |a: f64| {
        let (c, s) = (a.cos(), a.sin());
        [tip[0] - (dir[0] * c - dir[1] * s) * len * 0.4, tip[1] - (dir[0] * s + dir[1] * c) * len * 0.4]
    };
    for (a, b) in [(tail, tip), (back(0.5), tip), (back(-0.5), tip)] {
        let steps = ((b[0] - a[0]).hypot(b[1] - a[1]) * 2.0).ceil() as usize + 1;
        for i in 0..=steps {
            let t = i as f64 / steps as f64;
            let (x, y) = (a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t);
            let t = thick.round() as i64;
            for dy in 0..t {
                for dx in 0..t {
                    let (px, py) = (x.round() as i64 - (t - 1) / 2 + dx, y.round() as i64 - (t - 1) / 2 + dy);
                    if px >= 0 && py >= 0 && (px as usize) < w && (py as usize) < h {
                        rgb[(py as usize * w + px as usize) * 3..][..3].fill(0);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_and_arrows_ink_where_they_are_drawn() {
        let (w, h) = (40, 20);
        let mut rgb = vec![255u8; w * h * 3];
        draw_text(&mut rgb, w, [1, 1], "1F", 7.0);
        // The 1's stem (glyph column 2) and the F's top bar (row 0, columns 6..11).
        assert_eq!(rgb[(3 * w + 3) * 3], 0);
        assert!((7..12).all(|x| rgb[(w + x) * 3] == 0));
        assert_eq!(text_width("1F", 7.0), 12.0);
        let mut rgb = vec![255u8; w * h * 3];
        draw_arrow(&mut rgb, w, [20, 10], [1.0, 0.0], 16.0);
        // The shaft along the row, the head's strokes behind the tip above and below it.
        assert!((13..28).all(|x| rgb[(10 * w + x) * 3] == 0));
        assert!((7..=8).any(|y| rgb[(y * w + 24) * 3] == 0) && (12..=13).any(|y| rgb[(y * w + 24) * 3] == 0));
        assert_eq!(rgb[(2 * w + 5) * 3], 255);
    }
}
