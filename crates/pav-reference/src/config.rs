//! The config-key reference: a Markdown page per kind of config file, written from the config
//! types' own JSON Schemas (schemars reads their serde attributes and doc comments), so that the
//! pages cannot drift from what the loaders take.

use crate::ReferenceError;
use serde_json::{Map, Value};
use std::fmt::Write as _;
use std::path::Path;

/// One kind of config file and the schema of its keys.
pub struct Page {
    /// The page's file name.
    pub file: &'static str,
    /// Its title.
    pub title: &'static str,
    /// What reads these files and where they live.
    pub intro: String,
    /// The JSON Schema of the file's root type.
    pub schema: schemars::Schema,
}

/// The config pages: optimize, scene, views, rig and detector configs.
pub fn pages() -> Vec<Page> {
    let extends = "`extends = \"base.toml\"` (relative to the file) starts from another file: tables \
                   merge key by key, and every value the file sets (arrays included) replaces the base's.";
    vec![
        Page {
            file: "config-optimize.md",
            title: "Optimize configs",
            intro: format!(
                "Read by `pav optimize`, `eval-digital`, `crossval`, `lofo` and `pav print pieces` \
                    (`configs/optimize/`, `configs/studies/`). Relative paths are relative to the file. {extends}"
            ),
            schema: schemars::schema_for!(pav_attack::config::OptimizeConfig),
        },
        Page {
            file: "config-scene.md",
            title: "Scene configs",
            intro: "The lighting and the effects drawn for each training step (`configs/scenes/`), named by an \
                    optimize config's `scene`."
                .into(),
            schema: schemars::schema_for!(pav_scene::Scene),
        },
        Page {
            file: "config-views.md",
            title: "Views configs",
            intro: "Read by `pav views render` (`configs/views/`): which views of the car Blender's Cycles \
                    renders. Relative paths are relative to the file."
                .into(),
            schema: schemars::schema_for!(pav_scene::views::ViewsConfig),
        },
        Page {
            file: "config-rig.md",
            title: "Rig configs",
            intro: format!(
                "The turntable rig as a scene (`configs/rig/`): read by `pav views turntable`, \
                    `pav views render` and `pav-rig simulate`. Relative paths are relative to the file. {extends}"
            ),
            schema: schemars::schema_for!(pav_scene::rig::RigConfig),
        },
        Page {
            file: "config-detector.md",
            title: "Detector configs",
            intro: format!(
                "How pav runs an ONNX detector (`configs/detectors/`): read by `pav-rig evaluate`, \
                    `pav eval-digital` and an optimize config's `white_box`; docs/detectors.md is the guide. \
                    Relative paths are relative to the file. {extends}"
            ),
            schema: pav_detect::DetectorConfig::schema(),
        },
    ]
}

/// Writes every config page into `dir`; returns the files. A page with an optional key whose
/// default its schema cannot show is refused, the others written.
pub fn write(dir: &Path) -> Result<Vec<String>, ReferenceError> {
    let write = |path: std::path::PathBuf, text: &str| {
        std::fs::create_dir_all(dir)
            .and_then(|()| std::fs::write(&path, text))
            .map_err(|source| ReferenceError::Write { path, source })
    };
    let (mut written, mut refused) = (Vec::new(), None);
    for p in pages() {
        match page(&p) {
            Ok(md) => {
                write(dir.join(p.file), &md)?;
                written.push(p.file.to_string());
            }
            Err(e) => refused = refused.or(Some(e)),
        }
    }
    refused.map_or(Ok(written), Err)
}

/// The schema's definitions, and what the page collects while it walks them.
struct Walk<'a> {
    defs: &'a Map<String, Value>,
    /// Tables still to describe: (TOML header, anchor, key path, schema).
    queue: Vec<(String, String, String, &'a Value)>,
    /// Value types with several forms, described once at the end: name → description.
    values: std::collections::BTreeMap<String, String>,
    /// Optional keys whose default the schema cannot show (their type has no `Serialize`).
    gaps: Vec<String>,
    /// Tables described so far: (definition, key path, anchor), so that a table holding its
    /// own kind (a description's `raw`) links back instead of nesting without end.
    opened: Vec<(String, String, String)>,
}

