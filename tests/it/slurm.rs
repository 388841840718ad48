//! A real Slurm: scripts/cluster/local-slurm.sh starts a single-node cluster in a temporary folder
//! (its own MUNGE key and socket, slurmctld and slurmd on free ports), `pav cluster slurm` writes
//! the job array and its merge job for a crossval (two folds x two seeds) and for an evaluate of
//! three videos, one array task is requeued while it optimizes, and the merged results are the
//! one-process results byte for byte (timings aside). Every daemon is stopped at the end, also
//! when the test fails. A machine where Slurm cannot start fails this test with the reason.

use crate::common;
use crate::common::{pav, pav_rig};

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// A running local cluster; dropping it stops its daemons.
struct Cluster {
    dir: tempfile::TempDir,
}

impl Cluster {
    fn start() -> Cluster {
        let dir = tempfile::tempdir().unwrap();
        let o = Command::new("bash").arg(script()).arg("start").arg(dir.path()).output().unwrap();
        let c = Cluster { dir };
        assert!(o.status.success(), "Slurm did not start on this machine:\n{}", common::output_text(&o));
        c
    }

    fn conf(&self) -> PathBuf {
        self.dir.path().join("slurm.conf")
    }

    /// A Slurm client command (or any command that submits) pointed at this cluster.
    fn command(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", self.conf()).env("RUST_BACKTRACE", "0").current_dir(common::repo());
        c
    }

    fn queue_empty(&self) -> bool {
        let o = self.command("squeue").arg("-h").output().unwrap();
        assert!(o.status.success(), "squeue: {}", common::output_text(&o));
        o.stdout.is_empty()
    }

    /// Writes `command` as a 2-task array (1 CPU each) and its merge job into `jobs` with
    /// `pav cluster slurm`, submits both, and returns the array's job id.
    fn submit_array(&self, jobs: &Path, command: &[String]) -> String {
        run_ok(
            pav()
                .args(["cluster", "slurm", "--tasks", "2", "--cpus-per-task", "1", "--mem", "2G", "-o"])
                .arg(jobs)
                .arg("--")
                .args(command),
        );
        let o = self.command("bash").arg(jobs.join("submit.sh")).output().unwrap();
        assert!(o.status.success(), "{}", common::output_text(&o));
        // submit.sh prints `array ID, merge ID`.
        let ids = String::from_utf8_lossy(&o.stdout).to_string();
        ids.split_whitespace().nth(1).unwrap().trim_end_matches(',').to_string()
    }

