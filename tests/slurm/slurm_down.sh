#!/usr/bin/env bash
# Stop the one-node Slurm that tests/slurm/slurm_up.sh DIR started: cancel this cluster's jobs
# (by id) and wait until they are gone, then stop slurmd, slurmctld and munged by the pids in
# DIR (SIGTERM, SIGKILL after 10 s). Other clusters and services on the machine are left alone.
set -uo pipefail
DIR=${1:?usage: slurm_down.sh DIR}
export SLURM_CONF=$DIR/slurm.conf

alive() { [ -f "$DIR/$1.pid" ] && kill -0 "$(cat "$DIR/$1.pid")" 2>/dev/null; }

if alive slurmctld && [ -f "$SLURM_CONF" ]; then
  jobs=$(squeue -h -o %A 2>/dev/null | tr '\n' ' ')
  if [ -n "${jobs// /}" ]; then
    # shellcheck disable=SC2086
    scancel $jobs 2>/dev/null
    # the steps get SIGTERM, then SIGKILL after KillWait (30 s)
    for _ in $(seq 90); do
      [ -z "$(squeue -h -o %A 2>/dev/null)" ] && break
      sleep 0.5
    done
  fi
fi
stopped=0
for daemon in slurmd slurmctld munged; do
  if alive "$daemon"; then
    pid=$(cat "$DIR/$daemon.pid")
    kill "$pid"
    for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -0 "$pid" 2>/dev/null && kill -9 "$pid"
    stopped=$((stopped + 1))
  fi
  rm -f "$DIR/$daemon.pid"
done
echo "slurm_down.sh: stopped $stopped daemon(s) of $DIR"
