//! Checkpoints: the texture, Adam's moments, the step count, the EoT generator and the running
//! sum of the averaged textures (`optimizer.average`), written
//! atomically (temp file + rename) so a crash mid-write never leaves a broken checkpoint, and
//! checksummed so a damaged file is refused instead of resumed with another texture.

use super::adam::Adam;
use std::io::Read;
use std::path::Path;

/// Version 3 adds the running average after Adam's moments; version 2 ends with an FNV-1a
/// checksum of everything before it, as version 3 does; version 1 (no checksum) is still read.
const MAGIC: &[u8; 8] = b"PAVCKPT3";
const MAGIC_V2: &[u8; 8] = b"PAVCKPT2";
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
    /// The textures summed so far for `optimizer.average` and how many (empty and 0 without it).
    pub average: Average,
}

/// The running sum of the textures a run averages (`optimizer.average`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Average {
    /// Textures added.
    pub count: u64,
    /// Their sum (RGB interleaved; empty until the first).
    pub sum: Vec<f32>,
}

impl Average {
    /// Adds `tex`.
    pub fn add(&mut self, tex: &[f32]) {
        if self.sum.is_empty() {
            self.sum = vec![0.0; tex.len()];
        }
        self.sum.iter_mut().zip(tex).for_each(|(s, t)| *s += t);
        self.count += 1;
    }