    /// Waits until no job is queued or running; panics with the logs after `limit`.
    fn wait(&self, limit: Duration, logs: &Path) {
        let t = Instant::now();
        while !self.queue_empty() {
            if t.elapsed() > limit {
                panic!("jobs still queued after {limit:?}:\n{}", read_logs(logs));
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new("bash").arg(script()).arg("stop").arg(self.dir.path()).status();
    }
}

fn script() -> PathBuf {
    common::repo().join("scripts/cluster/local-slurm.sh")
}

fn read_logs(dir: &Path) -> String {
    let mut s = String::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        s.push_str(&format!("--- {}\n{}\n", e.path().display(), std::fs::read_to_string(e.path()).unwrap_or_default()));
    }
    s
}

fn run_ok(c: &mut Command) {
    let o = c.output().unwrap();
    assert!(o.status.success(), "{c:?}:\n{}", common::output_text(&o));
}

/// Every file under `a`, relative, except those `skip` names, with its bytes.
fn files(a: &Path, skip: &dyn Fn(&Path) -> bool) -> Vec<(PathBuf, Vec<u8>)> {
    fn walk(root: &Path, d: &Path, skip: &dyn Fn(&Path) -> bool, out: &mut Vec<(PathBuf, Vec<u8>)>) {
        for e in std::fs::read_dir(d).unwrap().flatten() {
            let rel = e.path().strip_prefix(root).unwrap().to_path_buf();
            if skip(&rel) {
                continue;
            }
            if e.path().is_dir() {
                walk(root, &e.path(), skip, out);
            } else {
                out.push((rel, std::fs::read(e.path()).unwrap()));
            }
        }
    }
    let mut out = Vec::new();
    walk(a, a, skip, &mut out);
    out.sort();
    out
}

/// Asserts the two folders hold the same files with the same bytes (after `strip`).
fn same_files(one: &Path, merged: &Path, skip: &dyn Fn(&Path) -> bool, strip: &dyn Fn(&Path, Vec<u8>) -> Vec<u8>) {
    let (a, b) = (files(one, skip), files(merged, skip));
    let names = |v: &[(PathBuf, Vec<u8>)]| v.iter().map(|f| f.0.clone()).collect::<Vec<_>>();
    assert_eq!(names(&a), names(&b), "the merged folder has other files than the one-process run");
    for ((name, x), (_, y)) in a.into_iter().zip(b) {
        assert!(
            strip(&name, x) == strip(&name, y),
            "{} differs between the one-process run and the merge",
            name.display()
        );
    }
}

#[test]
fn crossval_and_evaluate_run_as_slurm_arrays_and_merge_to_the_one_process_result() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    // Two photos, twelve one-photo epochs: a checkpoint every step, so a requeued task resumes.
    let cfg = t.join("tiny.toml");
    std::fs::write(
        &cfg,
        format!(
            "extends = {:?}\n[views]\ntrain = [\"data:fca/carla_dataset/test/data12501.npz\"]\ntest = [\"data:fca/carla_dataset/test/data12502.npz\"]\n[optimizer]\nepochs = 12\n",
            common::repo().join("configs/studies/half.toml").display().to_string()
        ),
    )
    .unwrap();
    let crossval = |out: &Path| -> Vec<String> {
        let mut v: Vec<String> = [env!("CARGO_BIN_EXE_pav"), "crossval", "--config"].map(String::from).to_vec();
        v.push(cfg.display().to_string());
        v.extend(
            ["--random-seeds", "1", "-d", "configs/detectors/yolov3-tiny.toml", "--seeds", "0,1", "-o"]
                .map(String::from),
        );
        v.push(out.display().to_string());
        v
    };
    let evaluate = |out: &Path| -> Vec<String> {
        let mut v: Vec<String> = [env!("CARGO_BIN_EXE_pav-rig"), "evaluate"].map(String::from).to_vec();
        v.extend(
            [
                "fixtures/turntable.mp4",
                "fixtures/carla_orbit.mp4",
                "fixtures/turntable.mp4",
                "--label",
                "a",
                "--label",
                "b",
            ]
            .map(String::from),
        );
        v.extend(["--label", "a", "-d", "configs/detectors/yolov3-tiny.toml", "--stride", "6", "-o"].map(String::from));
        v.push(out.display().to_string());
        v
    };
    // The one-process results.
    let line = |v: &[String]| {
        let mut c = Command::new(&v[0]);
        c.args(&v[1..]).current_dir(common::repo()).env("RUST_BACKTRACE", "0");
        c
    };
    run_ok(&mut line(&crossval(&t.join("cv-one"))));
    run_ok(&mut line(&evaluate(&t.join("ev-one"))));

