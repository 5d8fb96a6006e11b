#!/usr/bin/env bash
# One `surfsynth sweep` split over a Slurm job array: array task I of N runs
# shard I/N (shards count from 1, so the array does too), i.e. runs I, I+N,
# I+2N, ... of the grid's run list. Every task writes into the same sweep
# folder on a shared file system; each run has its own sub-folder, so the
# tasks never write the same run.
#
# Submit from the repository root (relative paths resolve against the
# submission folder), then rebuild the report once every task has ended:
#
#   jid=$(sbatch --parsable examples/sweep_job_array.sh)
#   sbatch --dependency=afterany:"$jid" --wrap "surfsynth sweep --summarise out/sweep_cluster"
#
# Each task writes summary.csv, summary.json and index.html as it ends, from
# the run folders present then; the --summarise job after the last task
# gives the page of the whole grid. Submitting the array again resumes it:
# complete runs (done.json with the same resolved config) are skipped, the
# others re-run. Check the grid first on the login node:
#
#   surfsynth sweep configs/00_default.toml --out out/sweep_cluster \
#       --grid seed=1,2,3,4 --grid input.texture_scale=0.2,0.3,0.5 --dry-run
#
# Keep --array=1-N and SHARDS=N equal.

#SBATCH --job-name=surfsynth-sweep
#SBATCH --array=1-4
#SBATCH --cpus-per-task=4
#SBATCH --mem=8G
#SBATCH --time=02:00:00
#SBATCH --output=slurm-%A_%a.out

set -euo pipefail

SHARDS=4                                   # = the N of --array=1-N
CONFIG=${CONFIG:-configs/00_default.toml}
OUT=${OUT:-out/sweep_cluster}              # on a file system every node sees
SURFSYNTH=${SURFSYNTH:-surfsynth}          # or target/release/surfsynth

if [ -n "${SLURM_ARRAY_TASK_COUNT:-}" ] && [ "$SLURM_ARRAY_TASK_COUNT" != "$SHARDS" ]; then
  echo "error: the array has $SLURM_ARRAY_TASK_COUNT tasks but SHARDS=$SHARDS" >&2
  exit 2
fi
cd "${SLURM_SUBMIT_DIR:-.}"

# One run at a time per task, on all the task's cores (results do not
# depend on the thread count). --timeout kills a run that hangs; it is
# reported as failed and the others go on.
exec "$SURFSYNTH" sweep "$CONFIG" --out "$OUT" \
  --grid seed=1,2,3,4 \
  --grid input.texture_scale=0.2,0.3,0.5 \
  --shard "${SLURM_ARRAY_TASK_ID:?run this with sbatch}/$SHARDS" \
  --jobs 1 --threads "${SLURM_CPUS_PER_TASK:-1}" \
  --timeout 3600 --quiet
