//! The ICC soft proof: a colour sent from sRGB to a printer's output profile (the ink it would
//! print) and back to sRGB (what that ink looks like), by LittleCMS.

use lcms2::{ColorSpaceSignature, Flags, Intent, PixelFormat, Profile, ProfileClassSignature, Transform};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Ghostscript's CMYK output profile (Debian `libgs-common`): the profile used until a printer's own is named.
pub const DEFAULT_PROFILE: &str = "/usr/share/color/icc/ghostscript/default_cmyk.icc";

/// How colours outside the printer's gamut are brought inside (ICC rendering intents).
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum RenderingIntent {
    /// Compresses the whole gamut, keeping relations between colours.
    Perceptual,
    /// Keeps in-gamut colours, clips the rest, maps white to the paper's white (LittleCMS's and
    /// most print dialogs' default).
    #[default]
    RelativeColorimetric,
    /// Keeps saturation at the cost of hue accuracy.
    Saturation,
    /// Like relative, but keeps the paper's tint.
    AbsoluteColorimetric,
}

impl std::str::FromStr for RenderingIntent {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "perceptual" => Ok(Self::Perceptual),
            "relative-colorimetric" => Ok(Self::RelativeColorimetric),
            "saturation" => Ok(Self::Saturation),
            "absolute-colorimetric" => Ok(Self::AbsoluteColorimetric),
            _ => Err(format!(
                "unknown rendering intent {s:?}: perceptual, relative-colorimetric, saturation or absolute-colorimetric"
            )),
        }
    }
}

impl std::fmt::Display for RenderingIntent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Perceptual => "perceptual",
            Self::RelativeColorimetric => "relative-colorimetric",
            Self::Saturation => "saturation",
            Self::AbsoluteColorimetric => "absolute-colorimetric",
        })
    }
}

impl RenderingIntent {
    fn lcms(self) -> Intent {
        match self {
            Self::Perceptual => Intent::Perceptual,
            Self::RelativeColorimetric => Intent::RelativeColorimetric,
            Self::Saturation => Intent::Saturation,
            Self::AbsoluteColorimetric => Intent::AbsoluteColorimetric,
        }
    }
}

/// Why a soft proof could not be built.
#[derive(Debug, thiserror::Error)]
pub enum ProofError {
    /// The profile file could not be read.
    #[error("ICC profile {path}: {source} (Debian's libgs-common ships {DEFAULT_PROFILE})")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not an ICC profile LittleCMS can parse.
    #[error("{path} is not an ICC profile LittleCMS can read: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// LittleCMS's error.
        source: lcms2::Error,
    },
    /// The profile describes a display, camera or colour space, not a printer.
    #[error("{path} is a {class} profile, not a printer's output profile (ICC class 'prtr'); name the profile your printer's driver or RIP uses")]
    NotOutput {
        /// The file.
        path: PathBuf,
        /// Its device class.
        class: String,
    },
    /// An output profile whose device colours are neither CMYK nor RGB.
    #[error("{path}: device colour space {space} is not supported (CMYK and RGB printers are)")]
    Space {
        /// The file.
        path: PathBuf,
        /// Its colour space.
        space: String,
    },
    /// The calibration file named instead of a profile.
    #[error("print calibration {path}: {why}")]
    Calibration {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// LittleCMS refused the transform.
    #[error("{path}: LittleCMS could not build the transform: {source}")]
    Transform {
        /// The file.
        path: PathBuf,
        /// LittleCMS's error.
        source: lcms2::Error,
    },
}

enum Device {
    Cmyk(Transform<[f64; 3], [f64; 4]>, Transform<[f64; 4], [f64; 3]>),
    Rgb(Transform<[f64; 3], [f64; 3]>, Transform<[f64; 3], [f64; 3]>),
}

/// sRGB → printer → sRGB through one output profile.
pub struct SoftProof {
    device: Device,
}

fn class_name(c: ProfileClassSignature) -> String {
    match c {
        ProfileClassSignature::InputClass => "input (camera or scanner)".into(),
        ProfileClassSignature::DisplayClass => "display".into(),
        ProfileClassSignature::LinkClass => "device link".into(),
        ProfileClassSignature::AbstractClass => "abstract".into(),
        ProfileClassSignature::ColorSpaceClass => "colour space".into(),
        ProfileClassSignature::NamedColorClass => "named colour".into(),
        other => format!("{other:?}"),
    }
}

