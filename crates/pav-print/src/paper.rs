//! Paper sizes by name (`a4`, `letter`, …), as `WIDTHxHEIGHT` in millimetres, or a roll
//! `roll:WIDTHmm` for a wide-format or wrap printer: `--paper` on every command that lays
//! something out on a page; model scales (`--scale 20` or `1:20`).

use std::fmt;
use std::str::FromStr;

/// A sheet of paper, portrait, in millimetres, or a roll.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Paper {
    /// Width in millimetres (the shorter side for a named size; across a roll).
    pub width_mm: f64,
    /// Height in millimetres (on a roll: the most one length may take).
    pub height_mm: f64,
    /// A roll: cut to the length a layout uses.
    pub roll: bool,
}

/// The named sizes `--paper` knows: ISO 216 and the North American ones.
pub const NAMED: &[(&str, f64, f64)] = &[
    ("a5", 148.0, 210.0),
    ("a4", 210.0, 297.0),
    ("a3", 297.0, 420.0),
    ("letter", 215.9, 279.4),
    ("legal", 215.9, 355.6),
    ("tabloid", 279.4, 431.8),
];

impl Paper {
    /// ISO A4, the default.
    pub const A4: Paper = Paper { width_mm: 210.0, height_mm: 297.0, roll: false };

    /// The longest length of roll one page takes, mm: 200 inches, the largest page PDF
    /// readers open (a longer layout goes on to another page of the roll).
    pub const ROLL_MM: f64 = 5080.0;

    /// A sheet `w × h` mm.
    pub fn sheet(width_mm: f64, height_mm: f64) -> Paper {
        Paper { width_mm, height_mm, roll: false }
    }

    /// The size as `[width, height]` millimetres.
    pub fn mm(&self) -> [f64; 2] {
        [self.width_mm, self.height_mm]
    }
}

impl FromStr for Paper {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let key = s.trim().to_ascii_lowercase();
        if let Some(&(_, w, h)) = NAMED.iter().find(|(n, ..)| *n == key) {
            return Ok(Paper::sheet(w, h));
        }
        let names = NAMED.iter().map(|n| n.0).collect::<Vec<_>>().join(", ");
        let bad = || {
            format!("`{s}` is no paper size: use {names}, WIDTHxHEIGHT in millimetres (e.g. 210x297), or roll:WIDTHmm (e.g. roll:1370mm)")
        };
        if let Some(w) = key.strip_prefix("roll:") {
            let w: f64 = w.trim().trim_end_matches("mm").trim().parse().map_err(|_| bad())?;
            if !(w.is_finite() && w > 0.0) {
                return Err(bad());
            }
            return Ok(Paper { width_mm: w, height_mm: Paper::ROLL_MM, roll: true });
        }
        let (w, h) = key.split_once('x').ok_or_else(bad)?;
        let (w, h): (f64, f64) = (w.trim().parse().map_err(|_| bad())?, h.trim().parse().map_err(|_| bad())?);
        if !(w.is_finite() && h.is_finite() && w > 0.0 && h > 0.0) {
            return Err(format!("a paper of {w} × {h} mm has no area: {}", bad()));
        }
        Ok(Paper::sheet(w, h))
    }
}

impl fmt::Display for Paper {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.roll {
            return write!(f, "roll:{}mm", self.width_mm);
        }
        match NAMED.iter().find(|(_, w, h)| *w == self.width_mm && *h == self.height_mm) {
            Some((name, ..)) => f.write_str(name),
            None => write!(f, "{}x{}", self.width_mm, self.height_mm),
        }
    }
}

/// A model scale written `20` or `1:20` (the model is 1/20 of the car): `--scale` wherever a
/// print is sized.
pub fn parse_scale(s: &str) -> Result<f64, String> {
    let t = s.trim();
    let n = t.strip_prefix("1:").unwrap_or(t).trim();
    match n.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 1.0 => Ok(v),
        _ => Err(format!("`{s}` is no model scale: write 20 or 1:20 for a model 1/20 of the car's size")),
    }
}

/// The model scales die-cast and kit cars are sold at: 1:18, 1:20, 1:24, 1:43.
pub const COMMON_SCALES: [f64; 4] = [18.0, 20.0, 24.0, 43.0];

/// The scale of a model measured `model_mm` long (bumper to bumper) of a car `car_m` long.
/// A length more than 15 % from what the nearest common scale gives is refused with both
/// numbers: the model in hand is probably another car.
pub fn scale_from_length(car_m: f64, model_mm: f64) -> Result<f64, String> {
    if !(model_mm.is_finite() && model_mm > 0.0) {
        return Err(format!("a model's length is a positive number of millimetres, not {model_mm}"));
    }
    let scale = car_m * 1000.0 / model_mm;
    let (nearest, expect) = COMMON_SCALES
        .iter()
        .map(|&s| (s, car_m * 1000.0 / s))
        .min_by(|a, b| (a.1 - model_mm).abs().total_cmp(&(b.1 - model_mm).abs()))
        .expect("common scales");
    if (model_mm - expect).abs() > 0.15 * expect {
        return Err(format!(
            "a model {model_mm:.0} mm long would be 1:{scale:.1} of this {car_m:.2} m car, but at the nearest common scale, 1:{nearest:.0}, the car is {expect:.0} mm long: more than 15 % apart, so the model is probably another car (measure it bumper to bumper, or give --scale)"
        ));
    }
    Ok(scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn named_sizes_and_millimetres_parse_and_print_back() {
        assert_eq!("A4".parse::<Paper>().unwrap(), Paper::A4);
        assert_eq!("letter".parse::<Paper>().unwrap().mm(), [215.9, 279.4]);
        assert_eq!("210x297".parse::<Paper>().unwrap().to_string(), "a4");
        assert_eq!("100 x 150".parse::<Paper>().unwrap().to_string(), "100x150");
        let roll = "roll:1370mm".parse::<Paper>().unwrap();
        assert!(roll.roll && roll.width_mm == 1370.0 && roll.to_string() == "roll:1370mm");
        assert_eq!("ROLL:610".parse::<Paper>().unwrap().to_string(), "roll:610mm");
        for bad in ["b5", "210", "0x297", "-1x2", "axb", "", "roll:", "roll:0mm", "roll:wide"] {
            let e = bad.parse::<Paper>().unwrap_err();
            assert!(e.contains("a4") || e.contains("no area"), "{bad}: {e}");
        }
    }

    #[test]
    fn a_scale_is_a_number_or_one_to_a_number() {
        assert_eq!(parse_scale("20"), Ok(20.0));
        assert_eq!(parse_scale("1:20"), Ok(20.0));
        assert_eq!(parse_scale(" 1:24.5 "), Ok(24.5));
        for bad in ["1:0", "0.5", "1/20", "x", "2:20"] {
            assert!(parse_scale(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_measured_model_sets_the_scale_unless_it_is_another_car() {
        // The e-tron is 4.90 m: 245 mm at 1:20.
        let s = scale_from_length(4.90, 250.0).unwrap();
        assert!((s - 19.6).abs() < 1e-9, "{s}");
        assert!((scale_from_length(4.90, 114.0).unwrap() - 4900.0 / 114.0).abs() < 1e-9, "1:43 is common too");
        let e = scale_from_length(4.90, 160.0).unwrap_err();
        assert!(e.contains("1:24") && e.contains("204 mm") && e.contains("another car"), "{e}");
        assert!(scale_from_length(4.90, 0.0).is_err() && scale_from_length(4.90, f64::NAN).is_err());
    }
}
