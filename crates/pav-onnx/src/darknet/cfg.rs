//! Parser for darknet `.cfg` network descriptions (the subset YOLOv3/YOLOv3-tiny use).

use super::DarknetError;
use std::collections::BTreeMap;
use std::path::Path;

/// DarknetActivation after a convolution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DarknetActivation {
    /// Identity.
    Linear,
    /// Leaky ReLU with slope 0.1 (darknet's fixed value).
    Leaky,
}

/// One YOLO detection head.
#[derive(Clone, Debug, PartialEq)]
pub struct YoloHead {
    /// Anchors (w, h) in network-input pixels used by this head, in mask order.
    pub anchors: Vec<(f32, f32)>,
    /// Number of classes.
    pub classes: usize,
}

/// A darknet layer, with its resolved shape parameters.
#[derive(Clone, Debug, PartialEq)]
pub enum Layer {
    /// `[convolutional]`.
    Conv {
        /// Output channels.
        filters: usize,
        /// Square kernel size.
        size: usize,
        /// Stride.
        stride: usize,
        /// Zero padding on each side.
        pad: usize,
        /// Whether batch normalization follows (and is stored in the weights).
        batch_normalize: bool,
        /// DarknetActivation.
        activation: DarknetActivation,
    },
    /// `[maxpool]`.
    MaxPool {
        /// Window size.
        size: usize,
        /// Stride.
        stride: usize,
    },
    /// `[upsample]` (nearest neighbour).
    Upsample {
        /// Integer scale factor.
        stride: usize,
    },
    /// `[route]`: concatenation of earlier layers along channels (absolute indices).
    Route {
        /// Source layers, absolute 0-based.
        layers: Vec<usize>,
    },
    /// `[yolo]`: decoding head over the previous layer's output.
    Yolo(YoloHead),
}

/// A parsed network: input size and layers.
#[derive(Clone, Debug)]
pub struct Network {
    /// Input width in pixels.
    pub width: usize,
    /// Input height in pixels.
    pub height: usize,
    /// Input channels.
    pub channels: usize,
    /// Layers in darknet order.
    pub layers: Vec<Layer>,
}

struct Section {
    kind: String,
    line: usize,
    kv: BTreeMap<String, (String, usize)>,
}

fn parse_sections(text: &str, path: &str) -> Result<Vec<Section>, DarknetError> {
    let mut out: Vec<Section> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split(['#', ';']).next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        if let Some(rest) = line.strip_prefix('[') {
            let kind = rest.strip_suffix(']').ok_or_else(|| DarknetError::Cfg {
                path: path.into(),
                line: i + 1,
                msg: format!("unterminated section header `{line}`"),
            })?;
            out.push(Section { kind: kind.trim().to_string(), line: i + 1, kv: BTreeMap::new() });
        } else {
            let (k, v) = line.split_once('=').ok_or_else(|| DarknetError::Cfg {
                path: path.into(),
                line: i + 1,
                msg: format!("expected `key=value`, found `{line}`"),
            })?;
            let sec = out.last_mut().ok_or_else(|| DarknetError::Cfg {
                path: path.into(),
                line: i + 1,
                msg: "option before the first [section]".into(),
            })?;
            sec.kv.insert(k.trim().to_string(), (v.trim().to_string(), i + 1));
        }
    }
    Ok(out)
}

impl Section {
    fn get<T: std::str::FromStr>(&self, key: &str, default: Option<T>, path: &str) -> Result<T, DarknetError> {
        match self.kv.get(key) {
            Some((v, line)) => v.parse().map_err(|_| DarknetError::Cfg {
                path: path.into(),
                line: *line,
                msg: format!("[{}] {key}={v} is not a valid value", self.kind),
            }),
            None => default.ok_or_else(|| DarknetError::Cfg {
                path: path.into(),
                line: self.line,
                msg: format!("[{}] needs `{key}`", self.kind),
            }),
        }
    }
    fn list<T: std::str::FromStr>(&self, key: &str, path: &str) -> Result<Vec<T>, DarknetError> {
        let (v, line) = self.kv.get(key).ok_or_else(|| DarknetError::Cfg {
            path: path.into(),
            line: self.line,
            msg: format!("[{}] needs `{key}`", self.kind),
        })?;
        v.split(',')
            .map(|s| s.trim())
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse().map_err(|_| DarknetError::Cfg {
                    path: path.into(),
                    line: *line,
                    msg: format!("[{}] {key}: `{s}` is not a number", self.kind),
                })
            })
            .collect()
    }
}

