#!/usr/bin/env bash
# The Slurm path of `tirewear process`, for real: slurmctld and slurmd on
# this one machine (Debian's slurm-wlm and munge), deploy/slurm/nightly.sh
# submits an array of 4 shards and the dependent commit, and the dataset
# must equal, byte for byte, one whole run's (summary.json aside).
# Usage: .ci/slurm.sh path/to/tirewear   (needs root for the daemons)
set -euo pipefail
cd "$(dirname "$0")/.."
tw=$(realpath "$1")

export DEBIAN_FRONTEND=noninteractive
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null
fi
host=$(hostname)
mkdir -p /var/spool/slurmctld /var/spool/slurmd /var/log/slurm /run/munge /etc/slurm
chown munge:munge /run/munge
[ -s /etc/munge/munge.key ] || { dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key 2>/dev/null; chown munge:munge /etc/munge/munge.key; chmod 400 /etc/munge/munge.key; }
# No cgroups or accounting in a CI container: linuxproc tracking, no task plugin.
cat > /etc/slurm/slurm.conf <<CONF
ClusterName=tirewear-ci
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
MpiDefault=none
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
NodeName=$host CPUs=$(nproc) State=UNKNOWN
PartitionName=ci Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
started=()
pgrep -x munged >/dev/null || { runuser -u munge -- munged --force; started+=(munged); }
pgrep -x slurmctld >/dev/null || { slurmctld; started+=(slurmctld); }
pgrep -x slurmd >/dev/null || { slurmd; started+=(slurmd); }
stop() { for d in "${started[@]}"; do pkill -x "$d" || true; done; }
trap stop EXIT
for _ in $(seq 1 60); do sinfo -h -o %T 2>/dev/null | grep -qx idle && break; sleep 1; done
sinfo

work=$(mktemp -d)
"$tw" --quiet --log warn simulate --preset tiny --seed 21 --rate 5 --out "$work/season" >/dev/null
"$tw" --quiet process "$work/season" --out "$work/whole" --engine cpu
cd "$work"
ARCHIVES="$work/season" DATASET="$work/sharded" SHARDS=4 ENGINE=cpu TIREWEAR="$tw" \
  SBATCH_OPTS="--chdir=$work" "$OLDPWD/deploy/slurm/nightly.sh" | tee submit.txt
commit=$(sed -n 's/.*commit: job \([0-9]*\).*/\1/p' submit.txt)
for _ in $(seq 1 300); do
  [ -z "$(squeue -h -o %i)" ] && break
  sleep 1
done
cat "$work"/tirewear-commit-*.log
grep -q "committed dataset" "$work/tirewear-commit-$commit.log"
diff -r --exclude=summary.json "$work/whole" "$work/sharded"
echo "slurm: 4 shards + commit equal one whole run"
rm -rf "$work"
