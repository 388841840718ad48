#!/usr/bin/env bash
# A single-node Slurm cluster on the loopback host, entirely inside one folder: its own MUNGE key,
# socket and daemon, its own slurm.conf, slurmctld and slurmd on free ports, state, spool, logs and
# pid files. It leaves no daemon behind and touches no system-wide MUNGE or Slurm set-up, so it can
# run beside a real one. Needs Debian's slurm-wlm and munge (scripts/setup.sh installs them) and
# root (slurmd starts jobs as their submitting user).
#   start DIR   start the cluster in DIR (created), wait until its node is idle; prints the line
#               `export SLURM_CONF=DIR/slurm.conf` that every sbatch/squeue/scontrol call needs
#   stop DIR    stop every daemon started in DIR (by its pid file), then wait for them to exit
#   env DIR     print that export line again
set -euo pipefail
cmd=${1:?usage: local-slurm.sh start|stop|env DIR}
DIR=${2:?usage: local-slurm.sh start|stop|env DIR}
export SLURM_CONF="$DIR/slurm.conf"

# The daemons' pids, one file each (munged writes its own; Slurm's are named in slurm.conf).
PIDS=(ctld.pid d.pid munge/munged.pid)

stop() {
  local pids=()
  for f in "${PIDS[@]}"; do
    [ -f "$DIR/$f" ] || continue
    p=$(cat "$DIR/$f" 2>/dev/null || true)
    [ -n "$p" ] && kill -0 "$p" 2>/dev/null && { kill "$p" 2>/dev/null || true; pids+=("$p"); }
  done
  # Jobs still running under slurmd's step daemons belong to this cluster too.
  pkill -f "slurmstepd:.*" -P 1 2>/dev/null || true
  for i in $(seq 1 100); do
    alive=0
    for p in "${pids[@]}"; do kill -0 "$p" 2>/dev/null && alive=1; done
    [ $alive = 0 ] && return 0
    sleep 0.1
  done
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null || true; done
}

free_port() { # first port from $1 that nothing listens on
  local p=$1
  while (exec 3<>"/dev/tcp/127.0.0.1/$p") 2>/dev/null || [ -n "$(ss -Hltn "sport = :$p" 2>/dev/null)" ]; do p=$((p + 1)); done
  echo "$p"
}

case $cmd in
  env) echo "export SLURM_CONF=$SLURM_CONF"; exit 0 ;;
  stop) stop; exit 0 ;;
  start) ;;
  *) echo "local-slurm.sh: unknown command $cmd (start, stop, env)" >&2; exit 2 ;;
esac

for p in slurmctld slurmd munged mungekey sinfo; do
  command -v "$p" >/dev/null || { echo "local-slurm.sh: $p is not installed (apt-get install slurm-wlm munge; scripts/setup.sh does)" >&2; exit 1; }
done
[ "$(id -u)" = 0 ] || { echo "local-slurm.sh: slurmd must run as root to start jobs as their users" >&2; exit 1; }
mkdir -p "$DIR"/{state,spool,log,munge}
DIR=$(cd "$DIR" && pwd)
export SLURM_CONF="$DIR/slurm.conf"
# If anything below fails, nothing started here is left running.
trap 'stop' ERR

# MUNGE with its own key and socket; --force because it runs as root here.
mungekey -c -k "$DIR/munge/munge.key" -f
chmod 700 "$DIR/munge"; chmod 400 "$DIR/munge/munge.key"
munged --force --key-file="$DIR/munge/munge.key" --socket="$DIR/munge/munge.socket" \
  --pid-file="$DIR/munge/munged.pid" --log-file="$DIR/munge/munged.log" --seed-file="$DIR/munge/munged.seed"

H=$(hostname)
ctld_port=$(free_port 16817)
d_port=$(free_port $((ctld_port + 1)))
cat > "$SLURM_CONF" <<CONF
ClusterName=pavlocal
SlurmctldHost=$H(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$d_port
AuthType=auth/munge
CredType=cred/munge
# A requeued task may start again after cred_expire seconds (Slurm's default is 120).
AuthInfo=socket=$DIR/munge/munge.socket,cred_expire=10
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/ctld.pid
SlurmdPidFile=$DIR/d.pid
SlurmctldLogFile=$DIR/log/ctld.log
SlurmdLogFile=$DIR/log/d.log
ReturnToService=2
MpiDefault=none
JobCompType=jobcomp/none
MailProg=/bin/true
SchedulerParameters=sched_interval=1
NodeName=$H NodeAddr=127.0.0.1 CPUs=$(nproc) RealMemory=$(($(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 1024)) State=UNKNOWN
PartitionName=local Nodes=$H Default=YES MaxTime=INFINITE State=UP
CONF
slurmctld -i
slurmd
for i in $(seq 1 100); do
  sinfo -h -o %T 2>/dev/null | grep -q idle && { echo "export SLURM_CONF=$SLURM_CONF"; exit 0; }
  sleep 0.2
done
echo "local-slurm.sh: the node did not come up idle within 20 s; logs in $DIR/log:" >&2
tail -n 20 "$DIR"/log/*.log >&2 || true
stop
exit 1
