//! `pav data fetch` without the internet: a mirror served over HTTP on the loopback address fills
//! an empty store with real data files, verified, and a corrupted file is refused and never lands.

use crate::common;
use crate::common::pav;

use std::io::{BufRead, BufReader, Write};
use std::net::TcpListener;
use std::path::{Path, PathBuf};

/// Serves the files under `root` (GET only, one connection at a time, 404 for what is absent)
/// on a loopback port until the test process ends; returns the base URL.
fn serve(root: PathBuf) -> String {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { continue };
            let mut line = String::new();
            let mut reader = BufReader::new(stream.try_clone().unwrap());
            if reader.read_line(&mut line).is_err() {
                continue;
            }
            // Drain the headers.
            let mut h = String::new();
            while reader.read_line(&mut h).map(|n| n > 2).unwrap_or(false) {
                h.clear();
            }
            let path = line.split_whitespace().nth(1).unwrap_or("/").trim_start_matches('/').to_string();
            let file = root.join(&path);
            let reply = match std::fs::read(&file) {
                Ok(body) if !path.contains("..") => {
                    let mut r =
                        format!("HTTP/1.1 200 OK\r\nContent-Length: {}\r\nConnection: close\r\n\r\n", body.len())
                            .into_bytes();
                    r.extend(body);
                    r
                }
                _ => b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n".to_vec(),
            };
            let _ = stream.write_all(&reply);
        }
    });
    format!("http://127.0.0.1:{port}")
}

fn copy(from: &Path, to: &Path, name: &str) {
    std::fs::create_dir_all(to.join(name).parent().unwrap()).unwrap();
    std::fs::copy(from.join(name), to.join(name)).unwrap();
}

#[test]
fn a_loopback_mirror_fills_an_empty_store_and_a_corrupt_file_is_refused() {
    let data = common::shared_data();
    let (mirror, store) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let good = ["models-yolox/coco_classes.txt", "fca/carla_dataset/masks/data12501.png", "das/all_faces.txt"];
    for n in good {
        copy(&data, mirror.path(), n);
    }
    // One flipped byte: same size, other hash.
    let corrupt = "fca/carla_dataset/test/data12501.npz";
    copy(&data, mirror.path(), corrupt);
    let mut bytes = std::fs::read(mirror.path().join(corrupt)).unwrap();
    bytes[1000] ^= 0x01;
    std::fs::write(mirror.path().join(corrupt), bytes).unwrap();
    let absent = "das/smile.jpg";
    let url = serve(mirror.path().to_path_buf());

    let out = pav()
        .args(["data", "fetch", "--mirror", &url])
        .args(good)
        .args([corrupt, absent, "fca/carla_dataset/derived_test_labels.tsv"])
        .env("PAV_DATA", store.path())
        .output()
        .unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(!out.status.success(), "a refused file must fail the fetch: {text}");
    assert!(text.contains("4 written, 0 already present, 2 failed"), "{text}");
    assert!(text.contains(&format!("{corrupt} from {url}/{corrupt}")) && text.contains("refused"), "{text}");
    assert!(text.contains(absent) && text.contains("404"), "{text}");
    for n in good {
        assert_eq!(std::fs::read(store.path().join(n)).unwrap(), std::fs::read(data.join(n)).unwrap(), "{n}");
    }
    assert!(!store.path().join(corrupt).exists(), "a refused file never lands");
    let leftovers: Vec<_> = walk(store.path()).into_iter().filter(|p| p.to_string_lossy().contains(".part")).collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // The shipped table comes from pav itself.
    assert!(store.path().join("fca/carla_dataset/derived_test_labels.tsv").is_file());

    let list =
        pav().args(["data", "list", "fca/carla_dataset/test", "das"]).env("PAV_DATA", store.path()).output().unwrap();
    let list = String::from_utf8_lossy(&list.stdout);
    assert!(list.contains("1 present, 12 missing, 0 corrupt"), "{list}");

    // Damage a stored file: `list` says corrupt, and a second fetch replaces it and keeps the rest.
    std::fs::write(store.path().join("das/all_faces.txt"), "1 2 3").unwrap();
    let list = pav().args(["data", "list", "das/all_faces.txt"]).env("PAV_DATA", store.path()).output().unwrap();
    assert!(String::from_utf8_lossy(&list.stdout).contains("corrupt ("), "{}", String::from_utf8_lossy(&list.stdout));
    let again =
        pav().args(["data", "fetch", "--mirror", &url]).args(good).env("PAV_DATA", store.path()).output().unwrap();
    let text = String::from_utf8_lossy(&again.stdout);
    assert!(again.status.success() && text.contains("1 written, 2 already present, 0 failed"), "{text}");
}

#[test]
fn without_the_data_a_config_fails_naming_the_fetch_command() {
    let empty = tempfile::tempdir().unwrap();
    let out = pav()
        .args(["render", "-o"])
        .arg(empty.path().join("r.png"))
        .env("PAV_DATA", empty.path())
        .current_dir(common::repo())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("pav-camou/xfl_yxz.obj is missing") && err.contains("pav data fetch pav-camou/xfl_yxz.obj"),
        "{err}"
    );
    let out = pav().args(["data", "path", "nope/x.bin"]).env("PAV_DATA", empty.path()).output().unwrap();
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("not in pav's data manifest"));
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}
