#!/usr/bin/env bash
# A throw-away single-node Slurm cluster on 127.0.0.1, for testing the Slurm profile (profiles/slurm).
#
#   scripts/slurm_local.sh start    install Debian's munge/slurm if missing (needs root), write the config,
#                                   start munged, slurmctld and slurmd, wait until the node is idle
#   scripts/slurm_local.sh stop     stop the daemons this script started (by their PID files)
#   scripts/slurm_local.sh env      print the `export SLURM_CONF=...` line clients need
#
# Both commands are idempotent. No systemd: the daemons run directly, without cgroups
# (ProctrackType=proctrack/linuxproc, TaskPlugin=task/none) and without slurmdbd, so `sacct`
# does not work; the profile polls job states with `squeue` instead.
# Everything lives in $SLURM_LOCAL_DIR (default /tmp/dpi-slurm). /etc/slurm/slurm.conf becomes a
# link to its slurm.conf, because Snakemake's job steps call `srun` without SLURM_CONF (an
# /etc/slurm/slurm.conf that this script did not write is left alone, and `start` fails).
# The partition is $SLURM_LOCAL_PARTITION (default "debug"); the node gets every CPU (nproc)
# and 90 % of the memory (free -m).
set -euo pipefail

STATE=${SLURM_LOCAL_DIR:-/tmp/dpi-slurm}
PARTITION=${SLURM_LOCAL_PARTITION:-debug}
NODE=dpinode
CONF="$STATE/slurm.conf"
PACKAGES=(munge slurmctld slurmd slurm-client)
MUNGE_SOCKET="$STATE/munge/munge.socket"
SYSTEM_CONF=/etc/slurm/slurm.conf
MARKER="# Written by scripts/slurm_local.sh"

log() { echo "slurm_local: $*" >&2; }

install_packages() {
  local missing=() pkg
  for pkg in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then
    log "cannot install ${missing[*]}: needs apt-get as root"; exit 2
  fi
  log "installing Debian packages ${missing[*]}"
  apt-get update -qq
  # policy-rc.d 101: the packages' maintainer scripts must not try to start services (no systemd here).
  local policy=/usr/sbin/policy-rc.d created=0
  if [ ! -e "$policy" ]; then printf '#!/bin/sh\nexit 101\n' >"$policy"; chmod +x "$policy"; created=1; fi
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  [ "$created" = 1 ] && rm -f "$policy"
  return 0
}

running() {  # running NAME: the daemon whose PID file is $STATE/NAME.pid is alive
  [ -f "$STATE/$1.pid" ] && kill -0 "$(cat "$STATE/$1.pid")" 2>/dev/null
}

write_config() {
  local cpus mem host
  cpus=$(nproc)
  mem=$(free -m | awk '/^Mem:/ {print int($2 * 0.9)}')
  host=$(hostname)
  mkdir -p "$STATE/ctld" "$STATE/spool" "$STATE/munge"
  cat >"$CONF" <<EOF
$MARKER: a single test node on 127.0.0.1, no cgroups, no accounting.
ClusterName=dpi-local
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=${SLURM_LOCAL_CTLD_PORT:-6817}
SlurmdPort=${SLURM_LOCAL_SLURMD_PORT:-6818}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$MUNGE_SOCKET
CredType=cred/munge
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/spool
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=$STATE/slurmctld.log
SlurmdLogFile=$STATE/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SwitchType=switch/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
SlurmdParameters=config_overrides
ReturnToService=2
MinJobAge=3600
SchedulerParameters=sched_interval=2
NodeName=$NODE NodeHostname=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=$PARTITION Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
  if [ -e "$SYSTEM_CONF" ] && ! grep -q "^$MARKER" "$SYSTEM_CONF"; then
    log "$SYSTEM_CONF exists and was not written by this script; not replacing it"; exit 2
  fi
  mkdir -p "$(dirname "$SYSTEM_CONF")"
  ln -sfn "$CONF" "$SYSTEM_CONF"
}

start_munge() {
  running munged && return 0
  local key=/etc/munge/munge.key
  if [ ! -s "$key" ]; then
    mkdir -p /etc/munge
    dd if=/dev/urandom bs=1 count=1024 of="$key" status=none
  fi
  chown root:root "$key" && chmod 400 "$key"
  rm -f "$MUNGE_SOCKET" "$MUNGE_SOCKET.lock"
  munged --force --key-file="$key" --socket="$MUNGE_SOCKET" --pid-file="$STATE/munged.pid" \
    --log-file="$STATE/munged.log" --seed-file="$STATE/munge/munged.seed"
}

wait_idle() {
  local i state
  for i in $(seq 1 60); do
    state=$(SLURM_CONF="$CONF" sinfo -h -n "$NODE" -o '%T' 2>/dev/null || true)
    case "$state" in
      idle*|mixed*|allocated*) log "node $NODE is $state (partition $PARTITION)"; return 0 ;;
      down*|drain*) SLURM_CONF="$CONF" scontrol update nodename="$NODE" state=resume >/dev/null 2>&1 || true ;;
    esac
    sleep 1
  done
  log "node $NODE did not become idle (state: ${state:-unknown}); see $STATE/*.log"
  return 1
}

start() {
  install_packages
  mkdir -p "$STATE"
  if running slurmctld && running slurmd && running munged && wait_idle; then echo "export SLURM_CONF=$CONF"; return 0; fi
  write_config
  start_munge
  running slurmctld || slurmctld -f "$CONF"
  running slurmd || slurmd -f "$CONF" -N "$NODE"
  wait_idle
  echo "export SLURM_CONF=$CONF"
}

stop() {
  local name pid i
  for name in slurmd slurmctld munged; do
    [ -f "$STATE/$name.pid" ] || continue
    pid=$(cat "$STATE/$name.pid")
    if kill -0 "$pid" 2>/dev/null; then
      kill "$pid"
      for i in $(seq 1 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
      kill -0 "$pid" 2>/dev/null && kill -9 "$pid"
    fi
    rm -f "$STATE/$name.pid"
  done
  [ "$(readlink "$SYSTEM_CONF" 2>/dev/null)" = "$CONF" ] && rm -f "$SYSTEM_CONF"
  log "stopped"
}

case "${1:-}" in
  start) start ;;
  stop) stop ;;
  env) echo "export SLURM_CONF=$CONF" ;;
  *) echo "usage: $0 start|stop|env" >&2; exit 2 ;;
esac
