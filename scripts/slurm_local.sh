#!/usr/bin/env bash
# A one-node Slurm cluster on this machine, for the Slurm sweep backend's test and for trying it
# (issue 14): `start` installs slurm-wlm and munge (apt, Debian 12), writes a configuration for
# localhost (one node with every core, one partition "local") and starts munged, slurmctld and
# slurmd; `stop` stops them and removes the state; `status` shows the node. Root only; no network
# beyond the Debian mirror. Idempotent: `start` on a running cluster only checks it.
#
#   scripts/slurm_local.sh start|stop|status
#
# The configuration and state live in /etc/slurm/slurm.conf and /var/lib/raytime-slurm; logs in
# /var/log/raytime-slurm. A cluster already configured by someone else (an /etc/slurm/slurm.conf
# not written by this script) is left alone and reported.
set -euo pipefail

state=/var/lib/raytime-slurm
logs=/var/log/raytime-slurm
conf=/etc/slurm/slurm.conf
marker="# written by raytime scripts/slurm_local.sh"

die() { echo "slurm_local.sh: $*" >&2; exit 1; }
[[ $(id -u) -eq 0 ]] || die "must run as root (it installs packages and starts daemons)"

running() { pgrep -x "$1" > /dev/null; }

wait_for_node() {
  local i
  for i in $(seq 1 30); do
    if sinfo -h -o '%t' 2> /dev/null | grep -qE '^(idle|mix|alloc)'; then return 0; fi
    sleep 1
  done
  sinfo >&2 || true
  tail -n 20 "$logs/slurmctld.log" "$logs/slurmd.log" >&2 || true
  die "the node did not become idle in 30 s (logs above, $logs)"
}

start() {
  if ! command -v slurmctld > /dev/null || ! command -v munged > /dev/null; then
    echo "slurm_local.sh: installing slurm-wlm and munge"
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends slurm-wlm munge \
      > /dev/null
  fi
  if [[ -f $conf ]] && ! grep -qF "$marker" "$conf"; then
    die "$conf exists and was not written by this script: a cluster is configured already"
  fi
  mkdir -p "$state/ctld" "$state/d" "$logs" /run/munge /etc/slurm
  local host cpus
  host=$(hostname -s)
  cpus=$(nproc)
  # A one-node cluster of short jobs: the main scheduler every second (default 60 s), at most
  # every 0.1 s (2 s), batch jobs not held back (3 s), so a dependent job starts about a second
  # after its dependency ends instead of three (the Slurm test: 37 -> 20 s).
  cat > "$conf.tmp" << EOF
$marker
ClusterName=raytime-local
SlurmctldHost=$host
AuthType=auth/munge
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SchedulerType=sched/backfill
SchedulerParameters=sched_interval=1,sched_min_interval=100000,batch_sched_delay=0
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
StateSaveLocation=$state/ctld
SlurmdSpoolDir=$state/d
SlurmctldPidFile=$state/slurmctld.pid
SlurmdPidFile=$state/slurmd.pid
SlurmctldLogFile=$logs/slurmctld.log
SlurmdLogFile=$logs/slurmd.log
JobCompType=jobcomp/none
NodeName=$host CPUs=$cpus State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
  mv "$conf.tmp" "$conf"
  # munge needs a key (the package makes one) owned by its user.
  [[ -s /etc/munge/munge.key ]] || mungekey --create > /dev/null 2>&1 || \
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1 count=128 2> /dev/null
  chown munge:munge /etc/munge/munge.key /run/munge 2> /dev/null || true
  chmod 400 /etc/munge/munge.key
  running munged || munged --force 2> "$logs/munged.err" || die "munged did not start: $(cat "$logs/munged.err")"
  running slurmctld || slurmctld || die "slurmctld did not start (see $logs/slurmctld.log)"
  running slurmd || slurmd || die "slurmd did not start (see $logs/slurmd.log)"
  wait_for_node
  echo "slurm_local.sh: one-node cluster up: $(sinfo -h -o '%P %D node(s) %c CPUs %t')"
}

stop() {
  local d
  for d in slurmd slurmctld; do
    if running "$d"; then pkill -x "$d"; fi
  done
  for d in slurmd slurmctld; do
    for _ in $(seq 1 20); do running "$d" || break; sleep 0.5; done
  done
  if [[ -f $conf ]] && grep -qF "$marker" "$conf"; then rm -f "$conf"; fi
  rm -rf "$state"
  echo "slurm_local.sh: stopped (munged left running: other services may use it)"
}

case "${1:-}" in
  start) start ;;
  stop) stop ;;
  status) sinfo ;;
  *) die "usage: scripts/slurm_local.sh start|stop|status" ;;
esac