    /// The mean of the textures added, None before the first.
    pub fn mean(&self) -> Option<Vec<f32>> {
        (self.count > 0).then(|| self.sum.iter().map(|s| s / self.count as f32).collect())
    }
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
    pav_core::rng::fnv1a(bytes.iter().map(|&b| u64::from(b)))
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
        b.extend_from_slice(&self.average.count.to_le_bytes());
        b.extend_from_slice(&(self.average.sum.len() as u64).to_le_bytes());
        put_f32s(&mut b, &self.average.sum);
        let sum = fingerprint(&b);
        b.extend_from_slice(&sum.to_le_bytes());
        pav_core::durable::write(path, &b).map_err(io)
    }

    /// Reads `path`.
    pub fn load(path: &Path) -> Result<Checkpoint, CheckpointError> {
        let fmt = |msg: String| CheckpointError::Format { path: path.display().to_string(), msg };
        let mut b = Vec::new();
        std::fs::File::open(path)
            .and_then(|mut f| f.read_to_end(&mut b))
            .map_err(|source| CheckpointError::Io { path: path.display().to_string(), source })?;
        if b.len() < 64 || ![MAGIC, MAGIC_V2, MAGIC_V1].iter().any(|m| &b[..8] == *m) {
            return Err(fmt("not a pav checkpoint".into()));
        }
        let (v3, checksum) = (&b[..8] == MAGIC, &b[..8] != MAGIC_V1);
        let n = u64::from_le_bytes(b[40..48].try_into().unwrap_or([0; 8])) as usize;
        let body = 64;
        let moments_end = n.saturating_mul(12).saturating_add(body);
        // Version 3: the average's count and length, then its values, between the moments and the checksum.
        let avg_len = if v3 && b.len() >= moments_end.saturating_add(16) {
            u64::from_le_bytes(b[moments_end + 8..moments_end + 16].try_into().unwrap_or([0; 8])) as usize
        } else {
            0
        };
        let avg_bytes = if v3 { avg_len.saturating_mul(4).saturating_add(16) } else { 0 };
        let expected = moments_end.saturating_add(avg_bytes).saturating_add(if checksum { 8 } else { 0 });
        if b.len() != expected {
            return Err(fmt(format!("{} bytes, expected {expected} for {n} values (truncated?)", b.len())));
        }
        if checksum {
            let (data, sum) = b.split_at(b.len() - 8);
            if fingerprint(data).to_le_bytes() != sum {
                return Err(fmt("checksum mismatch: the file is damaged; remove it to start over".into()));
            }
        }
        let u = |i: usize| u64::from_le_bytes(b[8 + 8 * i..16 + 8 * i].try_into().unwrap());
        let f = |i: usize| f32::from_le_bytes(b[48 + 4 * i..52 + 4 * i].try_into().unwrap());
        let f32s = |from: usize, len: usize| -> Vec<f32> {
            b[from..from + 4 * len].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
        };
        let arr = |k: usize| f32s(body + 4 * n * k, n);
        let average = if v3 {
            Average {
                count: u64::from_le_bytes(b[moments_end..moments_end + 8].try_into().unwrap()),
                sum: f32s(moments_end + 16, avg_len),
            }
        } else {
            Average::default()
        };
        Ok(Checkpoint {
            config_hash: u(0),
            steps_done: u(1),
            rng_state: u(2),
            params: arr(0),
            adam: Adam { lr: f(0), beta1: f(1), beta2: f(2), eps: f(3), t: u(3), m: arr(1), v: arr(2) },
            average,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(average: Average) -> Checkpoint {
        let mut adam = Adam::new(4, 0.015);
        adam.t = 7;
        adam.m = vec![0.1, -0.2, 0.0, 1e-9];
        adam.v[2] = 3.5;
        Checkpoint {
            config_hash: 99,
            steps_done: 12,
            rng_state: 0xdead_beef,
            params: vec![0.5, 0.25, 1e-4, 0.9999],
            adam,
            average,
        }
    }

    #[test]
    fn round_trip_and_truncation_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.bin");
        let mut average = Average::default();
        average.add(&[0.25, 0.5, 1.0, 0.0, 0.125, 0.75]);
        average.add(&[0.75, 0.5, 0.0, 1.0, 0.125, 0.25]);
        assert_eq!(average.mean().unwrap(), [0.5, 0.5, 0.5, 0.5, 0.125, 0.5]);
        let c = sample(average);
        c.save(&p).unwrap();
        assert_eq!(Checkpoint::load(&p).unwrap(), c);
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 3]).unwrap();
        let e = Checkpoint::load(&p).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        // One flipped bit anywhere is refused, in the average's values too.
        for at in [70, bytes.len() - 12] {
            let mut flipped = bytes.clone();
            flipped[at] ^= 0x10;
            std::fs::write(&p, &flipped).unwrap();
            let e = Checkpoint::load(&p).unwrap_err().to_string();
            assert!(e.contains("checksum"), "byte {at}: {e}");
        }
        std::fs::write(&p, b"hello").unwrap();
        assert!(Checkpoint::load(&p).unwrap_err().to_string().contains("not a pav checkpoint"));
        assert_ne!(fingerprint(b"lr = 0.015"), fingerprint(b"lr = 0.001"));
    }

    #[test]
    fn older_versions_load_without_an_average() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.bin");
        let c = sample(Average::default());
        c.save(&p).unwrap();
        let v3 = std::fs::read(&p).unwrap();
        // Version 2: no average section (count and length, 16 bytes), its own checksum.
        let mut v2 = v3[..v3.len() - 8 - 16].to_vec();
        v2[..8].copy_from_slice(MAGIC_V2);
        let sum = fingerprint(&v2);
        v2.extend_from_slice(&sum.to_le_bytes());
        std::fs::write(&p, &v2).unwrap();
        assert_eq!(Checkpoint::load(&p).unwrap(), c);
        // Version 1: no checksum either.
        let mut v1 = v2[..v2.len() - 8].to_vec();
        v1[..8].copy_from_slice(MAGIC_V1);
        std::fs::write(&p, &v1).unwrap();
        assert_eq!(Checkpoint::load(&p).unwrap(), c);
        // A version-3 file is not read as an older one: its length says so.
        let mut relabelled = v3.clone();
        relabelled[..8].copy_from_slice(MAGIC_V2);
        assert!(Checkpoint::load(&p).is_ok());
        std::fs::write(&p, &relabelled).unwrap();
        assert!(Checkpoint::load(&p).unwrap_err().to_string().contains("bytes, expected"));
    }
}
