//! Job scripts that run a shardable pav command on a cluster: a Slurm job array of `N` tasks,
//! task `K` running the command with `--shard K/N`, and a merge job that starts when every task
//! has succeeded and runs it with `--merge`; or the same as a Kubernetes Indexed Job.

/// What every cluster's scripts need to know about the job.
#[derive(Clone, Debug)]
pub struct ClusterJob {
    /// Job name shown by the scheduler.
    pub name: String,
    /// The pav command line without `--shard`/`--merge` (program first).
    pub command: Vec<String>,
    /// Array tasks (shards).
    pub tasks: usize,
    /// CPUs per task.
    pub cpus: usize,
    /// Memory per task, in the scheduler's notation (`8G`).
    pub mem: String,
    /// Wall-time limit per task (`HH:MM:SS`).
    pub time: String,
    /// The folder the tasks run in (where relative paths of the command resolve).
    pub workdir: String,
    /// Where the tasks' logs go.
    pub logs: String,
    /// Slurm partition (None: the cluster's default).
    pub partition: Option<String>,
    /// Container image for Kubernetes.
    pub image: String,
}

/// Why scripts cannot be written for a job.
#[derive(Debug, thiserror::Error)]
pub enum ClusterError {
    /// A job the scripts cannot describe.
    #[error("{0}")]
    Invalid(String),
}

/// Quotes one word for a POSIX shell.
pub fn shell_word(s: &str) -> String {
    if !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c)) {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

impl ClusterJob {
    /// Refuses what no scheduler would run: no command, zero tasks or CPUs, a command that
    /// already picks its shard.
    pub fn check(&self) -> Result<(), ClusterError> {
        if self.command.is_empty() {
            return Err(ClusterError::Invalid("no command given: put the pav command after `--`".into()));
        }
        if self.tasks == 0 || self.cpus == 0 {
            return Err(ClusterError::Invalid(format!(
                "--tasks {} and --cpus-per-task {} must both be at least 1",
                self.tasks, self.cpus
            )));
        }
        if let Some(w) = self.command.iter().find(|w| w.starts_with("--shard") || *w == "--merge") {
            return Err(ClusterError::Invalid(format!(
                "the command already has {w}: give it without; each task adds --shard K/N and the merge job --merge"
            )));
        }
        Ok(())
    }

    fn command_line(&self) -> String {
        self.command.iter().map(|w| shell_word(w)).collect::<Vec<_>>().join(" ")
    }

    fn header(&self, name: &str, cpus: usize, extra: &[String]) -> String {
        let mut h = format!(
            "#!/usr/bin/env bash\n#SBATCH --job-name={}\n#SBATCH --cpus-per-task={}\n#SBATCH --mem={}\n#SBATCH --time={}\n#SBATCH --chdir={}\n#SBATCH --export=ALL\n",
            shell_word(name),
            cpus,
            self.mem,
            self.time,
            shell_word(&self.workdir)
        );
        if let Some(p) = &self.partition {
            h.push_str(&format!("#SBATCH --partition={}\n", shell_word(p)));
        }
        for e in extra {
            h.push_str(&format!("#SBATCH {e}\n"));
        }
        h
    }

    /// The array script: task `$SLURM_ARRAY_TASK_ID` (1..=N) runs shard K/N. Requeued tasks
    /// append to their log and resume from what the shard already wrote.
    pub fn slurm_array(&self) -> String {
        let extra = [
            format!("--array=1-{}", self.tasks),
            "--requeue".into(),
            "--open-mode=append".into(),
            format!("--output={}/task-%a.log", shell_word(&self.logs)),
        ];
        format!(
            "{}set -euo pipefail\necho \"task $SLURM_ARRAY_TASK_ID of {n} on $(hostname), restart ${{SLURM_RESTART_COUNT:-0}}\"\nexec {} --shard \"$SLURM_ARRAY_TASK_ID/{n}\"\n",
            self.header(&self.name, self.cpus, &extra),
            self.command_line(),
            n = self.tasks
        )
    }

    /// The merge script, submitted to start after every array task succeeded.
    pub fn slurm_merge(&self) -> String {
        let extra = [format!("--output={}/merge.log", shell_word(&self.logs))];
        format!(
            "{}set -euo pipefail\nexec {} --merge\n",
            self.header(&format!("{}-merge", self.name), 1, &extra),
            self.command_line()
        )
    }

    /// Submits the array, then the merge with `afterok` on it; prints both job ids.
    pub fn slurm_submit(&self, array: &str, merge: &str) -> String {
        format!(
            "#!/usr/bin/env bash\n# Submits {name}: {n} array tasks, then its merge once all of them succeeded.\nset -euo pipefail\ncd \"$(dirname \"$0\")\"\nmkdir -p {logs}\narray=$(sbatch --parsable {array})\nmerge=$(sbatch --parsable --dependency=afterok:\"${{array%%;*}}\" --kill-on-invalid-dep=yes {merge})\necho \"array $array, merge $merge\"\n",
            name = self.name,
            n = self.tasks,
            logs = shell_word(&self.logs),
        )
    }

    /// A Kubernetes Indexed Job of N completions (pod index 0..N-1 runs shard index+1 of N);
    /// the working folder must be a volume every pod mounts at the same path.
    pub fn kubernetes(&self) -> String {
        let n = self.tasks;
        format!(
            "# {name}: {n} indexed pods, each one shard. Once it completed, apply merge.yaml:\n#   kubectl wait --for=condition=complete job/{name} --timeout=-1s && kubectl apply -f merge.yaml\n{}",
            self.k8s_job(&self.name, Some(n), &format!("--shard \"$((JOB_COMPLETION_INDEX + 1))/{n}\""), self.cpus),
            name = self.name,
        )
    }

    /// The merge as a plain Kubernetes Job.
    pub fn kubernetes_merge(&self) -> String {
        self.k8s_job(&format!("{}-merge", self.name), None, "--merge", 1)
    }

    fn k8s_job(&self, name: &str, indexed: Option<usize>, tail: &str, cpus: usize) -> String {
        let q = |s: &str| format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""));
        let spec = match indexed {
            Some(n) => format!(
                "  completionMode: Indexed\n  completions: {n}\n  parallelism: {n}\n  backoffLimitPerIndex: 3\n"
            ),
            None => "  backoffLimit: 3\n".into(),
        };
        let mem = q(&k8s_mem(&self.mem));
        format!(
            "apiVersion: batch/v1\nkind: Job\nmetadata:\n  name: {name}\nspec:\n{spec}  template:\n    spec:\n      restartPolicy: Never\n      containers:\n        - name: pav\n          image: {}\n          workingDir: {}\n          command: [\"bash\", \"-c\", {}]\n          resources:\n            requests: {{cpu: \"{cpus}\", memory: {mem}}}\n            limits: {{cpu: \"{cpus}\", memory: {mem}}}\n          volumeMounts:\n            - {{name: work, mountPath: {}}}\n      volumes:\n        - name: work\n          persistentVolumeClaim: {{claimName: pav-work}}\n",
            q(&self.image),
            q(&self.workdir),
            q(&format!("{} {tail}", self.command_line())),
            q(&self.workdir),
        )
    }
}

