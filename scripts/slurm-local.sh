#!/usr/bin/env bash
# Start (or stop) a one-node SLURM cluster on this machine, as ../shared/peers/slurm-local.md
# describes: munge + slurmctld + slurmd (Debian's slurm-wlm). Installs the packages when
# `sbatch` is missing (needs root and apt). Daemons started here are recorded in
# $STATE/started (PIDs) so that `scripts/slurm-local.sh stop` stops exactly those.
#   scripts/slurm-local.sh start   # idempotent: reuses daemons already running
#   scripts/slurm-local.sh stop
set -euo pipefail
STATE=${SLURM_LOCAL_STATE:-/tmp/granular-slurm-local}
mkdir -p "$STATE"

running() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }

start() {
    if ! command -v sbatch >/dev/null || ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
        if [ "$(id -u)" != 0 ]; then
            echo "slurm-local: slurm-wlm and munge are not installed and this is not root" >&2
            exit 2
        fi
        echo "slurm-local: installing slurm-wlm and munge"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null
    fi
    : > "$STATE/started.new"
    [ -f "$STATE/started" ] && cat "$STATE/started" >> "$STATE/started.new"
    mkdir -p /run/munge /var/log/munge /var/lib/munge
    chown munge:munge /run/munge /var/log/munge /var/lib/munge
    [ -f /etc/munge/munge.key ] || { dd if=/dev/urandom of=/etc/munge/munge.key bs=1 count=1024 2>/dev/null; chown munge:munge /etc/munge/munge.key; chmod 400 /etc/munge/munge.key; }
    if ! running /run/munge/munged.pid; then
        runuser -u munge -- /usr/sbin/munged
        sleep 0.5
        echo "munged $(cat /run/munge/munged.pid)" >> "$STATE/started.new"
    fi
    munge -n | unmunge >/dev/null
    mkdir -p /var/lib/slurm/slurmd /var/lib/slurm/slurmctld /var/log/slurm
    chown -R slurm:slurm /var/lib/slurm /var/log/slurm
    cpus=$(nproc)
    cat > /etc/slurm/slurm.conf <<CONF
ClusterName=localcluster
SlurmctldHost=localhost
SlurmUser=slurm
AuthType=auth/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
KillWait=10
StateSaveLocation=/var/lib/slurm/slurmctld
SlurmdSpoolDir=/var/lib/slurm/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
NodeName=localhost CPUs=$cpus State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
    if ! running /run/slurmctld.pid; then
        slurmctld
        for _ in $(seq 50); do running /run/slurmctld.pid && break; sleep 0.1; done
        echo "slurmctld $(cat /run/slurmctld.pid)" >> "$STATE/started.new"
    fi
    if ! running /run/slurmd.pid; then
        slurmd -N localhost
        for _ in $(seq 50); do running /run/slurmd.pid && break; sleep 0.1; done
        echo "slurmd $(cat /run/slurmd.pid)" >> "$STATE/started.new"
    fi
    mv "$STATE/started.new" "$STATE/started"
    for _ in $(seq 60); do
        if sinfo -h -o '%T' 2>/dev/null | grep -qx idle; then
            sinfo
            return 0
        fi
        scontrol update nodename=localhost state=resume >/dev/null 2>&1 || true
        sleep 1
    done
    echo "slurm-local: the node did not become idle; sinfo says:" >&2
    sinfo >&2 || true
    tail -20 /var/log/slurm/slurmctld.log /var/log/slurm/slurmd.log >&2 || true
    exit 1
}

stop() {
    [ -f "$STATE/started" ] || return 0
    # Reverse order: slurmd, slurmctld, munged.
    tac "$STATE/started" | while read -r name pid; do
        if kill -0 "$pid" 2>/dev/null; then
            kill "$pid" 2>/dev/null || true
            for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
            echo "slurm-local: stopped $name ($pid)"
        fi
    done
    rm -f "$STATE/started"
}

case "${1:-}" in
    start) start ;;
    stop) stop ;;
    *) echo "usage: $0 start|stop" >&2; exit 2 ;;
esac
