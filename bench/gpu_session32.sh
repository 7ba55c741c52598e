#!/usr/bin/env bash
# GPU runs prepared in session 31 for the next session, after the packed wheels are installed in /tmp/site and the
# scenes copied to $D (images_4 of castle_p30 and herz_jesus_p25 for phase k).
#   T=seconds bash bench/gpu_session32.sh PHASE D RUNS
# k: the five images_4 runs (768x512, 10,000 it) of the captures' default that session 31's device time did not
#    finish, seed 2: castle_p30 9 views full, herz_jesus_p25 3 / 6 / 9 views full and 9 views baseline (spline path,
#    3 poses: the default again since session 31). One call, 5 at a time. Copy $OUT/k369.txt to
#    bench/results/s32/k369.txt; bench/readme_results.py reads it beside s31/k369.txt.
# p: issue 15's host profile at 138k Gaussians without cProfile: py-spy (from .device/pyspy, installed into
#    /tmp/pyspy) records bench/rasterizer_host.py --loop 10 for warpgs, then for gsplat (from .device/gsplat), at
#    200 Hz with native frames; the raw profiles gzipped and bench/spy_summary.py's summaries into $OUT. Then
#    bench/rasterizer.py's three configurations (7 rounds), to put the profile beside a ratio of the same machine.
# L: lego 8 views (10,000 it, seeds 0-2) with session 17's best baseline setting (DropGaussian 0.2, opacity noise 0.8,
#    SH degree 1; 23.96 in session 31) and DropGaussian's own Blender recipe, one change at a time (DCVL-3D/
#    DropGaussian_release: white background without random backgrounds, no pruning of large Gaussians, 10,000 random
#    starting points in [-1, 1]^3 with opacity 0.1), all three together, and all three at 20,000 it. Needs blender_lego
#    in $D. Summary lines in $OUT/L.txt (python bench/seed_medians.py prints the medians).
# r: issue 15's host cuts at 138k (session 32: one host read without the largest depth on CUDA, camera tuples made
#    once per view and not rewritten into a launch, no float()/contiguous() calls on float32 contiguous inputs):
#    the CUDA rasterizer tests; bench/rasterizer.py at 138,766 Gaussians, 15 rounds, the code before them
#    (.device/old.tar: git archive of d8c358d's warpgs, bench and tests, unpacked into /tmp/old) and after, twice in
#    turn. t: the three configurations (7 rounds, the first again at the end); then fern's baseline trained (3
#    views, 3000 it) and bench/rasterizer.py on its Gaussians (SH degree 3) at 1x, 2x and 3x the test view.
# v: after the fix of r's finding (the launcher kept every struct argument's tuple, so a step's autograd graph outlived
#    it and the next step's CUDA graph capture failed; only KeptFields are kept now): the CUDA tests of the rasterizer,
#    the binning and the graph fallback (-k "cuda or fallback": the CPU ones, and test_launch's stand-ins, need Warp's
#    CPU compiler, which the packed Warp lacks there; TESTS_ONLY=1 stops after them), bench/graph_check.py (plain fern, 1000 it: the graphs recorded, and every
#    parameter and loss equal to the eager run's bit for bit), bench/train_speed.py (fern 3 views, 3000 it,
#    DropGaussian 0.2, against the gsplat loop). Then t again for the figures of the final code.
# M: lego 8 views, 10,000 it, seeds 0-2: more of session 17's best setting's neighbours (L found DropGaussian's recipe
#    no better): a lower growth threshold (strategy.grow_grad2d 0.0001 / 0.00015; 0.0004 lost 0.27 dB in session 17),
#    a higher drop rate (0.3), less opacity noise (0.6), and growth until the end (strategy.refine_stop_iter 10000 is
#    already the run's length: instead the position learning rate's final value x10, means_lr_final 1.6e-5). Needs
#    blender_lego in $D. Summary lines in $OUT/M.txt.
# N: M's winner, the position learning rate decaying to 1.6e-5 instead of 1.6e-6 (optim.means_lr_final; 24.27 at 10,000
#    it), at 20,000 it, and with no decay at all (1.6e-4) at 10,000 it; seeds 0-2, 6 runs at once. N.txt.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
ISSUE15=138766x648x420,555000x1280x720,1100000x1920x1080,138766x648x420  # issue 15's three configurations, the first again
case $P in
k)
  FLOAT="--set train.path_floaters_paths=spline --set train.path_floaters_poses=3"
  { echo "k_castle_p30_9v_full_s2 full castle_p30 9 2 $FLOAT"
    for v in 3 6 9; do echo "k_herz_jesus_p25_${v}v_full_s2 full herz_jesus_p25 $v 2 $FLOAT"; done
    echo "k_herz_jesus_p25_9v_baseline_s2 baseline herz_jesus_p25 9 2 $FLOAT"
  } | DS=4 IT=10000 xargs -P ${JOBS:-5} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary k_ k369.txt
  ;;
