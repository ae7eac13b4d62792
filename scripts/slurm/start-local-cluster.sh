#!/usr/bin/env bash
# RUN AS ROOT: INSTALLS PACKAGES (slurm-wlm, munge, with apt) AND OVERWRITES /etc/slurm/slurm.conf (and creates
# /etc/munge/munge.key if missing). Only on a machine whose Slurm and munge set-up you do not need.
#
# Starts a one-node Slurm cluster on this (Debian) machine, to try the scripts of this directory without a
# cluster: munge for authentication, slurmctld and slurmd on localhost, one partition `local` with every CPU.
# Stop it with
#   scripts/slurm/start-local-cluster.sh stop
set -euo pipefail
if [[ "${1:-}" == stop ]]; then
    pkill -x slurmd || true
    pkill -x slurmctld || true
    pkill -x munged || true
    exit 0
fi
if ! command -v slurmctld > /dev/null || ! command -v munged > /dev/null; then
    apt-get install -y slurm-wlm munge
fi
host="$(hostname -s)"
cpus="$(nproc)"
# slurmd's own view of the memory, minus a margin, so that the node registers as healthy.
mem_mb=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 512 ))
conf=/etc/slurm/slurm.conf
mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm /run/munge
cat > "$conf" <<CONF
# Written by calibench scripts/slurm/start-local-cluster.sh: one node, this machine.
ClusterName=calibench-local
SlurmctldHost=$host
SlurmUser=root
AuthType=auth/munge
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
ReturnToService=2
NodeName=$host CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
# munge needs a key readable by its user only.
if [[ ! -s /etc/munge/munge.key ]]; then
    mkdir -p /etc/munge
    dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key status=none
fi
chown -R munge:munge /etc/munge /run/munge /var/lib/munge /var/log/munge 2>/dev/null || true
chmod 0700 /etc/munge
chmod 0400 /etc/munge/munge.key
pgrep -x munged > /dev/null || runuser -u munge -- munged
pgrep -x slurmctld > /dev/null || slurmctld
pgrep -x slurmd > /dev/null || slurmd
for _ in $(seq 30); do
    if sinfo -h -o '%T' 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
        sinfo
        exit 0
    fi
    sleep 1
done
echo "the node did not come up: see /var/log/slurm/slurmctld.log and slurmd.log" >&2
sinfo >&2 || true
exit 1
