//! Reader for NumPy `.npz` archives (zip of `.npy` arrays), little-endian C-order only.

use std::io::Read;
use std::path::{Path, PathBuf};

/// Errors reading an npz archive.
#[derive(Debug, thiserror::Error)]
pub enum NpzError {
    /// The file could not be opened.
    #[error("{path}: {source}")]
    Open {
        /// Archive path.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not a zip archive.
    #[error("{path}: not an npz (zip) archive: {source}")]
    Archive {
        /// Archive path.
        path: PathBuf,
        /// The zip reader's error.
        source: zip::result::ZipError,
    },
    /// An array is missing.
    #[error("{path}: no array `{name}` (has: {have})")]
    Missing {
        /// Archive path.
        path: PathBuf,
        /// Requested array.
        name: String,
        /// Arrays present.
        have: String,
    },
    /// An array's header or payload is malformed or of an unsupported type.
    #[error("{path}: array `{name}`: {msg}")]
    Array {
        /// Archive path.
        path: PathBuf,
        /// Array name.
        name: String,
        /// Reason.
        msg: String,
    },
}

/// Element data of an array.
#[derive(Clone, Debug, PartialEq)]
pub enum NpyData {
    /// `|u1`.
    U8(Vec<u8>),
    /// `<f4`.
    F32(Vec<f32>),
    /// `<f8`.
    F64(Vec<f64>),
    /// `<i8`.
    I64(Vec<i64>),
}

/// One array: shape and data.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// Dimensions (C order).
    pub shape: Vec<usize>,
    /// Elements.
    pub data: NpyData,
}

impl NpyArray {
    /// Elements converted to f64 (u8 and integers exactly, f32 widened).
    pub fn to_f64(&self) -> Vec<f64> {
        match &self.data {
            NpyData::U8(v) => v.iter().map(|&x| x as f64).collect(),
            NpyData::F32(v) => v.iter().map(|&x| x as f64).collect(),
            NpyData::F64(v) => v.clone(),
            NpyData::I64(v) => v.iter().map(|&x| x as f64).collect(),
        }
    }
}

/// An opened npz archive.
pub struct Npz {
    path: PathBuf,
    zip: zip::ZipArchive<std::fs::File>,
}

impl Npz {
    /// Opens `path`.
    pub fn open(path: &Path) -> Result<Self, NpzError> {
        let f = std::fs::File::open(path).map_err(|source| NpzError::Open { path: path.into(), source })?;
        let zip = zip::ZipArchive::new(f).map_err(|source| NpzError::Archive { path: path.into(), source })?;
        Ok(Npz { path: path.into(), zip })
    }

    /// Names of the arrays in the archive.
    pub fn names(&self) -> Vec<String> {
        self.zip.file_names().map(|n| n.trim_end_matches(".npy").to_string()).collect()
    }

    /// Reads array `name`.
    pub fn array(&mut self, name: &str) -> Result<NpyArray, NpzError> {
        let have = self.names().join(", ");
        let path = self.path.clone();
        let mut entry = self.zip.by_name(&format!("{name}.npy")).map_err(|_| NpzError::Missing {
            path: path.clone(),
            name: name.into(),
            have,
        })?;
        let mut bytes = Vec::with_capacity(entry.size() as usize);
        entry.read_to_end(&mut bytes).map_err(|e| NpzError::Array {
            path: path.clone(),
            name: name.into(),
            msg: e.to_string(),
        })?;
        parse_npy(&bytes).map_err(|msg| NpzError::Array { path, name: name.into(), msg })
    }
}

/// Parses one `.npy` file's bytes.
fn parse_npy(b: &[u8]) -> Result<NpyArray, String> {
    if b.len() < 10 || &b[..6] != b"\x93NUMPY" {
        return Err("not an .npy payload (bad magic)".into());
    }
    let (hlen, start) = match b[6] {
        1 => (u16::from_le_bytes([b[8], b[9]]) as usize, 10),
        2 | 3 if b.len() >= 12 => (u32::from_le_bytes([b[8], b[9], b[10], b[11]]) as usize, 12),
        v => return Err(format!("unsupported .npy version {v}")),
    };
    let header =
        std::str::from_utf8(b.get(start..start + hlen).ok_or("truncated header")?).map_err(|e| e.to_string())?;
    let field = |key: &str| -> Result<&str, String> {
        let at = header.find(&format!("'{key}':")).ok_or_else(|| format!("header lacks `{key}`: {header}"))?;
        Ok(header[at + key.len() + 3..].trim_start())
    };
    let descr = field("descr")?;
    let descr = descr.trim_start_matches('\'').split('\'').next().unwrap_or("");
    if field("fortran_order")?.starts_with("True") {
        return Err("Fortran-ordered arrays are not supported".into());
    }
    let shape_txt = field("shape")?;
    let inner = shape_txt.trim_start_matches('(').split(')').next().unwrap_or("");
    let shape: Vec<usize> = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>().map_err(|_| format!("bad shape `{shape_txt}`")))
        .collect::<Result<_, _>>()?;
    let n: usize = shape.iter().product();
    let payload = &b[start + hlen..];
    let need = |w: usize| -> Result<&[u8], String> {
        payload
            .get(..n * w)
            .ok_or_else(|| format!("payload has {} bytes, shape {shape:?} of {descr} needs {}", payload.len(), n * w))
    };
    let data = match descr {
        "|u1" | "<u1" => NpyData::U8(need(1)?.to_vec()),
        "<f4" => NpyData::F32(need(4)?.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4"))).collect()),
        "<f8" => NpyData::F64(need(8)?.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8"))).collect()),
        "<i8" => NpyData::I64(need(8)?.chunks_exact(8).map(|c| i64::from_le_bytes(c.try_into().expect("8"))).collect()),
        other => return Err(format!("unsupported dtype `{other}`")),
    };
    Ok(NpyArray { shape, data })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(descr: &str, shape: &str, payload: &[u8]) -> Vec<u8> {
        let mut h = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
        while (10 + h.len() + 1) % 64 != 0 {
            h.push(' ');
        }
        h.push('\n');
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(h.len() as u16).to_le_bytes());
        b.extend_from_slice(h.as_bytes());
        b.extend_from_slice(payload);
        b
    }

    #[test]
    fn parses_numpy_headers() {
        let a = parse_npy(&npy("<f8", "(2, 1)", &[1.5f64.to_le_bytes(), (-2.0f64).to_le_bytes()].concat())).unwrap();
        assert_eq!(a.shape, vec![2, 1]);
        assert_eq!(a.to_f64(), vec![1.5, -2.0]);
        let s = parse_npy(&npy("|u1", "()", &[7])).unwrap();
        assert_eq!((s.shape.len(), s.to_f64()), (0, vec![7.0]));
        assert!(parse_npy(&npy("<f8", "(3,)", &[0; 16])).unwrap_err().contains("needs 24"));
        assert!(parse_npy(&npy("<c16", "(1,)", &[0; 16])).unwrap_err().contains("unsupported dtype"));
    }
}
