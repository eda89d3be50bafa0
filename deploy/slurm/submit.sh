#!/usr/bin/env bash
# Submit a ghostship pipeline to Slurm as N shards plus a dependent merge job:
#
#   deploy/slurm/submit.sh PIPELINE.toml OUT_DIR N [extra sbatch options…]
#
# OUT_DIR must be on a file system every node sees. Prints the array job id and the merge job id
# (one per line). The merge job waits for every shard (--dependency=afterok) and is cancelled if
# any shard fails (--kill-on-invalid-dep=yes). GHOSTSHIP (the binary) is passed through.
set -euo pipefail
if [[ $# -lt 3 ]]; then
    echo "usage: $0 PIPELINE.toml OUT_DIR N [sbatch options…]" >&2
    exit 2
fi
pipeline=$1 out=$2 shards=$3
shift 3
if ! [[ "$shards" =~ ^[1-9][0-9]*$ ]]; then
    echo "error: N must be a positive integer, got '$shards'" >&2
    exit 2
fi
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$out"
pipeline=$(realpath "$pipeline")
out=$(realpath "$out")
export PIPELINE=$pipeline OUT=$out GHOSTSHIP=${GHOSTSHIP:-ghostship}
array=$(sbatch --parsable --array="1-$shards" --export=ALL "$@" "$here/pipeline-array.sbatch")
array=${array%%;*}
merge=$(sbatch --parsable --dependency="afterok:$array" --kill-on-invalid-dep=yes \
    --export=ALL "$@" "$here/pipeline-merge.sbatch")
merge=${merge%%;*}
echo "$array"
echo "$merge"