/// Slurm's `8G` as Kubernetes' `8Gi`.
fn k8s_mem(m: &str) -> String {
    match m.chars().last() {
        Some(u @ ('K' | 'M' | 'G' | 'T')) => format!("{}{u}i", &m[..m.len() - 1]),
        _ => format!("{m}Mi"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job() -> ClusterJob {
        ClusterJob {
            name: "cv".into(),
            command: ["pav", "crossval", "--config", "a b.toml", "-o", "out/cv"].map(String::from).to_vec(),
            tasks: 4,
            cpus: 2,
            mem: "8G".into(),
            time: "04:00:00".into(),
            workdir: "/work/pav".into(),
            logs: "logs".into(),
            partition: None,
            image: "pav:latest".into(),
        }
    }

    #[test]
    fn each_array_task_runs_its_shard_and_the_merge_waits_for_all() {
        let j = job();
        j.check().unwrap();
        let a = j.slurm_array();
        assert!(a.contains("#SBATCH --array=1-4\n") && a.contains("#SBATCH --requeue\n"), "{a}");
        assert!(
            a.contains("exec pav crossval --config 'a b.toml' -o out/cv --shard \"$SLURM_ARRAY_TASK_ID/4\""),
            "{a}"
        );
        let m = j.slurm_merge();
        assert!(m.contains("--merge\n") && m.contains("--cpus-per-task=1\n") && !m.contains("--array"), "{m}");
        let s = j.slurm_submit("array.sbatch", "merge.sbatch");
        assert!(s.contains("--dependency=afterok:"), "{s}");
        let k = j.kubernetes();
        assert!(k.contains("completionMode: Indexed") && k.contains("completions: 4"), "{k}");
        assert!(k.contains("$((JOB_COMPLETION_INDEX + 1))/4") && k.contains("memory: \"8Gi\""), "{k}");
        let km = j.kubernetes_merge();
        assert!(km.contains("--merge") && !km.contains("Indexed") && km.starts_with("apiVersion"), "{km}");
    }

    #[test]
    fn a_command_that_picks_its_own_shard_is_refused() {
        let mut j = job();
        j.command.push("--shard".into());
        assert!(j.check().unwrap_err().to_string().contains("already has --shard"));
        let j = ClusterJob { tasks: 0, ..job() };
        assert!(j.check().is_err());
        let j = ClusterJob { command: vec![], ..job() };
        assert!(j.check().unwrap_err().to_string().contains("after `--`"));
    }
}
