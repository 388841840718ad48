//! Reader for darknet `.weights` files, with batch norm folded into the convolutions.

use super::cfg::{Layer, Network};
use super::DarknetError;
use std::path::Path;

/// Batch-norm epsilon used when folding (OpenCV's darknet importer uses the same value).
const BN_EPS: f32 = 1e-6;

/// Folded convolution parameters for one `[convolutional]` layer.
#[derive(Clone, Debug)]
pub struct ConvWeights {
    /// Layer index in the network.
    pub layer: usize,
    /// Kernel, OIHW row-major (filters × in_channels × size × size).
    pub weight: Vec<f32>,
    /// Bias per output channel (batch norm folded in).
    pub bias: Vec<f32>,
    /// Shape (out, in, k, k).
    pub shape: [usize; 4],
}

/// All convolution weights of a network, in layer order.
#[derive(Clone, Debug)]
pub struct Weights {
    /// One entry per `[convolutional]` layer.
    pub convs: Vec<ConvWeights>,
}

impl Weights {
    /// Reads `path` and checks that its size matches `net` exactly.
    pub fn from_file(path: &Path, net: &Network) -> Result<Self, DarknetError> {
        let bytes = std::fs::read(path).map_err(|source| DarknetError::Io { path: path.into(), source })?;
        Self::parse(&bytes, net, &path.display().to_string())
    }

    /// Parses weights bytes for `net`; `origin` names the file in errors.
    pub fn parse(bytes: &[u8], net: &Network, origin: &str) -> Result<Self, DarknetError> {
        let err = |msg: String| DarknetError::Weights { path: origin.into(), msg };
        if bytes.len() < 16 {
            return Err(err(format!("{} bytes is too short for a header", bytes.len())));
        }
        let word = |i: usize| i32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().expect("4 bytes"));
        let (major, minor) = (word(0), word(1));
        // Header: major, minor, revision (int32), then `seen` as int64 from format 0.2 on.
        let header = if major * 10 + minor >= 2 { 20 } else { 16 };
        let body = &bytes[header.min(bytes.len())..];
        if body.len() % 4 != 0 {
            return Err(err(format!("body of {} bytes is not a whole number of float32", body.len())));
        }
        let floats: Vec<f32> =
            body.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect();
        let chans = net.channels_per_layer();
        let mut pos = 0usize;
        let mut take = |n: usize, what: &str, layer: usize| -> Result<Vec<f32>, DarknetError> {
            let end = pos + n;
            if end > floats.len() {
                return Err(err(format!(
                    "file ends inside layer {layer} ({what}): needs {} floats, has {}",
                    end,
                    floats.len()
                )));
            }
            let v = floats[pos..end].to_vec();
            pos = end;
            Ok(v)
        };
        let mut convs = Vec::new();
        for (i, layer) in net.layers.iter().enumerate() {
            let Layer::Conv { filters, size, batch_normalize, .. } = *layer else {
                continue;
            };
            let cin = if i == 0 { net.channels } else { chans[i - 1] };
            let mut bias = take(filters, "biases", i)?;
            let bn = if batch_normalize {
                Some((take(filters, "bn scales", i)?, take(filters, "bn means", i)?, take(filters, "bn variances", i)?))
            } else {
                None
            };
            let per_filter = cin * size * size;
            let mut weight = take(filters * per_filter, "kernel", i)?;
            if let Some((scale, mean, var)) = bn {
                for f in 0..filters {
                    let inv = scale[f] / (var[f] + BN_EPS).sqrt();
                    for w in &mut weight[f * per_filter..(f + 1) * per_filter] {
                        *w *= inv;
                    }
                    bias[f] -= mean[f] * inv;
                }
            }
            if let Some(bad) = weight.iter().chain(bias.iter()).find(|v| !v.is_finite()) {
                return Err(err(format!("layer {i} has a non-finite parameter ({bad}) after folding")));
            }
            convs.push(ConvWeights { layer: i, weight, bias, shape: [filters, cin, size, size] });
        }
        if pos != floats.len() {
            return Err(err(format!(
                "{} floats left over after the last layer: the weights do not belong to this cfg",
                floats.len() - pos
            )));
        }
        Ok(Weights { convs })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn net() -> Network {
        Network::parse(
            "[net]\nwidth=4\nheight=4\nchannels=1\n[convolutional]\nbatch_normalize=1\nfilters=1\nsize=1\nactivation=linear\n",
            "t",
        )
        .unwrap()
    }

    fn file(vals: &[f32]) -> Vec<u8> {
        let mut b = Vec::new();
        for h in [0i32, 2, 0] {
            b.extend_from_slice(&h.to_le_bytes());
        }
        b.extend_from_slice(&0i64.to_le_bytes());
        for v in vals {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b
    }

    #[test]
    fn folds_batch_norm() {
        // beta=0.5, gamma=2, mean=1, var=4, w=3  =>  w' = 3*2/2 = 3, b' = 0.5 - 1*1 = -0.5
        let w = Weights::parse(&file(&[0.5, 2.0, 1.0, 4.0, 3.0]), &net(), "t").unwrap();
        assert!((w.convs[0].weight[0] - 3.0).abs() < 1e-5);
        assert!((w.convs[0].bias[0] + 0.5).abs() < 1e-5);
    }

    #[test]
    fn size_mismatch_is_an_error() {
        let short = Weights::parse(&file(&[0.5, 2.0, 1.0]), &net(), "t").unwrap_err().to_string();
        assert!(short.contains("ends inside layer 0"), "{short}");
        let long = Weights::parse(&file(&[0.5, 2.0, 1.0, 4.0, 3.0, 9.0]), &net(), "t").unwrap_err().to_string();
        assert!(long.contains("left over"), "{long}");
        let nan = Weights::parse(&file(&[0.5, 2.0, 1.0, -1.0, 3.0]), &net(), "t").unwrap_err().to_string();
        assert!(nan.contains("non-finite"), "{nan}");
    }
}