impl SoftProof {
    /// Opens `profile` (an ICC output profile) with the intent and black-point compensation of
    /// the way to the printer; the way back is relative colorimetric, as a print viewed under
    /// the light it is photographed in.
    pub fn open(profile: &Path, intent: RenderingIntent, black_point_compensation: bool) -> Result<Self, ProofError> {
        let bytes = std::fs::read(profile).map_err(|source| ProofError::Read { path: profile.into(), source })?;
        let printer = Profile::new_icc(&bytes).map_err(|source| ProofError::Parse { path: profile.into(), source })?;
        if printer.device_class() != ProfileClassSignature::OutputClass {
            return Err(ProofError::NotOutput { path: profile.into(), class: class_name(printer.device_class()) });
        }
        let srgb = Profile::new_srgb();
        let flags = if black_point_compensation { Flags::BLACKPOINT_COMPENSATION } else { Flags::default() };
        let err = |source| ProofError::Transform { path: profile.into(), source };
        let device = match printer.color_space() {
            ColorSpaceSignature::CmykData => Device::Cmyk(
                Transform::new_flags(
                    &srgb,
                    PixelFormat::RGB_DBL,
                    &printer,
                    PixelFormat::CMYK_DBL,
                    intent.lcms(),
                    flags,
                )
                .map_err(err)?,
                Transform::new(
                    &printer,
                    PixelFormat::CMYK_DBL,
                    &srgb,
                    PixelFormat::RGB_DBL,
                    Intent::RelativeColorimetric,
                )
                .map_err(err)?,
            ),
            ColorSpaceSignature::RgbData => Device::Rgb(
                Transform::new_flags(&srgb, PixelFormat::RGB_DBL, &printer, PixelFormat::RGB_DBL, intent.lcms(), flags)
                    .map_err(err)?,
                Transform::new(
                    &printer,
                    PixelFormat::RGB_DBL,
                    &srgb,
                    PixelFormat::RGB_DBL,
                    Intent::RelativeColorimetric,
                )
                .map_err(err)?,
            ),
            other => return Err(ProofError::Space { path: profile.into(), space: format!("{other:?}") }),
        };
        Ok(Self { device })
    }

    /// The proofs of many sRGB colours (encoded, in [0, 1]); results clipped to [0, 1].
    pub fn proof(&self, rgb: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let mut out = vec![[0f64; 3]; rgb.len()];
        match &self.device {
            Device::Cmyk(to, back) => {
                let mut ink = vec![[0f64; 4]; rgb.len()];
                to.transform_pixels(rgb, &mut ink);
                back.transform_pixels(&ink, &mut out);
            }
            Device::Rgb(to, back) => {
                let mut ink = vec![[0f64; 3]; rgb.len()];
                to.transform_pixels(rgb, &mut ink);
                back.transform_pixels(&ink, &mut out);
            }
        }
        out.iter_mut().for_each(|p| p.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0)));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pav_core::colour::{delta_e2000_srgb, spread};

    #[test]
    fn the_default_cmyk_profile_moves_saturated_colours_and_keeps_greys_close() {
        let p = SoftProof::open(Path::new(DEFAULT_PROFILE), RenderingIntent::RelativeColorimetric, false).unwrap();
        let greys: Vec<[f64; 3]> = (1..10).map(|i| [i as f64 / 10.0; 3]).collect();
        let de: Vec<f64> = greys.iter().zip(p.proof(&greys)).map(|(a, b)| delta_e2000_srgb(*a, b)).collect();
        assert!(spread(&de, 5.0).0 < 3.0, "greys move by {de:?}");
        // sRGB's green primary is far outside a CMYK press gamut.
        let g = p.proof(&[[0.0, 1.0, 0.0]])[0];
        assert!(delta_e2000_srgb([0.0, 1.0, 0.0], g) > 10.0, "{g:?}");
    }

    #[test]
    fn a_display_profile_or_a_non_profile_is_refused_with_its_reason() {
        let dir = tempfile::tempdir().unwrap();
        let srgb = dir.path().join("srgb.icc");
        std::fs::write(&srgb, Profile::new_srgb().icc().unwrap()).unwrap();
        let e = SoftProof::open(&srgb, RenderingIntent::Perceptual, false).err().unwrap();
        assert!(matches!(e, ProofError::NotOutput { .. }) && e.to_string().contains("display"), "{e}");
        let junk = dir.path().join("junk.icc");
        std::fs::write(&junk, b"not a profile").unwrap();
        assert!(matches!(SoftProof::open(&junk, RenderingIntent::Perceptual, false), Err(ProofError::Parse { .. })));
        let e = SoftProof::open(&dir.path().join("missing.icc"), RenderingIntent::Perceptual, false).err().unwrap();
        assert!(matches!(e, ProofError::Read { .. }) && e.to_string().contains("libgs-common"), "{e}");
    }
}
