#!/usr/bin/env bash
# Opt-in cluster test (issue 9, part 4): a real single-node Slurm cluster on this machine runs
# pipelines/paper.toml as 4 shards (deploy/slurm/pipeline-array.sbatch, a job array) plus the
# dependent merge job (deploy/slurm/pipeline-merge.sbatch), and the merged outputs must be
# byte-identical to a local `ghostship pipeline run` of the same pipeline.
#
#   GHOSTSHIP_SLURM_TEST=1 bash tests/cluster/slurm.sh
#
# Without GHOSTSHIP_SLURM_TEST=1 it prints why and exits 0 (it installs packages and starts
# daemons, so it never runs by surprise). Needs root (or sudo) and Debian's apt.
#
# Steps (the recipe of a verified single-node setup, Slurm 22.05):
#  1. install slurm-wlm, munge and jq from apt when missing;
#  2. start munged (unless one already answers), check `munge -n | unmunge`;
#  3. write slurm.conf into a temporary folder (state, spool, logs and pid files there too;
#     SLURM_CONF points every daemon and client at it, /etc/slurm is not touched), start
#     slurmctld and slurmd, wait until the node is idle;
#  4. smoke test: a 4-task array records SLURM_ARRAY_TASK_ID/SLURM_ARRAY_TASK_COUNT, a job with
#     --dependency=afterok on it checks the four records;
#  5. ghostship: build, run the pipeline locally into one folder, submit it to Slurm with
#     deploy/slurm/submit.sh (4 shards + merge) into another, wait, then compare: the same set of
#     files, every output file byte for byte, and the set of (path, sha256) entries of the two
#     manifests, each checked against the file's own hash.
# Every failure exits non-zero. The daemons this script started are stopped (by the pids in
# their pid files) and its temporary folder removed on any exit; GHOSTSHIP_SLURM_KEEP=1 keeps the
# folder for inspection. GHOSTSHIP_SLURM_SMOKE_ONLY=1 stops after step 4;
# GHOSTSHIP_SLURM_BINARY=PATH uses that binary instead of building target/release/ghostship.
set -euo pipefail

if [[ "${GHOSTSHIP_SLURM_TEST:-}" != 1 ]]; then
    echo "tests/cluster/slurm.sh: skipped (set GHOSTSHIP_SLURM_TEST=1 to run the Slurm cluster test)"
    exit 0
fi

ROOT=$(cd "$(dirname "$0")/../.." && pwd)
SHARDS=4
PIPELINE=$ROOT/pipelines/paper.toml
TIMEOUT_S=${GHOSTSHIP_SLURM_TIMEOUT_S:-1800}

log() { printf '[slurm.sh %s] %s\n' "$(date -u +%H:%M:%S)" "$*"; }
fail() {
    printf '[slurm.sh] FAIL: %s\n' "$*" >&2
    exit 1
}

SUDO=()
if [[ $(id -u) -ne 0 ]]; then
    command -v sudo >/dev/null || fail "needs root or sudo"
    SUDO=(sudo)
fi

# --- 1. packages -------------------------------------------------------------------------------
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null ||
    ! command -v munged >/dev/null || ! command -v jq >/dev/null; then
    log "installing slurm-wlm, munge, jq"
    "${SUDO[@]}" apt-get update -qq
    DEBIAN_FRONTEND=noninteractive "${SUDO[@]}" apt-get install -y -qq slurm-wlm munge jq >/dev/null
fi

WORK=$(mktemp -d /tmp/ghostship-slurm.XXXXXX)
STARTED_MUNGED=0