p)
  install_gsplat
  python3 -m pip install -q --no-index --no-deps --target /tmp/pyspy .device/pyspy/*.whl 2>/dev/null
  for who in warpgs gsplat; do
    timeout 200 /tmp/pyspy/bin/py-spy record --native --idle --threads -r 200 -f raw -o "$OUT/spy_$who.txt" -- \
      python3 bench/rasterizer_host.py --loop 10 --only $who > "$OUT/spy_$who.log" 2>&1
    tail -2 "$OUT/spy_$who.log"
    python3 bench/spy_summary.py "$OUT/spy_$who.txt" --under timed_loop --rows 60 > "$OUT/spy_${who}_summary.txt" 2>&1
    head -40 "$OUT/spy_${who}_summary.txt"
    gzip -f "$OUT/spy_$who.txt"
  done
  CONFIGS=$ISSUE15 rasterizer_configs --warmup 10 --iters 20 --rounds ${ROUNDS:-7}
  ;;
L)
  WHITE="--set train.random_background=false"
  NOBIG="--set strategy.prune_scale3d=1000"
  BOX="--set model.init=box --set model.init_num=10000 --set model.init_box=[-1,-1,-1,1,1,1]"
  { for s in 0 1 2; do
      echo "lego L_all20k_s$s baseline $s 20000 $LEGO_BEST $WHITE $NOBIG $BOX"
      echo "lego L_white_s$s baseline $s 10000 $LEGO_BEST $WHITE"
      echo "lego L_nobig_s$s baseline $s 10000 $LEGO_BEST $NOBIG"
      echo "lego L_box_s$s baseline $s 10000 $LEGO_BEST $BOX"
      echo "lego L_all_s$s baseline $s 10000 $LEGO_BEST $WHITE $NOBIG $BOX"
    done; } | xargs -P ${JOBS:-15} -L 1 bash -c '"$@"' _ | grep -v "rc=0"
  summary L_ L.txt
  ;;
r)
  install_gsplat
  timeout 240 python3 -m pytest -q -x -p no:warnings tests/test_rasterizer.py tests/test_binning.py tests/test_launch.py \
    > "$OUT/tests_cuda.log" 2>&1; tail -3 "$OUT/tests_cuda.log"
  mkdir -p /tmp/old && tar -xf .device/old.tar -C /tmp/old
  AB="--warmup 10 --iters 20 --rounds 15 --configs 138766x648x420"
  for k in 1 2; do
    (cd /tmp/old && timeout 200 python3 bench/rasterizer.py $AB --out "$OUT/ab_old_$k.json" 2>&1 | grep -E "warpgs  |gsplat  |ratio|paired" | sed "s/^/old $k: /")
    timeout 200 python3 bench/rasterizer.py $AB --out "$OUT/ab_new_$k.json" 2>&1 | grep -E "warpgs  |gsplat  |ratio|paired" | sed "s/^/new $k: /"
  done
  ;;
t)  # (the second half of r, a call of its own)
  CONFIGS=$ISSUE15 rasterizer_runs --warmup 10 --iters 20 --rounds 7
  ;;
v)
  install_gsplat
  timeout 200 python3 -m pytest -q -p no:warnings tests/test_rasterizer.py tests/test_binning.py \
    tests/test_graph_fallback.py -k "cuda or fallback" > "$OUT/tests_cuda.log" 2>&1; tail -3 "$OUT/tests_cuda.log"
  [ -n "${TESTS_ONLY:-}" ] && exit 0
  gc plain
  timeout 240 python3 bench/train_speed.py --data-root "$D" --out "$OUT/train_speed_cuda.json" --set model.init=frustum \
    --set train.drop_rate=0.2 2>&1 | grep -v "^Module\|^Warp" | tee "$OUT/train_speed.log" | tail -12
  ;;
M)
  { for s in 0 1 2; do
      echo "lego M_g1_s$s baseline $s 10000 $LEGO_BEST --set strategy.grow_grad2d=0.0001"
      echo "lego M_g15_s$s baseline $s 10000 $LEGO_BEST --set strategy.grow_grad2d=0.00015"
      echo "lego M_drop3_s$s baseline $s 10000 $LEGO_BEST --set train.drop_rate=0.3"
      echo "lego M_noise6_s$s baseline $s 10000 $LEGO_BEST --set train.opacity_noise=0.6"
      echo "lego M_lrf_s$s baseline $s 10000 $LEGO_BEST --set optim.means_lr_final=1.6e-5"
    done; } | xargs -P ${JOBS:-15} -L 1 bash -c '"$@"' _ | grep -v "rc=0"
  summary M_ M.txt
  ;;
N)
  { for s in 0 1 2; do
      echo "lego N_lrf20k_s$s baseline $s 20000 $LEGO_BEST --set optim.means_lr_final=1.6e-5"
      echo "lego N_lrconst_s$s baseline $s 10000 $LEGO_BEST --set optim.means_lr_final=1.6e-4"
    done; } | xargs -P ${JOBS:-6} -L 1 bash -c '"$@"' _ | grep -v "rc=0"
  summary N_ N.txt
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
