#!/usr/bin/env bash
# A one-node Slurm cluster on this machine, for the `slurm` tests and for trying the sbatch
# scripts of docs/cluster.md:  tests/slurm/slurm_up.sh DIR  then  export SLURM_CONF=DIR/slurm.conf
# Stop it with tests/slurm/slurm_down.sh DIR.
#
# Installs Debian's slurmctld, slurmd, slurm-client and munge when missing (root and apt-get
# needed), writes DIR/slurm.conf (one node with this machine's CPUs and memory, partition
# "debug", no cgroups, no accounting daemon: finished jobs go to DIR/jobcomp.txt, which
# `sacct --completion` reads), starts munged, slurmctld and slurmd with their state, logs and
# sockets in DIR, and waits until sinfo shows the node idle.
#
# Exit status 3 with a line "skip: <reason>" on stderr: Slurm cannot be started here (not root,
# no apt-get, packages not installable); the tests skip with that reason. Any other failure:
# the daemons' logs are printed.
set -euo pipefail

DIR=${1:?usage: slurm_up.sh DIR}
mkdir -p "$DIR"
DIR=$(cd "$DIR" && pwd)
PARTITION=${SLURM_TEST_PARTITION:-debug}
CTLD_PORT=${SLURM_TEST_CTLD_PORT:-6817}
SLURMD_PORT=${SLURM_TEST_SLURMD_PORT:-6818}

skip() {
  echo "skip: $*" >&2
  exit 3
}

binaries=(/usr/sbin/slurmctld /usr/sbin/slurmd /usr/bin/sbatch /usr/sbin/munged /usr/sbin/mungekey)
missing=0
for binary in "${binaries[@]}"; do [ -x "$binary" ] || missing=1; done
if [ "$missing" -eq 1 ]; then
  [ "$(id -u)" -eq 0 ] || skip "Slurm is not installed and this is not root (apt-get install slurmctld slurmd slurm-client munge)"
  command -v apt-get >/dev/null || skip "Slurm is not installed and there is no apt-get"
  export DEBIAN_FRONTEND=noninteractive
  { apt-get update -qq && apt-get install -y -qq --no-install-recommends \
      slurmctld slurmd slurm-client munge; } >"$DIR/apt.log" 2>&1 \
    || skip "apt-get could not install slurmctld slurmd slurm-client munge (see $DIR/apt.log)"
fi
# slurmd and slurmctld run jobs as their owners and need root for that
[ "$(id -u)" -eq 0 ] || skip "the Slurm daemons need root to start jobs (this is uid $(id -u))"

NODE=$(hostname -s)
# CPUs, sockets, cores, threads and memory as slurmd sees them (first line of slurmd -C)
HARDWARE=$(slurmd -C | head -n 1 | sed -e 's/^NodeName=[^ ]* //' -e 's/ UpTime=.*//')
CPUS=$(sed -n 's/.*CPUs=\([0-9]*\).*/\1/p' <<<"$HARDWARE")
MEMORY=$(sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p' <<<"$HARDWARE")
MEMORY=$((MEMORY * 9 / 10)) # leave the system some room: slurmd drains a node with less than it was told

mkdir -p "$DIR/state" "$DIR/spool"
chmod 755 "$DIR" "$DIR/spool"
cat >"$DIR/slurm.conf" <<CONF
# written by tests/slurm/slurm_up.sh
ClusterName=intermask
SlurmctldHost=$NODE(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$DIR/munge.socket
CredType=cred/munge
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/slurmctld.pid
SlurmdPidFile=$DIR/slurmd.pid
SlurmctldLogFile=$DIR/slurmctld.log
SlurmdLogFile=$DIR/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
# no cgroups: processes are tracked through /proc, tasks are not pinned
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SwitchType=switch/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU_Memory
# no slurmdbd: finished jobs are written to a text file that sacct --completion reads
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$DIR/jobcomp.txt
JobAcctGatherType=jobacct_gather/none
JobRequeue=1
ReturnToService=2
KillWait=30
MinJobAge=600
InactiveLimit=0
SlurmdTimeout=300
NodeName=$NODE NodeAddr=127.0.0.1 $HARDWARE RealMemory=$MEMORY State=UNKNOWN
PartitionName=$PARTITION Nodes=$NODE Default=YES MaxTime=INFINITE State=UP DefMemPerCPU=$((MEMORY / CPUS))
CONF
sed -i "s/ RealMemory=[0-9]* RealMemory=/ RealMemory=/" "$DIR/slurm.conf" # slurmd -C's value replaced

export SLURM_CONF=$DIR/slurm.conf
fail() {
  echo "slurm_up.sh: $*" >&2
  for log in munged.log slurmctld.log slurmd.log; do
    [ -f "$DIR/$log" ] && { echo "--- $DIR/$log" >&2; tail -n 30 "$DIR/$log" >&2; }
  done
  exit 1
}

# munge: its own key, socket and pid file in DIR (an installed munge service is left alone)
[ -f "$DIR/munge.key" ] || mungekey --create --keyfile="$DIR/munge.key" >/dev/null 2>&1 \
  || dd if=/dev/urandom of="$DIR/munge.key" bs=1024 count=1 2>/dev/null
chmod 600 "$DIR/munge.key"
munged --force --socket="$DIR/munge.socket" --key-file="$DIR/munge.key" \
  --pid-file="$DIR/munged.pid" --log-file="$DIR/munged.log" --seed-file="$DIR/munged.seed" \
  || fail "munged did not start"
slurmctld -c -f "$SLURM_CONF" || fail "slurmctld did not start"
slurmd -f "$SLURM_CONF" || fail "slurmd did not start"

for _ in $(seq 120); do
  state=$(sinfo -h -n "$NODE" -o %T 2>/dev/null || true)
  [ "$state" = idle ] && break
  sleep 0.5
done
[ "$state" = idle ] || fail "node $NODE is '${state:-not reported}', not idle, after 60 s"
sinfo
