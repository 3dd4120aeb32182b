#!/bin/bash
# Submits a nightly reprocessing: N shard tasks, then the commit.
#   ARCHIVES="/data/2026 /data/2025" DATASET=/data/kpi-dataset SHARDS=8 deploy/slurm/nightly.sh
# Extra sbatch options (partition, account, time, cpus) go in SBATCH_OPTS.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
shards=${SHARDS:-4}
export ARCHIVES DATASET ENGINE TIREWEAR
# shellcheck disable=SC2086 # SBATCH_OPTS is a list of options
array=$(sbatch --parsable ${SBATCH_OPTS:-} --array="1-$shards" "$here/shard.sbatch")
# shellcheck disable=SC2086
commit=$(sbatch --parsable ${SBATCH_OPTS:-} --dependency="afterany:$array" "$here/commit.sbatch")
echo "shards: job $array (1-$shards); commit: job $commit"