    let cluster = Cluster::start();
    // The crossval as a 2-task array (1 CPU each) plus its merge.
    let jobs = t.join("cv-jobs");
    let array = cluster.submit_array(&jobs, &crossval(&t.join("cv")));
    // Requeue task 1 once it is optimizing (a fold with a checkpoint and no scores yet): Slurm
    // stops it and starts it again from the beginning of its script; pav resumes.
    let shard1 = t.join("cv/shard-1-of-2");
    let started = Instant::now();
    let mid_way = || {
        ["seed0", "seed1"].iter().any(|s| {
            let f = shard1.join(s).join("fold0of2");
            f.join("checkpoint.bin").exists() && !f.join("scores.json").exists()
        })
    };
    while !mid_way() {
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "task 1 never got to optimizing:\n{}",
            read_logs(&jobs.join("logs"))
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let o = cluster.command("scontrol").args(["requeue", &format!("{array}_1")]).output().unwrap();
    assert!(o.status.success(), "scontrol requeue: {}", common::output_text(&o));
    cluster.wait(Duration::from_secs(600), &jobs.join("logs"));
    let logs = read_logs(&jobs.join("logs"));
    assert!(
        logs.contains("task 1 of 2 on") && logs.contains("restart 1"),
        "task 1 ran once more after the requeue:\n{logs}"
    );
    assert!(t.join("cv/seed1/crossval.csv").is_file(), "the merge job did not write the tables:\n{logs}");
    // Timing aside (a fold's seconds, the optimizer's per-step and per-stage times and its
    // checkpoint), the merge is the one-process run.
    let timing = |p: &Path| {
        let n = p.file_name().unwrap().to_str().unwrap();
        n.starts_with("shard-")
            || ["run.toml", "loss.csv", "loss_detectors.csv", "loss_stages.csv", "checkpoint.bin", "scores.json"]
                .contains(&n)
    };
    let header_aside = |p: &Path, b: Vec<u8>| {
        if p.ends_with("crossval.md") {
            String::from_utf8(b).unwrap().lines().skip(1).collect::<Vec<_>>().join("\n").into_bytes()
        } else {
            b
        }
    };
    same_files(&t.join("cv-one"), &t.join("cv"), &timing, &header_aside);
    // Each seed's folder is a run of its own, with its seed in its record.
    let seed1 = std::fs::read_to_string(t.join("cv/seed1/run.toml")).unwrap();
    assert!(seed1.contains("seed = \"1\""), "{seed1}");
    // The scores themselves are the same too, the requeued fold's included.
    for f in ["seed0/fold0of2", "seed0/fold1of2", "seed1/fold0of2", "seed1/fold1of2"] {
        let read = |d: &Path| pav::studies::crossval::read_fold_scores(&d.join(f)).unwrap();
        let (a, b) = (read(&t.join("cv-one")), read(&t.join("cv")));
        assert_eq!(serde_json::to_string(&a.records).unwrap(), serde_json::to_string(&b.records).unwrap(), "{f}");
        assert_eq!(serde_json::to_string(&a.pooled).unwrap(), serde_json::to_string(&b.pooled).unwrap(), "{f}");
    }

    // The evaluate of three videos as a 2-task array: reports and plots as one process wrote them.
    let jobs = t.join("ev-jobs");
    cluster.submit_array(&jobs, &evaluate(&t.join("ev")));
    cluster.wait(Duration::from_secs(300), &jobs.join("logs"));
    assert!(
        t.join("ev/summary.csv").is_file(),
        "the merge job did not write the reports:\n{}",
        read_logs(&jobs.join("logs"))
    );
    let own = |p: &Path| p.starts_with("shard-1-of-2") || p.starts_with("shard-2-of-2") || p.ends_with("run.toml");
    same_files(&t.join("ev-one"), &t.join("ev"), &own, &|_, b| b);
    // The merge's run record says it joined two shards.
    let run = std::fs::read_to_string(t.join("ev/run.toml")).unwrap();
    assert!(run.contains("shards = \"2\""), "{run}");
    drop(cluster);
}

/// Merging refuses what cannot be one run's shards, naming them, and writes nothing: a missing
/// shard, a shard of another config, an unfinished shard. No cluster needed.
#[test]
fn merge_refuses_missing_foreign_and_unfinished_shards() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("ev");
    let ev = |extra: &[&str]| {
        let mut c = pav_rig();
        c.args([
            "evaluate",
            "fixtures/turntable.mp4",
            "fixtures/carla_orbit.mp4",
            "-d",
            "configs/detectors/yolov3-tiny.toml",
        ]);
        c.args(["--stride", "10", "--no-plots", "-o"]).arg(&out).args(extra);
        c.output().unwrap()
    };
    for bad in ["0/2", "3/2", "1/0"] {
        let o = ev(&["--shard", bad]);
        assert!(
            !o.status.success() && common::output_text(&o).contains(&format!("--shard {bad}")),
            "{}",
            common::output_text(&o)
        );
    }
    let o = ev(&["--shard", "1/2"]);
    assert!(o.status.success(), "{}", common::output_text(&o));
    let o = ev(&["--merge"]);
    let text = common::output_text(&o);
    assert!(!o.status.success() && text.contains("missing 1 of 2 shards: shard-2-of-2"), "{text}");
    assert!(!out.join("summary.csv").exists(), "nothing merged");
    // Shard 2 made with another threshold: another run.
    let o = ev(&["--shard", "2/2", "--threshold", "0.4"]);
    assert!(o.status.success(), "{}", common::output_text(&o));
    let text = common::output_text(&ev(&["--merge"]));
    assert!(text.contains("shard-2-of-2: its setting threshold is `0.4`, this merge's is `0.5`"), "{text}");
    // Shard 2 of this run, but cut short before it listed its videos.
    let o = ev(&["--shard", "2/2"]);
    assert!(o.status.success(), "{}", common::output_text(&o));
    std::fs::remove_file(out.join("shard-2-of-2/videos.json")).unwrap();
    let text = common::output_text(&ev(&["--merge"]));
    assert!(text.contains("shard-2-of-2: has not finished its videos"), "{text}");
    assert!(!out.join("summary.csv").exists(), "nothing merged");
    let o = ev(&["--shard", "2/2"]);
    assert!(o.status.success());
    let o = ev(&["--merge"]);
    assert!(o.status.success(), "{}", common::output_text(&o));
    let frames = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    let files: Vec<&str> = frames.lines().skip(1).map(|l| l.rsplit(',').next().unwrap()).collect();
    let first_orbit = files.iter().position(|f| *f == "carla_orbit.mp4").unwrap();
    assert!(
        files[..first_orbit].iter().all(|f| *f == "turntable.mp4")
            && files[first_orbit..].iter().all(|f| *f == "carla_orbit.mp4")
    );
}