impl Network {
    /// Reads and parses a `.cfg` file.
    pub fn from_file(path: &Path) -> Result<Self, DarknetError> {
        let text = std::fs::read_to_string(path).map_err(|source| DarknetError::Io { path: path.into(), source })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses cfg text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, DarknetError> {
        let sections = parse_sections(text, origin)?;
        let (net, rest) = sections.split_first().ok_or_else(|| DarknetError::Cfg {
            path: origin.into(),
            line: 0,
            msg: "empty cfg".into(),
        })?;
        if net.kind != "net" && net.kind != "network" {
            return Err(DarknetError::Cfg {
                path: origin.into(),
                line: net.line,
                msg: format!("first section must be [net], found [{}]", net.kind),
            });
        }
        let width = net.get("width", None, origin)?;
        let height = net.get("height", None, origin)?;
        let channels = net.get("channels", Some(3), origin)?;
        let mut layers = Vec::with_capacity(rest.len());
        for (index, s) in rest.iter().enumerate() {
            let layer = match s.kind.as_str() {
                "convolutional" => {
                    let size: usize = s.get("size", Some(1), origin)?;
                    let pad_flag: usize = s.get("pad", Some(0), origin)?;
                    let padding: usize = s.get("padding", Some(0), origin)?;
                    let activation = match s.get::<String>("activation", Some("logistic".into()), origin)?.as_str() {
                        "linear" => DarknetActivation::Linear,
                        "leaky" => DarknetActivation::Leaky,
                        other => {
                            return Err(DarknetError::Unsupported {
                                index,
                                kind: s.kind.clone(),
                                msg: format!("activation `{other}`"),
                            })
                        }
                    };
                    Layer::Conv {
                        filters: s.get("filters", None, origin)?,
                        size,
                        stride: s.get("stride", Some(1), origin)?,
                        // darknet: `pad=1` means "same" padding (size/2) and overrides `padding`.
                        pad: if pad_flag != 0 { size / 2 } else { padding },
                        batch_normalize: s.get::<usize>("batch_normalize", Some(0), origin)? != 0,
                        activation,
                    }
                }
                "maxpool" => {
                    let size = s.get("size", Some(1), origin)?;
                    let stride = s.get("stride", Some(1), origin)?;
                    Layer::MaxPool { size, stride }
                }
                "upsample" => Layer::Upsample { stride: s.get("stride", Some(2), origin)? },
                "route" => {
                    let rel: Vec<i64> = s.list("layers", origin)?;
                    let mut abs = Vec::with_capacity(rel.len());
                    for r in rel {
                        let a = if r < 0 { index as i64 + r } else { r };
                        if a < 0 || a >= index as i64 {
                            return Err(DarknetError::Cfg {
                                path: origin.into(),
                                line: s.line,
                                msg: format!("[route] at layer {index} refers to layer {a}, which is not before it"),
                            });
                        }
                        abs.push(a as usize);
                    }
                    Layer::Route { layers: abs }
                }
                "yolo" => {
                    let mask: Vec<usize> = s.list("mask", origin)?;
                    let flat: Vec<f32> = s.list("anchors", origin)?;
                    if flat.len() % 2 != 0 {
                        return Err(DarknetError::Cfg {
                            path: origin.into(),
                            line: s.line,
                            msg: "[yolo] anchors must come in (w,h) pairs".into(),
                        });
                    }
                    let all: Vec<(f32, f32)> = flat.chunks(2).map(|c| (c[0], c[1])).collect();
                    let anchors = mask
                        .iter()
                        .map(|&m| {
                            all.get(m).copied().ok_or_else(|| DarknetError::Cfg {
                                path: origin.into(),
                                line: s.line,
                                msg: format!("[yolo] mask {m} but only {} anchors", all.len()),
                            })
                        })
                        .collect::<Result<_, _>>()?;
                    let scale: f32 = s.get("scale_x_y", Some(1.0), origin)?;
                    if scale != 1.0 {
                        return Err(DarknetError::Unsupported {
                            index,
                            kind: s.kind.clone(),
                            msg: format!("scale_x_y={scale}"),
                        });
                    }
                    Layer::Yolo(YoloHead { anchors, classes: s.get("classes", None, origin)? })
                }
                other => {
                    return Err(DarknetError::Unsupported { index, kind: other.into(), msg: "unknown section".into() })
                }
            };
            layers.push(layer);
        }
        Ok(Network { width, height, channels, layers })
    }

    /// Output channels of every layer, in order (needed to size convolution weights).
    pub fn channels_per_layer(&self) -> Vec<usize> {
        let mut out: Vec<usize> = Vec::with_capacity(self.layers.len());
        for layer in &self.layers {
            let prev = out.last().copied().unwrap_or(self.channels);
            out.push(match layer {
                Layer::Conv { filters, .. } => *filters,
                Layer::Route { layers } => layers.iter().map(|&l| out[l]).sum(),
                _ => prev,
            });
        }
        out
    }

    /// Indices of the `[yolo]` layers with their heads.
    pub fn heads(&self) -> Vec<(usize, &YoloHead)> {
        self.layers
            .iter()
            .enumerate()
            .filter_map(|(i, l)| match l {
                Layer::Yolo(h) => Some((i, h)),
                _ => None,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TINY: &str = "[net]\nwidth=32\nheight=32\nchannels=3\n\n[convolutional]\nbatch_normalize=1\nfilters=4\nsize=3\nstride=1\npad=1\nactivation=leaky\n\n[maxpool]\nsize=2\nstride=2\n\n[convolutional]\nfilters=6\nsize=1\npad=1\nactivation=linear\n[yolo]\nmask=0\nanchors=10,14, 23,27\nclasses=1\n[route]\nlayers=-3\n[upsample]\nstride=2\n[route]\nlayers=-1,0\n";

    #[test]
    fn parses_layers_with_darknet_padding_rule() {
        let n = Network::parse(TINY, "t").unwrap();
        assert_eq!((n.width, n.height, n.channels), (32, 32, 3));
        assert_eq!(n.layers.len(), 7);
        // size=1 with pad=1 gives no padding (size/2 = 0).
        assert!(matches!(n.layers[2], Layer::Conv { pad: 0, filters: 6, .. }));
        assert!(matches!(n.layers[0], Layer::Conv { pad: 1, batch_normalize: true, .. }));
        assert_eq!(n.layers[4], Layer::Route { layers: vec![1] });
        assert_eq!(n.layers[6], Layer::Route { layers: vec![5, 0] });
        assert_eq!(n.channels_per_layer(), vec![4, 4, 6, 6, 4, 4, 8]);
        assert_eq!(n.heads()[0].1.anchors, vec![(10.0, 14.0)]);
    }

    #[test]
    fn bad_input_names_the_line() {
        let e = Network::parse("[net]\nwidth=a\nheight=3", "x.cfg").unwrap_err().to_string();
        assert!(e.contains("x.cfg:2"), "{e}");
        let e = Network::parse("[net]\nwidth=3\nheight=3\n[route]\nlayers=-1", "x.cfg").unwrap_err().to_string();
        assert!(e.contains("not before it"), "{e}");
        let e = Network::parse("[net]\nwidth=3\nheight=3\n[shortcut]\nfrom=-3", "x.cfg").unwrap_err().to_string();
        assert!(e.contains("[shortcut]"), "{e}");
    }
}
