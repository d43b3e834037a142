#!/usr/bin/env bash
# The scheduler test: a real one-node Slurm (slurmctld + slurmd, munge authentication,
# select/cons_tres, proctrack/linuxproc) runs the documented job array
# (tests/scheduler/sample_array.sbatch) as four tasks of `trainer sample --shard K/4`;
# `trainer merge` of the four shards must be byte-identical (`cmp`) to one unsharded run.
#
# Usage: tests/scheduler/slurm_one_node.sh TRAINER_BINARY [PROBLEM_FILE]
# Installs slurm-wlm and munge from Debian when missing (root, apt-get). Every failure is
# loud and non-zero: a daemon that cannot start fails the test, it is never skipped.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
trainer="$(realpath "${1:?usage: $0 TRAINER_BINARY [PROBLEM_FILE]}")"
problem="$(realpath "${2:-$repo/configs/pendulum.toml}")"
tasks=4
fail() { echo "FATAL (slurm test): $*" >&2; exit 1; }
[ -x "$trainer" ] || fail "$trainer is not an executable trainer binary"

if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v munged >/dev/null; then
  echo "== installing slurm-wlm and munge (Debian packages) for the scheduler test"
  { apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y slurm-wlm munge; } ||
    fail "cannot install slurm-wlm / munge"
fi

work="$(mktemp -d /tmp/ampc-slurm.XXXXXX)"
chmod 755 "$work"
conf="$work/slurm.conf"
host="$(hostname -s)"
cpus="$(nproc)"
mem_mb=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 512 ))
mkdir -p "$work/spool/ctld" "$work/spool/d" "$work/log" "$work/munge" "$work/run"

cleanup() {
  local rc=$?
  [ -f "$work/run/slurmd.pid" ] && kill "$(cat "$work/run/slurmd.pid")" 2>/dev/null || true
  [ -f "$work/run/slurmctld.pid" ] && kill "$(cat "$work/run/slurmctld.pid")" 2>/dev/null || true
  [ -f "$work/munge/munged.pid" ] && kill "$(cat "$work/munge/munged.pid")" 2>/dev/null || true
  if [ $rc -ne 0 ]; then
    echo "---- slurmctld log" >&2; tail -n 40 "$work/log/slurmctld.log" >&2 2>/dev/null || true
    echo "---- slurmd log" >&2; tail -n 40 "$work/log/slurmd.log" >&2 2>/dev/null || true
    echo "---- job outputs" >&2; cat "$work"/job/shards/slurm-*.out >&2 2>/dev/null || true
  fi
  exit $rc
}
trap cleanup EXIT

# munge: its own key, socket and pid file in the work folder (no system service needed).
# The socket's folder must be open to all (munge checks), the key's private to munge.
priv="$work/munge-private"
mkdir -p "$priv"
key="$priv/munge.key"
dd if=/dev/urandom of="$key" bs=1024 count=1 status=none
chown munge:munge "$work/munge" "$priv" "$key" || fail "cannot give the munge files to user munge"
chmod 755 "$work/munge"; chmod 700 "$priv"; chmod 400 "$key"
sock="$work/munge/munge.socket.2"
runuser -u munge -- munged --key-file="$key" --socket="$sock" \
  --pid-file="$work/munge/munged.pid" --log-file="$priv/munged.log" \
  --seed-file="$priv/munged.seed" ||
  fail "munged does not start (log: $(cat "$priv/munged.log" 2>/dev/null))"
munge -S "$sock" -n | unmunge -S "$sock" >/dev/null || fail "munge cannot encode/decode a credential"

cat > "$conf" <<EOF
ClusterName=ampc
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$sock
CredType=cred/munge
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
ReturnToService=2
StateSaveLocation=$work/spool/ctld
SlurmdSpoolDir=$work/spool/d
SlurmctldPidFile=$work/run/slurmctld.pid
SlurmdPidFile=$work/run/slurmd.pid
SlurmctldLogFile=$work/log/slurmctld.log
SlurmdLogFile=$work/log/slurmd.log
SlurmctldPort=$(( 16817 + RANDOM % 1000 ))
SlurmdPort=$(( 18818 + RANDOM % 1000 ))
NodeName=$host CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=ampc Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF="$conf"

echo "== starting slurmctld and slurmd on $host ($cpus CPUs)"
slurmctld -c || fail "slurmctld does not start"
slurmd || fail "slurmd does not start"
for _ in $(seq 1 60); do
  state="$(sinfo -h -N -o '%T' 2>/dev/null | head -n1 || true)"
  [ "$state" = "idle" ] && break
  sleep 1
done
[ "$state" = "idle" ] || fail "the node never became idle (state: '${state:-none}')"
sinfo

# The documented job array, as written, submitted as $tasks tasks.
mkdir -p "$work/job/shards"
cp "$problem" "$work/job/problem.toml"
cd "$work/job"
echo "== sbatch --array=0-$((tasks - 1)) sample_array.sbatch"
PATH="$(dirname "$trainer"):$PATH" AMPC_CONFIG=problem.toml \
  sbatch --wait --array=0-$((tasks - 1)) "$here/sample_array.sbatch" ||
  fail "the job array failed (sbatch --wait returned non-zero)"
ls shards
for k in $(seq 0 $((tasks - 1))); do
  [ -s "shards/part-$k.bin" ] || fail "array task $k wrote no shards/part-$k.bin"
done
"$trainer" merge merged.bin shards/part-*.bin
"$trainer" sample --config problem.toml --out single.bin --quiet
cmp merged.bin single.bin || fail "the merged shards differ from the unsharded run"
echo "== slurm: $tasks array tasks merged = the unsharded run (cmp equal, $(stat -c %s single.bin) bytes)"