cleanup() {
    local status=$?
    set +e
    if [[ -s "$WORK/slurmctld.pid" ]] && command -v scancel >/dev/null; then
        scancel --quiet --user="$(id -un)" 2>/dev/null
    fi
    for pidfile in "$WORK/slurmd.pid" "$WORK/slurmctld.pid"; do
        if [[ -s "$pidfile" ]]; then
            local pid
            pid=$(cat "$pidfile")
            "${SUDO[@]}" kill "$pid" 2>/dev/null
            for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
            kill -0 "$pid" 2>/dev/null && "${SUDO[@]}" kill -9 "$pid" 2>/dev/null
        fi
    done
    if [[ $STARTED_MUNGED == 1 && -s /run/munge/munged.pid ]]; then
        "${SUDO[@]}" kill "$(cat /run/munge/munged.pid)" 2>/dev/null
    fi
    if [[ "${GHOSTSHIP_SLURM_KEEP:-}" == 1 ]]; then
        log "kept $WORK"
    else
        "${SUDO[@]}" rm -rf "$WORK"
    fi
    if [[ $status -eq 0 ]]; then log "PASS"; else log "exit status $status"; fi
    exit "$status"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# --- 2. munge ----------------------------------------------------------------------------------
if munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    log "munged already running"
else
    [[ -s /etc/munge/munge.key ]] || "${SUDO[@]}" /usr/sbin/mungekey --create --force
    "${SUDO[@]}" chown munge:munge /etc/munge/munge.key
    "${SUDO[@]}" chmod 400 /etc/munge/munge.key
    "${SUDO[@]}" mkdir -p /run/munge
    "${SUDO[@]}" chown munge:munge /run/munge
    "${SUDO[@]}" su -s /bin/sh munge -c /usr/sbin/munged
    STARTED_MUNGED=1
    for _ in $(seq 50); do munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break; sleep 0.1; done
fi
munge -n | unmunge | grep -q 'STATUS: *Success' || fail "munge -n | unmunge does not say Success"

# --- 3. slurmctld + slurmd ---------------------------------------------------------------------
HOST=$(hostname -s)
CPUS=$(nproc)
MEM_MB=$(($(awk '/^MemAvailable:/ {print int($2 / 1024)}' /proc/meminfo) - 1024))
((MEM_MB > 512)) || fail "not enough free memory for a node ($MEM_MB MiB)"
mkdir -p "$WORK/state" "$WORK/spool" "$WORK/log" "$WORK/jobs"
export SLURM_CONF=$WORK/slurm.conf
cat >"$SLURM_CONF" <<EOF
ClusterName=ghostship-test
SlurmctldHost=$HOST
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$WORK/state
SlurmdSpoolDir=$WORK/spool
SlurmctldLogFile=$WORK/log/slurmctld.log
SlurmdLogFile=$WORK/log/slurmd.log
SlurmctldPidFile=$WORK/slurmctld.pid
SlurmdPidFile=$WORK/slurmd.pid
SlurmctldPort=${GHOSTSHIP_SLURMCTLD_PORT:-6817}
SlurmdPort=${GHOSTSHIP_SLURMD_PORT:-6818}
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
SchedulerType=sched/backfill
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
MinJobAge=600
NodeName=$HOST CPUs=$CPUS RealMemory=$MEM_MB State=UNKNOWN
PartitionName=test Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
EOF
log "starting slurmctld and slurmd ($HOST, $CPUS CPUs, $MEM_MB MiB) in $WORK"
"${SUDO[@]}" env SLURM_CONF="$SLURM_CONF" slurmctld
"${SUDO[@]}" env SLURM_CONF="$SLURM_CONF" slurmd
idle=0
for _ in $(seq 60); do
    if sinfo --noheader --nodes="$HOST" --format=%t 2>/dev/null | grep -qx 'idle'; then
        idle=1
        break
    fi
    sleep 1
done
if [[ $idle != 1 ]]; then
    tail -n 20 "$WORK/log/slurmctld.log" "$WORK/log/slurmd.log" >&2 || true
    fail "node $HOST did not become idle"
fi
log "node idle: $(sinfo --noheader --format='%P %D %t %c CPUs')"

# Wait until job $1 (a plain job or an array) has left the queue; print its final states.
wait_for_job() {
    local id=$1 deadline=$((SECONDS + TIMEOUT_S)) states
    while ((SECONDS < deadline)); do
        states=$(scontrol show job -o "$id" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | sort -u)
        [[ -n "$states" ]] || fail "job $id unknown to slurmctld"
        if ! grep -qE 'JobState=(PENDING|RUNNING|CONFIGURING|COMPLETING|SUSPENDED|REQUEUED)' <<<"$states"; then
            echo "$states"
            return 0
        fi
        sleep 1
    done
    fail "job $id still queued or running after ${TIMEOUT_S}s"
}

# --- 4. smoke test: array + dependent job --------------------------------------------------------
cat >"$WORK/jobs/record.sh" <<'EOF'
#!/bin/sh
echo "$SLURM_ARRAY_TASK_ID $SLURM_ARRAY_TASK_COUNT" > "$RECORDS/task-$SLURM_ARRAY_TASK_ID"
EOF
cat >"$WORK/jobs/check.sh" <<'EOF'
#!/bin/sh
set -e
for k in 1 2 3 4; do grep -qx "$k 4" "$RECORDS/task-$k"; done
echo ok > "$RECORDS/checked"
EOF
mkdir -p "$WORK/records"
export RECORDS=$WORK/records
array=$(sbatch --parsable --array=1-4 --chdir="$WORK/jobs" --output="$WORK/log/record-%A_%a.out" \
    --export=ALL "$WORK/jobs/record.sh")
array=${array%%;*}
check=$(sbatch --parsable --dependency="afterok:$array" --kill-on-invalid-dep=yes \
    --chdir="$WORK/jobs" --output="$WORK/log/check-%j.out" --export=ALL "$WORK/jobs/check.sh")
check=${check%%;*}
log "smoke: array $array (4 tasks), dependent job $check"
states=$(wait_for_job "$array")
[[ "$states" == "JobState=COMPLETED" ]] || fail "smoke array $array ended: $states"
states=$(wait_for_job "$check")
[[ "$states" == "JobState=COMPLETED" ]] || fail "smoke dependent job $check ended: $states"
[[ -f "$RECORDS/checked" ]] || fail "the dependent job did not see the four task records"
log "smoke: 4 tasks recorded ids 1-4 of 4; the afterok job ran after them and checked them"

if [[ "${GHOSTSHIP_SLURM_SMOKE_ONLY:-}" == 1 ]]; then
    log "GHOSTSHIP_SLURM_SMOKE_ONLY=1: skipping the ghostship pipeline part"
    exit 0
fi

# --- 5. ghostship: 4 shards + merge on Slurm against one local run -------------------------------
if [[ -n "${GHOSTSHIP_SLURM_BINARY:-}" ]]; then
    export GHOSTSHIP=$GHOSTSHIP_SLURM_BINARY # another build (or a stand-in) to test
else
    log "building ghostship (release)"
    (cd "$ROOT" && cargo build --release --quiet)
    export GHOSTSHIP=$ROOT/target/release/ghostship
fi
LOCAL=$WORK/local
CLUSTER=$WORK/cluster
log "local run of $PIPELINE"
"$GHOSTSHIP" pipeline run "$PIPELINE" --out "$LOCAL" --quiet
ids=$("$ROOT/deploy/slurm/submit.sh" "$PIPELINE" "$CLUSTER" "$SHARDS" \
    --chdir="$WORK/jobs" --output="$WORK/log/%x-%A_%a.out")
array=$(sed -n 1p <<<"$ids")
merge=$(sed -n 2p <<<"$ids")
log "cluster: array $array ($SHARDS shards), merge $merge"
states=$(wait_for_job "$array")
if [[ "$states" != "JobState=COMPLETED" ]]; then
    tail -n 20 "$WORK"/log/ghostship-shard-* >&2 || true
    fail "shard array $array ended: $states"
fi
states=$(wait_for_job "$merge")
if [[ "$states" != "JobState=COMPLETED" ]]; then
    tail -n 20 "$WORK"/log/ghostship-merge-* >&2 || true
    fail "merge job $merge ended: $states"
fi

# Manifests (manifest.json and any shard manifest manifest*.json) are compared by their entries,
# every other file byte for byte.
is_manifest() { [[ $(basename "$1") == manifest*.json ]]; }
list_files() { (cd "$1" && find . -type f | sed 's|^\./||' | LC_ALL=C sort); }
: >"$WORK/outputs.local"
: >"$WORK/outputs.cluster"
while read -r f; do is_manifest "$f" || echo "$f" >>"$WORK/outputs.local"; done < <(list_files "$LOCAL")
while read -r f; do is_manifest "$f" || echo "$f" >>"$WORK/outputs.cluster"; done < <(list_files "$CLUSTER")
[[ -s "$WORK/outputs.local" ]] || fail "the local run wrote no output files"
if ! diff -u "$WORK/outputs.local" "$WORK/outputs.cluster"; then
    fail "the sharded run wrote a different set of files than the local run (diff above)"
fi
count=0
while read -r f; do
    cmp -s "$LOCAL/$f" "$CLUSTER/$f" || fail "$f differs between the local and the sharded run"
    count=$((count + 1))
done <"$WORK/outputs.local"
log "$count output files byte-identical"

# The manifests' outputs as "path sha256" lines: every job's `outputs` map (path relative to
# the output folder → {sha256, bytes}).
manifest_outputs() {
    jq -r '[.jobs[] | (.outputs // {}) | to_entries[] | "\(.key) \(.value.sha256)"]
           | sort | .[]' "$1"
}
[[ -f "$LOCAL/manifest.json" ]] || fail "the local run wrote no manifest.json"
[[ -f "$CLUSTER/manifest.json" ]] || fail "the merge wrote no manifest.json"
manifest_outputs "$LOCAL/manifest.json" >"$WORK/manifest.local"
manifest_outputs "$CLUSTER/manifest.json" >"$WORK/manifest.cluster"
[[ -s "$WORK/manifest.local" ]] || fail "no (path, sha256) entries found in the local manifest.json"
if ! diff -u "$WORK/manifest.local" "$WORK/manifest.cluster"; then
    fail "the merged manifest lists other outputs than the local run's (diff above)"
fi
# Each entry's hash is the file's (paths relative to the output folder).
while read -r path sha; do
    [[ -f "$CLUSTER/$path" ]] || fail "merged manifest lists $path, which is not in $CLUSTER"
    actual=$(sha256sum "$CLUSTER/$path" | cut -d' ' -f1)
    [[ "$actual" == "$sha" ]] || fail "$path: manifest sha256 $sha, file $actual"
done <"$WORK/manifest.cluster"
log "merged manifest: $(wc -l <"$WORK/manifest.cluster") outputs, the local run's set, hashes match the files"
