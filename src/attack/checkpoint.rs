//! Checkpoints: the texture, Adam's moments, the step count and the EoT generator, written
//! atomically (temp file + rename) so a crash mid-write never leaves a broken checkpoint, and
//! checksummed so a damaged file is refused instead of resumed with another texture.

use super::adam::Adam;
use std::io::{Read, Write};
use std::path::Path;

/// Version 2 ends with an FNV-1a checksum of everything before it; version 1 (no checksum) is
/// still read.
const MAGIC: &[u8; 8] = b"PAVCKPT2";
const MAGIC_V1: &[u8; 8] = b"PAVCKPT1";

/// A resumable optimization state.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    /// Fingerprint of the config it belongs to.
    pub config_hash: u64,
    /// Steps completed.
    pub steps_done: u64,
    /// EoT generator state.
    pub rng_state: u64,
    /// The optimized values: the texture's, or its pyramid's levels (`attack::pyramid`).
    pub params: Vec<f32>,
    /// Optimizer state.
    pub adam: Adam,
}

/// Errors reading or writing a checkpoint.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// File system.
    #[error("checkpoint {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// Not a checkpoint of this format, or truncated.
    #[error("checkpoint {path}: {msg}")]
    Format {
        /// The file.
        path: String,
        /// What is wrong.
        msg: String,
    },
}

/// FNV-1a of `bytes`: a stable fingerprint of a config file.
pub fn fingerprint(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ *b as u64).wrapping_mul(0x100_0000_01b3))
}

fn put_f32s(out: &mut Vec<u8>, v: &[f32]) {
    for x in v {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

impl Checkpoint {
    /// Writes to `path` atomically.
    pub fn save(&self, path: &Path) -> Result<(), CheckpointError> {
        let io = |source| CheckpointError::Io { path: path.display().to_string(), source };
        let n = self.params.len();
        let mut b = Vec::with_capacity(64 + 12 * n);
        b.extend_from_slice(MAGIC);
        for v in [self.config_hash, self.steps_done, self.rng_state, self.adam.t, n as u64] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        for v in [self.adam.lr, self.adam.beta1, self.adam.beta2, self.adam.eps] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        put_f32s(&mut b, &self.params);
        put_f32s(&mut b, &self.adam.m);
        put_f32s(&mut b, &self.adam.v);
        let sum = fingerprint(&b);
        b.extend_from_slice(&sum.to_le_bytes());
        let tmp = path.with_extension("tmp");
        let mut f = std::fs::File::create(&tmp).map_err(io)?;
        f.write_all(&b).map_err(io)?;
        f.sync_all().map_err(io)?;
        std::fs::rename(&tmp, path).map_err(io)
    }

    /// Reads `path`.
    pub fn load(path: &Path) -> Result<Checkpoint, CheckpointError> {
        let fmt = |msg: String| CheckpointError::Format { path: path.display().to_string(), msg };
        let mut b = Vec::new();
        std::fs::File::open(path)
            .and_then(|mut f| f.read_to_end(&mut b))
            .map_err(|source| CheckpointError::Io { path: path.display().to_string(), source })?;
        if b.len() < 64 || (&b[..8] != MAGIC && &b[..8] != MAGIC_V1) {
            return Err(fmt("not a pav checkpoint".into()));
        }
        let v2 = &b[..8] == MAGIC;
        let n = u64::from_le_bytes(b[40..48].try_into().unwrap_or([0; 8])) as usize;
        let body = 64;
        let expected = n.saturating_mul(12).saturating_add(body + if v2 { 8 } else { 0 });
        if b.len() != expected {
            return Err(fmt(format!("{} bytes, expected {expected} for {n} values (truncated?)", b.len())));
        }
        if v2 {
            let (data, sum) = b.split_at(b.len() - 8);
            if fingerprint(data).to_le_bytes() != sum {
                return Err(fmt("checksum mismatch: the file is damaged; remove it to start over".into()));
            }
        }
        let u = |i: usize| u64::from_le_bytes(b[8 + 8 * i..16 + 8 * i].try_into().unwrap());
        let f = |i: usize| f32::from_le_bytes(b[48 + 4 * i..52 + 4 * i].try_into().unwrap());
        let arr = |k: usize| -> Vec<f32> {
            b[body + 4 * n * k..body + 4 * n * (k + 1)]
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                .collect()
        };
        Ok(Checkpoint {
            config_hash: u(0),
            steps_done: u(1),
            rng_state: u(2),
            params: arr(0),
            adam: Adam { lr: f(0), beta1: f(1), beta2: f(2), eps: f(3), t: u(3), m: arr(1), v: arr(2) },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_truncation_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.bin");
        let mut adam = Adam::new(4, 0.015);
        adam.t = 7;
        adam.m = vec![0.1, -0.2, 0.0, 1e-9];
        adam.v[2] = 3.5;
        let c = Checkpoint {
            config_hash: 99,
            steps_done: 12,
            rng_state: 0xdead_beef,
            params: vec![0.5, 0.25, 1e-4, 0.9999],
            adam,
        };
        c.save(&p).unwrap();
        assert_eq!(Checkpoint::load(&p).unwrap(), c);
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 3]).unwrap();
        let e = Checkpoint::load(&p).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        // One flipped bit anywhere is refused.
        let mut flipped = bytes.clone();
        flipped[70] ^= 0x10;
        std::fs::write(&p, &flipped).unwrap();
        let e = Checkpoint::load(&p).unwrap_err().to_string();
        assert!(e.contains("checksum"), "{e}");
        // A version-1 file (no checksum) still loads.
        let mut v1 = bytes[..bytes.len() - 8].to_vec();
        v1[..8].copy_from_slice(MAGIC_V1);
        std::fs::write(&p, &v1).unwrap();
        assert_eq!(Checkpoint::load(&p).unwrap(), c);
        std::fs::write(&p, b"hello").unwrap();
        assert!(Checkpoint::load(&p).unwrap_err().to_string().contains("not a pav checkpoint"));
        assert_ne!(fingerprint(b"lr = 0.015"), fingerprint(b"lr = 0.001"));
    }
}