/// The Markdown of one page.
pub fn page(p: &Page) -> Result<String, ReferenceError> {
    let root = p.schema.as_value();
    let empty = Map::new();
    let defs = root.get("$defs").and_then(Value::as_object).unwrap_or(&empty);
    let mut w = Walk {
        defs,
        queue: vec![("Top level".into(), "top-level".into(), String::new(), root)],
        values: Default::default(),
        gaps: vec![],
        opened: vec![],
    };
    let mut md = format!("# {}\n\n{}\n\n", p.title, p.intro);
    let mut k = 0;
    while k < w.queue.len() {
        let (header, anchor, path, schema) = w.queue[k].clone();
        let _ = writeln!(md, "<a id=\"{anchor}\"></a>\n\n## {header}\n");
        let tagged = header.contains(" with ");
        md += &w.table(&path, (k > 0).then_some(anchor.as_str()), tagged, schema);
        k += 1;
    }
    if !w.values.is_empty() {
        md += "## Values\n\n";
        for (name, text) in &w.values {
            let _ = writeln!(md, "<a id=\"{}\"></a>\n\n### {name}\n\n{text}", name.to_lowercase());
        }
    }
    if !w.gaps.is_empty() {
        return Err(ReferenceError::NoDefault { page: p.file.to_string(), keys: w.gaps });
    }
    Ok(md.trim_end().to_string() + "\n")
}

/// One line of text for a table cell.
fn cell(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ").replace('|', "\\|")
}

/// A JSON value as TOML writes it.
fn toml_value(v: &Value) -> String {
    match v {
        Value::String(s) => format!("\"{s}\""),
        Value::Array(a) => format!("[{}]", a.iter().map(toml_value).collect::<Vec<_>>().join(", ")),
        Value::Object(o) => {
            format!(
                "{{ {} }}",
                o.iter().map(|(k, v)| format!("{k} = {}", toml_value(v))).collect::<Vec<_>>().join(", ")
            )
        }
        Value::Null => "absent".into(),
        // Config floats are f32: shown as the f32 they are (0.7, not 0.699999988079071).
        Value::Number(n) if n.is_f64() => {
            let x = n.as_f64().unwrap_or_default();
            if (x as f32) as f64 == x {
                format!("{:?}", x as f32)
            } else {
                format!("{x:?}")
            }
        }
        other => other.to_string(),
    }
}

/// The description of a schema, or of what it refers to.
fn description(v: &Value) -> &str {
    v.get("description").and_then(Value::as_str).unwrap_or("")
}

impl<'a> Walk<'a> {
    /// Follows `$ref`s: the schema and the name of the definition it came from.
    fn resolve(&self, v: &'a Value) -> (&'a Value, Option<String>) {
        match v.get("$ref").and_then(Value::as_str).and_then(|r| r.strip_prefix("#/$defs/")) {
            Some(name) => (self.resolve(&self.defs[name]).0, Some(name.to_string())),
            None => (v, None),
        }
    }

