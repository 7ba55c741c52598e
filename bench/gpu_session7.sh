#!/usr/bin/env bash
# GPU runs of session 7 (issue #13): the acceptance runs at images_4, 10,000 it, over seeds 0-2, with the capture
# defaults of configs/nerfstudio.yaml (the full method now with full.growth_budget=1.0: session 6's single run on
# castle_p30 at 9 views gave 22.58 with it against 20.28 without and 21.63 for the baseline).
# On a lent 2-GPU host, after the packed wheels are in /tmp/site and the scenes in $D:
#   bash bench/gpu_session7.sh PHASE D RUNS
#   a: full, seed 0 (6 runs); baseline, seed 1 (6 runs); baseline seed 0 on castle_p30 at 9 views, to check that
#      session 6's baseline runs (seed 0) are reproduced exactly
#   b: resume a's unfinished runs; full, seed 1; baseline, seed 2
#   c: resume; full, seed 2
#   d: resume what is left
# Each run stops with SIGINT after T s (checkpointed) and the next phase resumes it; RUNS/<name>/metrics.json
# (gather: bench/gather_runs.py).
set -u
P=$1; D=$2; R=$3; mkdir -p "$R"
GPUS=${GPUS:-2}; source bench/gpu_runs.sh  # sp, spt, acceptance_i4
T=${T:-540}
resume() { for d in "$R"/*_i4_s*; do [ -d "$d" ] && [ ! -f "$d/metrics.json" ] && spt "$T" "$(basename "$d")" --resume "$d" & done; }
case $P in
a) METHODS=full SUF=_s0 acceptance_i4 "$T" --seed 0
   METHODS=baseline SUF=_s1 acceptance_i4 "$T" --seed 1
   spt "$T" c9_baseline_i4_s0 --data "$D/castle_p30" --downscale 4 --views 9 --method baseline --iterations 10000 --seed 0 & ;;
b) resume; METHODS=full SUF=_s1 acceptance_i4 "$T" --seed 1; METHODS=baseline SUF=_s2 acceptance_i4 "$T" --seed 2 ;;
c) resume; METHODS=full SUF=_s2 acceptance_i4 "$T" --seed 2 ;;
d) resume ;;
esac
wait
python3 bench/gather_runs.py "$R" "$OUT/runs_$P.json" --logs "$OUT/logs_$P.txt"
