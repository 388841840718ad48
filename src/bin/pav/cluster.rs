//! `pav cluster`.

use anyhow::{Context, Result};
use pav::cluster::ClusterJob;
use std::path::{Path, PathBuf};

#[derive(clap::Subcommand)]
pub enum Cmd {
    /// Write a Slurm job array for a shardable command (`pav crossval`, `pav-rig evaluate`,
    /// `pav views render`, `pav views turntable`, `pav optimize --seeds`): task K of N runs it with
    /// `--shard K/N`, a merge job runs it with `--merge` once every task succeeded. Writes
    /// array.sbatch, merge.sbatch and submit.sh into the folder; `bash <folder>/submit.sh` submits.
    #[command(after_help = "Examples:
  pav cluster slurm --tasks 6 --cpus-per-task 2 --mem 4G -o jobs/cv -- target/release/pav crossval --config configs/optimize/quick.toml -o out/cv")]
    Slurm(Args),
    /// The same as a Kubernetes Indexed Job (job.yaml) and a merge Job (merge.yaml). Not run by
    /// pav's tests: no Kubernetes here; the commands are the ones the Slurm test proves.
    #[command(after_help = "Examples:
  pav cluster kubernetes --tasks 6 --cpus-per-task 1 --mem 4G --image registry.example/pav:0.1 -o jobs/cv -- target/release/pav crossval --config configs/optimize/quick.toml -o out/cv")]
    Kubernetes(Args),
}

#[derive(clap::Args)]
pub struct Args {
    /// Array tasks: the number of shards.
    #[arg(long)]
    tasks: usize,
    /// CPUs per task.
    #[arg(long, default_value_t = 2)]
    cpus_per_task: usize,
    /// Memory per task (Slurm notation: 8G, 500M).
    #[arg(long, default_value = "8G")]
    mem: String,
    /// Wall-time limit per task (HH:MM:SS).
    #[arg(long, default_value = "24:00:00")]
    time: String,
    /// Slurm partition (default: the cluster's default partition).
    #[arg(long)]
    partition: Option<String>,
    /// Job name (default: pav-<subcommand>).
    #[arg(long)]
    name: Option<String>,
    /// Folder the tasks run in, so relative paths in the command resolve as here (default: this
    /// folder); on a cluster it must be on a file system every node mounts.
    #[arg(long)]
    workdir: Option<PathBuf>,
    /// Container image (Kubernetes) with pav built and its data store reachable.
    #[arg(long, default_value = "pav:latest")]
    image: String,
    /// Folder to write the scripts into (task logs go into its logs/).
    #[arg(long, short = 'o')]
    out: PathBuf,
    /// The command to shard, after `--`: e.g. `-- target/release/pav crossval --config C -o out/cv`.
    #[arg(last = true, required = true)]
    command: Vec<String>,
}

fn job(a: &Args) -> Result<ClusterJob> {
    let workdir = match &a.workdir {
        Some(w) => w.clone(),
        None => std::env::current_dir().context("the current folder")?,
    };
    let out = std::path::absolute(&a.out).with_context(|| format!("{}", a.out.display()))?;
    let name = a.name.clone().unwrap_or_else(|| {
        let sub = a.command.iter().skip(1).find(|w| !w.starts_with('-')).map_or("job", String::as_str);
        format!("pav-{sub}")
    });
    let job = ClusterJob {
        name,
        command: a.command.clone(),
        tasks: a.tasks,
        cpus: a.cpus_per_task,
        mem: a.mem.clone(),
        time: a.time.clone(),
        workdir: workdir.display().to_string(),
        logs: out.join("logs").display().to_string(),
        partition: a.partition.clone(),
        image: a.image.clone(),
    };
    job.check()?;
    Ok(job)
}

fn write(dir: &Path, name: &str, text: &str, executable: bool) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let p = dir.join(name);
    std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?;
    if executable {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755))?;
    }
    Ok(p)
}

pub fn run(cmd: &Cmd) -> Result<()> {
    match cmd {
        Cmd::Slurm(a) => {
            let j = job(a)?;
            write(&a.out, "array.sbatch", &j.slurm_array(), false)?;
            write(&a.out, "merge.sbatch", &j.slurm_merge(), false)?;
            let submit = write(&a.out, "submit.sh", &j.slurm_submit("array.sbatch", "merge.sbatch"), true)?;
            eprintln!(
                "wrote array.sbatch ({} tasks), merge.sbatch and submit.sh in {}; submit with: bash {}",
                a.tasks,
                a.out.display(),
                submit.display()
            );
        }
        Cmd::Kubernetes(a) => {
            let j = job(a)?;
            write(&a.out, "job.yaml", &j.kubernetes(), false)?;
            write(&a.out, "merge.yaml", &j.kubernetes_merge(), false)?;
            eprintln!(
                "wrote job.yaml ({} indexed pods) and merge.yaml in {} (untested here: no Kubernetes on pav's test machines)",
                a.tasks,
                a.out.display()
            );
        }
    }
    Ok(())
}