/// `pav optimize --seeds`: each shard optimizes its seeds into its folder, the merge gathers
/// every seed's folder, and each texture is the one a single process makes; a run without
/// --seeds cannot be sharded.
#[test]
fn optimize_seeds_run_as_shards_and_gather() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let cfg = tmp.path().join("tiny.toml");
    std::fs::write(
        &cfg,
        format!(
            "extends = {:?}\n[views]\ntrain = [\"data:fca/carla_dataset/test/data12501.npz\"]\ntest = [\"data:fca/carla_dataset/test/data12502.npz\"]\n[optimizer]\nepochs = 2\n",
            common::repo().join("configs/studies/half.toml").display().to_string()
        ),
    )
    .unwrap();
    let opt = |out: &str, extra: &[&str]| {
        let mut c = pav();
        c.args(["optimize", "--config"]).arg(&cfg).args(["--seeds", "3,4", "-o"]).arg(tmp.path().join(out)).args(extra);
        c.output().unwrap()
    };
    for o in [opt("one", &[]), opt("sh", &["--shard", "1/2"])] {
        assert!(o.status.success(), "{}", common::output_text(&o));
    }
    let text = common::output_text(&opt("sh", &["--merge"]));
    assert!(
        text.contains("shard-1-of-2: has not finished seed 4") || text.contains("missing 1 of 2 shards: shard-2-of-2"),
        "{text}"
    );
    assert!(opt("sh", &["--shard", "2/2"]).status.success());
    let o = opt("sh", &["--merge"]);
    assert!(o.status.success(), "{}", common::output_text(&o));
    for s in ["seed3", "seed4"] {
        let read = |d: &str| std::fs::read(tmp.path().join(d).join(s).join("texture.png")).unwrap();
        assert_eq!(read("one"), read("sh"), "{s}'s texture");
    }
    assert_ne!(
        std::fs::read(tmp.path().join("one/seed3/texture.png")).unwrap(),
        std::fs::read(tmp.path().join("one/seed4/texture.png")).unwrap()
    );
    let o = pav().args(["optimize", "--config"]).arg(&cfg).args(["--shard", "1/2"]).output().unwrap();
    assert!(!o.status.success() && common::output_text(&o).contains("give them with --seeds"));
}
