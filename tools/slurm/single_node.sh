#!/usr/bin/env bash
# A real single-node Slurm for testing the method grid's array job (issue 18):
#
#   tools/slurm/single_node.sh start DIR   # writes DIR/slurm.conf, starts munged, slurmctld, slurmd
#   tools/slurm/single_node.sh stop DIR    # stops them
#
# Needs Debian's `slurm-wlm` and `munge` (apt-get install slurm-wlm munge) and root (the
# daemons run as root here; a real cluster runs them as the slurm user). After `start`,
# export SLURM_CONF=DIR/slurm.conf and use sbatch / squeue / sacct as usual.
set -euo pipefail
cmd=${1:?start|stop}
dir=$(realpath -m "${2:?state folder}")
mkdir -p "$dir"/{spool,state,log,munge}
host=$(hostname -s)
cpus=$(nproc)
mem=$(awk '/MemTotal/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)

case "$cmd" in
start)
  cat > "$dir/slurm.conf" <<CONF
ClusterName=gbnerf
SlurmctldHost=$host
AuthType=auth/munge
CredType=cred/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
SlurmUser=root
SlurmdUser=root
SlurmctldPidFile=$dir/state/slurmctld.pid
SlurmdPidFile=$dir/state/slurmd.pid
SlurmdSpoolDir=$dir/spool
StateSaveLocation=$dir/state
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$dir/log/jobcomp.txt
MaxArraySize=10001
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=main Nodes=$host Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
CONF
  : > "$dir/cgroup.conf"
  # munge: a key, and the daemon (it refuses root without --force)
  if [ ! -s /etc/munge/munge.key ]; then
    mungekey --create --keyfile=/etc/munge/munge.key 2>/dev/null \
      || dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key 2>/dev/null
  fi
  chmod 400 /etc/munge/munge.key
  mkdir -p /run/munge /var/lib/munge /var/log/munge
  if ! pgrep -x munged >/dev/null; then
    munged --force --socket=/run/munge/munge.socket.2
  fi
  export SLURM_CONF="$dir/slurm.conf"
  slurmctld -f "$SLURM_CONF"
  slurmd -f "$SLURM_CONF"
  for _ in $(seq 1 60); do
    if sinfo -h -o '%T' 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
      echo "slurm is up: SLURM_CONF=$SLURM_CONF ($host, $cpus CPUs)"
      exit 0
    fi
    sleep 1
  done
  echo "slurm did not come up; see $dir/log" >&2
  sinfo >&2 || true
  exit 1
  ;;
stop)
  for pid in "$dir/state/slurmd.pid" "$dir/state/slurmctld.pid"; do
    [ -f "$pid" ] && kill "$(cat "$pid")" 2>/dev/null || true
  done
  ;;
*)
  echo "usage: $0 start|stop DIR" >&2
  exit 2
  ;;
esac