    /// The branches of a union, without its `null` (an optional value is the value).
    fn branches(&self, v: &'a Value) -> Vec<&'a Value> {
        let any = v.get("oneOf").or(v.get("anyOf")).and_then(Value::as_array);
        any.map(|b| b.iter().filter(|b| b.get("type") != Some(&Value::from("null"))).collect()).unwrap_or_default()
    }

    /// A union whose every branch is a table told apart by one constant key (`layout`, `kind`).
    fn tag(&self, v: &'a Value) -> Option<String> {
        let b = self.branches(v);
        let first = b.first().map(|b| self.resolve(b).0)?.get("properties")?.as_object()?;
        let key = first.iter().find(|(_, p)| p.get("const").is_some())?.0.clone();
        b.iter().all(|b| self.resolve(b).0.pointer(&format!("/properties/{key}/const")).is_some()).then_some(key)
    }

    /// The type column of a key at `path`; queues the tables it opens.
    fn ty(&mut self, path: &str, anchor: &str, v: &'a Value, array: bool) -> String {
        let (s, name) = self.resolve(v);
        let b = self.branches(s);
        if b.len() == 1 && s.get("properties").is_none() {
            return self.ty(path, anchor, b[0], array);
        }
        let (open, close) = if array { ("[[", "]]") } else { ("[", "]") };
        let anchor = anchor.to_string();
        if let Some(name) = &name {
            let outer = self.opened.iter().find(|(n, p, _)| n == name && path.starts_with(&format!("{p}.")));
            if let Some((_, p, a)) = outer {
                return format!("[table](#{a}), as `{p}` itself");
            }
            self.opened.push((name.clone(), path.to_string(), anchor.clone()));
        }
        if s.get("properties").is_some() {
            self.queue.push((format!("`{open}{path}{close}`"), anchor.clone(), path.to_string(), s));
            return format!("[table{}](#{anchor})", if array { "s" } else { "" });
        }
        if let Some(tag) = self.tag(s) {
            let mut links = Vec::new();
            for br in b {
                let br = self.resolve(br).0;
                let value = br.pointer(&format!("/properties/{tag}/const")).map(toml_value).unwrap_or_default();
                let a = format!("{anchor}-{}", value.trim_matches('"'));
                self.queue.push((
                    format!("`{open}{path}{close}` with `{tag} = {value}`"),
                    a.clone(),
                    path.to_string(),
                    br,
                ));
                links.push(format!("[{}](#{a})", value.trim_matches('"')));
            }
            return format!("table{} by `{tag}`: {}", if array { "s" } else { "" }, links.join(", "));
        }
        match s.get("type").and_then(|t| t.as_str().or_else(|| t.as_array()?.first()?.as_str())) {
            Some("array") => {
                let n = s.get("minItems").filter(|m| *m == s.get("maxItems").unwrap_or(&Value::Null));
                let item = s.get("items").unwrap_or(&Value::Null);
                if self.resolve(item).0.get("properties").is_some() || self.tag(self.resolve(item).0).is_some() {
                    return self.ty(path, &anchor, item, true);
                }
                let inner = self.ty(path, &anchor, item, false);
                match n {
                    Some(n) => format!("{n} × {inner}"),
                    None => format!("list of {inner}"),
                }
            }
            Some(t) if b.is_empty() && s.get("const").is_none() && s.get("enum").is_none() => t.into(),
            _ => self.value_type(s, name),
        }
    }

    /// A value of several forms (constants, numbers, small tables): its forms, inline when they
    /// are few constants, else in the page's Values section.
    fn value_type(&mut self, s: &'a Value, name: Option<String>) -> String {
        let forms: Vec<(String, String)> = if let Some(e) = s.get("enum").and_then(Value::as_array) {
            e.iter().map(|v| (toml_value(v), String::new())).collect()
        } else if let Some(c) = s.get("const") {
            vec![(toml_value(c), String::new())]
        } else {
            self.branches(s).into_iter().map(|b| (self.form(b), description(b).to_string())).collect()
        };
        let shown: Vec<&str> = forms.iter().map(|(f, _)| f.as_str()).collect();
        let Some(name) = name.filter(|_| forms.iter().any(|(_, d)| !d.is_empty())) else {
            return shown.iter().map(|f| format!("`{f}`")).collect::<Vec<_>>().join(", ");
        };
        let mut text = format!("{}\n\n", cell(description(s)));
        for (f, d) in &forms {
            let _ = writeln!(text, "- `{f}`{}", if d.is_empty() { String::new() } else { format!(": {}", cell(d)) });
        }
        self.values.insert(name.clone(), text);
        format!(
            "[{name}](#{}): {}",
            name.to_lowercase(),
            shown.iter().map(|f| format!("`{f}`")).collect::<Vec<_>>().join(", ")
        )
    }

    /// One form of a value, as it is written in TOML.
    fn form(&self, v: &'a Value) -> String {
        let (s, _) = self.resolve(v);
        if let Some(c) = s.get("const") {
            return toml_value(c);
        }
        if let Some(e) = s.get("enum").and_then(Value::as_array) {
            return e.iter().map(toml_value).collect::<Vec<_>>().join(" | ");
        }
        if let Some(p) = s.get("properties").and_then(Value::as_object) {
            let keys: Vec<String> = p.iter().map(|(k, v)| format!("{k} = {}", self.form(v))).collect();
            return format!("{{ {} }}", keys.join(", "));
        }
        let b = self.branches(s);
        if !b.is_empty() {
            return b.iter().map(|b| self.form(b)).collect::<Vec<_>>().join(" | ");
        }
        s.get("type").and_then(Value::as_str).unwrap_or("value").to_uppercase()
    }

    /// The table of the keys of the TOML table at `prefix`, required ones first, each in name
    /// order, its own tables anchored under `anchor` (none: the top level); a `tagged` table (one
    /// form of a union) leaves out the constant key that names it.
    fn table(&mut self, prefix: &str, anchor: Option<&str>, tagged: bool, s: &'a Value) -> String {
        let mut md = String::new();
        let d = description(s);
        // The root's description says what the page's introduction says.
        if !d.is_empty() && anchor.is_some() {
            let _ = writeln!(md, "{}\n", cell(d));
        }
        let Some(props) = s.get("properties").and_then(Value::as_object) else { return md };
        let required: Vec<&str> = s
            .get("required")
            .and_then(Value::as_array)
            .map(|r| r.iter().filter_map(Value::as_str).collect())
            .unwrap_or_default();
        let mut keys: Vec<&String> = props.keys().collect();
        keys.sort_by_key(|k| (!required.contains(&k.as_str()), k.to_string()));
        let _ = writeln!(md, "| key | type | default | meaning |\n|---|---|---|---|");
        for key in keys {
            let v = &props[key];
            if v.get("const").is_some() && tagged {
                continue;
            }
            let path = if prefix.is_empty() { key.clone() } else { format!("{prefix}.{key}") };
            let a = anchor.map_or(key.clone(), |a| format!("{a}-{key}"));
            let ty = self.ty(&path, &a, v, false);
            let nullable = v.get("type").and_then(Value::as_array).is_some_and(|t| t.contains(&Value::from("null")))
                || v.get("anyOf")
                    .and_then(Value::as_array)
                    .is_some_and(|b| b.iter().any(|b| b.get("type") == Some(&Value::from("null"))));
            let default = if required.contains(&key.as_str()) {
                "required".to_string()
            } else if let Some(d) = v.get("default").filter(|d| !d.is_null()) {
                format!("`{}`", toml_value(d))
            } else if nullable || v.get("default").is_some() {
                "absent".to_string()
            } else {
                self.gaps.push(path.clone());
                String::new()
            };
            let _ = writeln!(md, "| `{key}` | {ty} | {default} | {} |", cell(description(v)));
        }
        md + "\n"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A root.
    #[derive(serde::Deserialize, schemars::JsonSchema)]
    #[allow(dead_code)]
    struct Root {
        /// A number.
        #[serde(default = "half")]
        x: f32,
        /// Steps.
        #[serde(default)]
        step: Vec<Step>,
        /// A tree.
        node: Node,
    }

    fn half() -> f32 {
        0.5
    }

    /// One step.
    #[derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema)]
    #[serde(tag = "kind", rename_all = "snake_case")]
    #[allow(dead_code)]
    enum Step {
        /// Up.
        Up {
            /// How far.
            by: u32,
        },
        /// Down.
        Down {
            /// How far.
            by: u32,
        },
    }

    /// A node.
    #[derive(serde::Deserialize, schemars::JsonSchema)]
    #[allow(dead_code)]
    struct Node {
        /// Below.
        child: Option<Box<Node>>,
        /// Its side.
        #[serde(default)]
        side: Side,
    }

    /// A side, without `Serialize`: its default cannot be shown.
    #[derive(Default, serde::Deserialize, schemars::JsonSchema)]
    #[allow(dead_code)]
    enum Side {
        #[default]
        Left,
        Right,
    }

    fn page_of(schema: schemars::Schema) -> Result<String, ReferenceError> {
        page(&Page { file: "t.md", title: "T", intro: "Intro.".into(), schema })
    }

    #[test]
    fn keys_unions_and_nesting_are_written_and_a_hidden_default_refused() {
        match page_of(schemars::schema_for!(Root)) {
            Err(ReferenceError::NoDefault { keys, .. }) => assert_eq!(keys, vec!["node.side"]),
            other => panic!("{other:?}"),
        }
        #[derive(serde::Deserialize, schemars::JsonSchema)]
        #[allow(dead_code)]
        struct Shown {
            /// A number.
            #[serde(default = "half")]
            x: f32,
            /// Steps.
            #[serde(default)]
            step: Vec<Step>,
            /// Nested.
            inner: Option<Inner>,
        }
        /// Inner.
        #[derive(serde::Deserialize, schemars::JsonSchema)]
        #[allow(dead_code)]
        struct Inner {
            /// Again.
            again: Option<Box<Inner>>,
        }
        let md = page_of(schemars::schema_for!(Shown)).unwrap();
        assert!(md.contains("| `x` | number | `0.5` | A number. |"), "{md}");
        assert!(md.contains("tables by `kind`: [up](#step-up), [down](#step-down)"), "{md}");
        assert!(md.contains("## `[[step]]` with `kind = \"down\"`"), "{md}");
        assert!(md.contains("| `by` | integer | required | How far. |"), "{md}");
        assert!(md.contains("| `again` | [table](#inner), as `inner` itself | absent | Again. |"), "{md}");
    }
}
