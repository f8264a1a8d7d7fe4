#!/usr/bin/env bash
# End-to-end test of `relume slurm --submit` on a one-node Slurm cluster started here
# (Debian's slurm-wlm: munged, slurmctld and slurmd on localhost, everything under a temporary
# folder, the system's own configuration untouched): PathTrace on graphs/reference_cornell.ron
# as an array job of 3 tasks plus the gather job, whose image must equal an unsharded run's
# byte for byte.
#
#   tests/scripts/slurm_e2e.sh [RELUME_BINARY]     (default: target/release/relume)
#
# Exit codes: 0 passed; 1 failed (a relume or Slurm job problem); 77 skipped: Slurm or munge is
# not installed, not root, or the daemons would not start (the reason is printed on the last
# line, "skipped: <why>"). Set KEEP=1 to keep the temporary folder.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT="$PWD"
RELUME="$(realpath "${1:-target/release/relume}")"
SPP="${SPP:-8}"
TIMEOUT="${TIMEOUT:-150}"

skip() {
  echo "skipped: $*"
  exit 77
}
fail() {
  echo "FAILED: $*" >&2
  exit 1
}

[ -x "$RELUME" ] || fail "no relume binary at $RELUME (cargo build --release first)"
[ "$(id -u)" = 0 ] || skip "starting slurmctld and slurmd needs root"
for p in munged mungekey slurmctld slurmd sbatch squeue scontrol; do
  command -v "$p" >/dev/null || skip "$p is not installed (apt-get install slurm-wlm)"
done

E2E="$(mktemp -d /tmp/relume-slurm-e2e.XXXXXX)"
chmod 755 "$E2E"
PIDS=()
cleanup() {
  for pid in "${PIDS[@]}"; do
    kill "$pid" 2>/dev/null || true
  done
  for pid in "${PIDS[@]}"; do
    wait "$pid" 2>/dev/null || true
  done
  if [ "${KEEP:-0}" = 1 ]; then
    echo "kept $E2E"
  else
    rm -rf "$E2E"
  fi
}
trap cleanup EXIT

