# Shared by bench/gpu_session*.sh (source it after setting R, the runs folder, and D, the scenes folder).
# sp NAME ARGS...: one run of warpgs.pipelines.sparse on CUDA into $R/NAME (log $R/NAME.log).
# spt T NAME ARGS...: the same, stopped with SIGINT after T s (it checkpoints; resume with --resume $R/NAME).
# Runs are spread over $GPUS GPUs round-robin (default 1) and share the cores (OMP_NUM_THREADS=1).
# acceptance_i4 T [ARGS...]: issue 13's acceptance runs, images_4, 10,000 it, castle_p30 / herz_jesus_p25 x
# 3 / 6 / 9 views, baseline and full (METHODS, default both), named <c|h><views>_<method>_i4$SUF, in the background.
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
GPUS=${GPUS:-1}; rm -f "$R/.k"
gpu() { flock "$R/.k.lock" bash -c "n=\$(cat '$R/.k' 2>/dev/null || echo 0); echo \$((n + 1)) > '$R/.k'; echo \$((n % $GPUS))"; }
sp() { local name=$1; shift; local g; g=$(gpu)
       CUDA_VISIBLE_DEVICES=$g python3 -m warpgs.pipelines.sparse --no-progress --device cuda --out "$R/$name" "$@" \
       > "$R/$name.log" 2>&1; echo "$name rc=$?"; }
spt() { local t=$1 name=$2; shift 2; local g; g=$(gpu)
        CUDA_VISIBLE_DEVICES=$g timeout -s INT "$t" python3 -m warpgs.pipelines.sparse --no-progress \
        --device cuda --out "$R/$name" "$@" >> "$R/$name.log" 2>&1; echo "$name rc=$?"; }
acceptance_i4() { local t=$1; shift
  for sc in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
    for m in ${METHODS:-baseline full}; do
      spt "$t" "${sc:0:1}${v}_${m}_i4${SUF:-}" --data "$D/$sc" --downscale 4 --views $v --method $m --iterations 10000 "$@" &
    done
  done; done
}
