#!/usr/bin/env bash
# GPU runs for issue #7's synthetic point: the embedded scene (3 views), baseline and full-method
# settings at equal iterations, in parallel on one GPU.   bash bench/gpu_synthetic_variants.sh RUNS_DIR
set -u
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
R=$1; mkdir -p "$R"
sp() { local name=$1; shift; python3 -m warpgs.pipelines.sparse --no-progress --device cuda --out "$R/$name" "$@" \
       > "$R/$name.log" 2>&1; echo "$name rc=$?"; }
sp s_base --method baseline &
sp s_full --method full &
sp s_c3 --method full --cycles 3 &
sp s_nf13 --method full --set full.n_frames=13 &
sp s_bf3 --method full --set full.baseline_fraction=0.3 &
sp s_c3bf3 --method full --cycles 3 --set full.baseline_fraction=0.3 &
sp s_base800 --method baseline --iterations 800 &
sp s_full800 --method full --iterations 800 &
wait