show_logs() {
  for f in "$E2E"/log/*.log "$E2E"/work/slurm\ scripts/*.log; do
    [ -f "$f" ] || continue
    echo "--- $f"
    tail -n 30 "$f"
  done
}

# Ports out of the default range, so a real Slurm on this machine is left alone.
CTLD_PORT=$((17000 + RANDOM % 2000))
SLURMD_PORT=$((CTLD_PORT + 2000))
mkdir -p "$E2E"/{munge,state,spool,log,work}
chmod 711 "$E2E/munge"

# munge: a key of our own and a socket in the temporary folder.
mungekey --create --keyfile="$E2E/munge/munge.key" >/dev/null 2>&1 || skip "mungekey could not create a key"
munged --foreground --force --socket="$E2E/munge/munge.sock" --key-file="$E2E/munge/munge.key" \
  --pid-file="$E2E/munge/munged.pid" --seed-file="$E2E/munge/munged.seed" --log-file="$E2E/log/munged.log" >"$E2E/log/munged.out" 2>&1 &
PIDS+=($!)
for _ in $(seq 50); do
  [ -S "$E2E/munge/munge.sock" ] && break
  sleep 0.1
done
[ -S "$E2E/munge/munge.sock" ] || { show_logs; skip "munged did not start"; }

export SLURM_CONF="$E2E/slurm.conf"
cat >"$SLURM_CONF" <<EOF
# A one-node cluster for relume's end-to-end test (tests/scripts/slurm_e2e.sh).
ClusterName=relume-e2e
SlurmctldHost=localhost
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$E2E/munge/munge.sock
CredType=cred/munge
StateSaveLocation=$E2E/state
SlurmdSpoolDir=$E2E/spool
SlurmctldPidFile=$E2E/slurmctld.pid
SlurmdPidFile=$E2E/slurmd.pid
SlurmctldLogFile=$E2E/log/slurmctld.log
SlurmdLogFile=$E2E/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/builtin
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
JobAcctGatherType=jobacct_gather/none
MpiDefault=none
ReturnToService=2
MinJobAge=600
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$(nproc) State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
# The plugin stack of the system configuration, if any, is not ours to load.
: >"$E2E/plugstack.conf"
echo "PlugStackConfig=$E2E/plugstack.conf" >>"$SLURM_CONF"

slurmctld -D -i -f "$SLURM_CONF" >"$E2E/log/slurmctld.out" 2>&1 &
PIDS+=($!)
slurmd -D -N localhost -f "$SLURM_CONF" >"$E2E/log/slurmd.out" 2>&1 &
PIDS+=($!)
up=""
for _ in $(seq 100); do
  if scontrol show node localhost 2>/dev/null | grep -Eq "State=(IDLE|MIXED|ALLOCATED)"; then
    up=1
    break
  fi
  sleep 0.2
done
[ -n "$up" ] || {
  show_logs
  cat "$E2E"/log/*.out
  skip "slurmctld and slurmd did not bring the node up within 20 s"
}
echo "Slurm is up: $(sinfo -h -o '%P %D %t %c' 2>/dev/null || true)"

START=$(date +%s)
W="$E2E/work"
# The graph path, the cache and the script folder hold spaces: the scripts must quote them.
ln -s "$ROOT/graphs" "$W/graph dir"
G="$W/graph dir/reference_cornell.ron"

"$RELUME" slurm "$G" --node reference --shards 3 --set "reference.spp=$SPP" --output image \
  --cache "$W/shared cache" --out "$W/out" --script-dir "$W/slurm scripts" --partition debug --time 00:10:00 \
  --cpus-per-task 1 --relume "$RELUME" --submit | tee "$W/submit.txt" || { show_logs; fail "relume slurm --submit failed"; }
ARRAY_ID=$(sed -n 's/^array job \([0-9]*\)$/\1/p' "$W/submit.txt")
GATHER_ID=$(sed -n 's/^gather job \([0-9]*\)$/\1/p' "$W/submit.txt")
[ -n "$ARRAY_ID" ] && [ -n "$GATHER_ID" ] || fail "relume slurm --submit did not print both job ids"

# Meanwhile, the unsharded run to compare with (its own cache).
"$RELUME" run "$G" --set "reference.spp=$SPP" --output image --cache "$W/cache-unsharded" --out "$W/unsharded" -q

while [ -n "$(squeue -h -j "$ARRAY_ID,$GATHER_ID" 2>/dev/null)" ]; do
  if [ $(($(date +%s) - START)) -gt "$TIMEOUT" ]; then
    squeue
    show_logs
    fail "the jobs did not finish within $TIMEOUT s"
  fi
  sleep 1
done
ELAPSED=$(($(date +%s) - START))

states=$(scontrol -o show job "$ARRAY_ID" | grep -o 'JobState=[A-Z_]*' | sort | uniq -c | tr -s ' ')
gstate=$(scontrol -o show job "$GATHER_ID" | grep -o 'JobState=[A-Z_]*')
echo "array job $ARRAY_ID:$states; gather job $GATHER_ID: $gstate"
tasks_done=$(scontrol -o show job "$ARRAY_ID" | grep -c 'JobState=COMPLETED' || true)
[ "$tasks_done" = 3 ] || {
  show_logs
  fail "expected 3 completed array tasks, got $tasks_done"
}
[ "$gstate" = "JobState=COMPLETED" ] || {
  show_logs
  fail "the gather job ended $gstate"
}
cmp "$W/out/image.exr" "$W/unsharded/image.exr" || fail "the gathered image differs from the unsharded run's"
python3 - "$W/out/report.json" <<'PY' || fail "the gather's report does not show every chunk from the cache"
import json, sys
n = next(n for n in json.load(open(sys.argv[1]))["nodes"] if n["id"] == "reference")
s = n["shards"]
print(f"gather report: reference {n['status']}, {s['chunks']} chunks, {s['cached']} cached, {s['ran']} ran")
sys.exit(0 if s["cached"] == s["chunks"] and s["ran"] == 0 else 1)
PY
# The logs land where the quoted #SBATCH --output lines say (a folder with a space).
for i in 0 1 2; do
  [ -f "$W/slurm scripts/reference_cornell-reference-shard-$i.json" ] || fail "array task $i wrote no report"
  [ -f "$W/slurm scripts/reference_cornell-reference-shard-${ARRAY_ID}_$i.log" ] || fail "array task $i wrote no log"
done
[ -f "$W/slurm scripts/reference_cornell-reference-gather-$GATHER_ID.log" ] || fail "the gather job wrote no log"
echo "passed: 3 array tasks and the gather on Slurm in ${ELAPSED} s; image.exr byte-identical to the unsharded run"
