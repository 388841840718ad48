//! Joining the folders of a sharded render, and a contact sheet of a folder's views.

use super::*;
use pav_run::shard::{Shard, ShardError};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Joins the shards of a view set (found and checked by `shard::find_checked`) into `out`:
/// every shard's images linked into `out/views`, and one `manifest.csv` in the order one process
/// renders them (environment by environment, grid views before plate views). Refused before
/// anything is linked: a view of the config that no shard rendered (named with its shard), or one
/// that two shards list. Returns the number of views.
pub fn merge_shards(cfg: &ViewsConfig, shards: &[(Shard, PathBuf)], out: &Path) -> Result<usize, ViewsError> {
    let all = cfg.views();
    let order: HashMap<&str, (usize, bool, usize)> =
        all.iter().enumerate().map(|(i, v)| (v.name.as_str(), (v.environment, v.plate.is_some(), i))).collect();
    let mut rows: HashMap<String, (ViewRecord, PathBuf)> = HashMap::new();
    for (_, dir) in shards {
        let manifest = manifest_path(dir);
        let listed = if manifest.exists() { read_manifest(&manifest)? } else { Vec::new() };
        for row in listed.into_iter().filter(|r| dir.join(&r.image).exists()) {
            if !order.contains_key(row.name.as_str()) {
                return Err(ViewsError::Config {
                    path: manifest.clone(),
                    msg: format!("view {} is not one of the config's", row.name),
                });
            }
            if let Some((_, other)) = rows.get(&row.name) {
                return Err(ShardError::Duplicate {
                    what: format!("view {}", row.name),
                    a: other.clone(),
                    b: dir.clone(),
                }
                .into());
            }
            rows.insert(row.name.clone(), (row, dir.clone()));
        }
    }
    if let Some((i, v)) = all.iter().enumerate().find(|(_, v)| !rows.contains_key(&v.name)) {
        let dir = pav_run::shard::owner_dir(shards, i);
        let missing = all.iter().filter(|v| !rows.contains_key(&v.name)).count();
        let what = format!("view {} ({missing} of {} views missing)", v.name, all.len());
        return Err(ShardError::Unfinished { shard: dir, what }.into());
    }
    for (_, dir) in shards {
        pav_run::shard::link_tree(&dir.join("views"), &out.join("views"))?;
    }
    if let Some((_, first)) = shards.first() {
        for f in ["views.toml", "mesh.obj"] {
            let to = out.join(f);
            let _ = std::fs::remove_file(&to);
            std::fs::copy(first.join(f), &to).map_err(io(&to))?;
        }
    }
    let mut rows: Vec<ViewRecord> = rows.into_values().map(|r| r.0).collect();
    rows.sort_by_key(|r| order[r.name.as_str()]);
    let path = manifest_path(out);
    write_manifest(&path, &rows)?;
    Ok(rows.len())
}

/// Writes `contact.png` in `dir`: up to `max` views of its manifest side by side, each beside
/// its mask, evenly picked, so a glance shows poses, lighting and alignment.
pub fn contact_sheet(dir: &Path, max: usize) -> Result<PathBuf, ViewsError> {
    let manifest = manifest_path(dir);
    let rows: Vec<(PathBuf, PathBuf)> = read_manifest(&manifest)?.into_iter().map(|r| (r.image, r.mask)).collect();
    let pick: Vec<&(PathBuf, PathBuf)> =
        if rows.len() <= max { rows.iter().collect() } else { (0..max).map(|k| &rows[k * rows.len() / max]).collect() };
    let mut tiles = Vec::new();
    let mut size = (0, 0);
    for (img, mask) in pick {
        for p in [img, mask] {
            let t = pav_core::image::Rgb::load(&dir.join(p))?;
            size = (t.width, t.height);
            tiles.push(t.rgb);
        }
    }
    let path = dir.join("contact.png");
    if tiles.is_empty() || tiles.iter().any(|t| t.len() != size.0 * size.1 * 3) {
        return Err(ViewsError::Config { path: manifest, msg: "no views of one size to show".into() });
    }
    let (w, h, px) = pav_core::image::tile(&tiles, size.0, size.1, 8, 1.0);
    pav_core::image::save_rgb(&path, w, h, &px)?;
    Ok(path)
}
