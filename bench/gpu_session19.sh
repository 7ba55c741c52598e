#!/usr/bin/env bash
# GPU runs of session 19 (issue 15), after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session19.sh PHASE D RUNS
# g: the CUDA tests of the rasterizer and the optimiser, then bench/graph_check.py bit for bit with and without the
#    graphs: plain fern; fern with dropout and opacity noise (their draws inside the graph); castle_p30 9 views with
#    the far field and dropout (the captures' default); lego 8 views with dropout and a random background.
# r: bench/rasterizer.py with interleaved rounds: the three random configurations (the first again at the end), then
#    fern's baseline trained (3 views, 3000 it, frustum start) and its Gaussians at 1x, 2x and 3x the test view.
# u: bench/suite.py's full preset (the speed-against-accuracy charts) with this code.
# f: the full method on fern and DTU 65 (3 views, 3000 it), seed ${SEEDS:-0}: the default against one change at a time
#    to what the captures' config does (no learning-rate restart, a growth budget, dropout); VARIANTS picks some.
# e: the shipped defaults end to end with and without the graphs (train.cuda_graph): castle_p30 9 views (images_8,
#    3000 it; SfM start, far field, path clearance, dropout) baseline and full, fern 3 views baseline: same metrics?
# p: train.path_floaters (RATIO, default 10) against the default on the captures at 384x256, 3000 it, seeds 0-2,
#    baseline and full (CASES, default castle_p30:9 castle_p30:6 herz_jesus_p25:9): 36 runs of bench/gpu_one.sh's one
#    (10 evaluations each, resumed when a call ran out of time), JOBS at a time.
# s: bench/train_speed.py with DropGaussian on (the LLFF default): the trainer with and without graphs, gsplat.
set -u
P=$1; D=$2; R=$3; shift 3; mkdir -p "$R" "$OUT"
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0 WARPGS_TEST_DEVICES=cuda
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
case $P in
g)
  timeout ${T:-200} python3 -m pytest -q -x tests/test_rasterizer.py tests/test_sync.py -k "cuda or adam or masked or capacity" \
    2>&1 | tail -3 | tee "$OUT/tests_cuda.log"
  gc plain
  gc drop_noise --set train.drop_rate=0.2 --set train.opacity_noise=0.8
  gc castle_ff --data dl3dv --scene castle_p30 --views 9 --set train.far_field=elevation --set train.drop_rate=0.2
  gc lego_rb --data blender --scene lego --views 8 --set train.drop_rate=0.2
  ;;
r)
  rasterizer_runs --warmup 10 --iters 20 --rounds 7
  ;;
u)
  timeout ${T:-560} python3 bench/suite.py --device cuda --data-root "$D" --preset full --jobs ${JOBS:-6} \
    --out "$OUT/suite_cuda" --work "$R/suite" > "$OUT/suite.log" 2>&1; echo "suite rc=$?"
  tail -30 "$OUT/suite.log" | cut -c1-300
  ;;
s)
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
  timeout ${T:-560} python3 bench/train_speed.py --data-root "$D" --set model.init=frustum --set train.drop_rate=0.2 \
    --repeats ${REPEATS:-1} --loops warpgs_trainer,warpgs_trainer_eager,plain_gsplat \
    --out "$OUT/train_speed_drop_cuda.json" > "$OUT/train_speed_drop.log" 2>&1; echo "train_speed rc=$?"
  tail -10 "$OUT/train_speed_drop.log"
  ;;
e)
  for g in true false; do
    python3 -m warpgs.pipelines.sparse --method baseline --data dl3dv --scene castle_p30 --data-root "$D" --views 9 \
      --downscale 8 --iterations 3000 --device cuda --no-progress --set train.cuda_graph=$g --out "$R/e_c9_base_$g" \
      > "$OUT/e_c9_base_$g.log" 2>&1 &
    python3 -m warpgs.pipelines.sparse --method full --data dl3dv --scene castle_p30 --data-root "$D" --views 9 \
      --downscale 8 --iterations 3000 --device cuda --no-progress --set train.cuda_graph=$g --out "$R/e_c9_full_$g" \
      > "$OUT/e_c9_full_$g.log" 2>&1 &
    python3 -m warpgs.pipelines.sparse --method baseline --data llff --data-root "$D" --views 3 --iterations 3000 \
      --device cuda --no-progress --set train.cuda_graph=$g --out "$R/e_fern_base_$g" > "$OUT/e_fern_base_$g.log" 2>&1 &
  done; wait
  for m in "$R"/e_*/metrics.json; do
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print(sys.argv[1].split('/')[-2], repr(d['psnr']), d['num_gaussians'], round(d['train_time_s'],1))" "$m"
  done | tee "$OUT/defaults_graph_vs_eager.txt"
  ;;
p)
  export R D T
  for c in ${CASES:-castle_p30:9 castle_p30:6 herz_jesus_p25:9}; do for m in baseline full; do for s in 0 1 2; do
    for r in 0 ${RATIO:-10}; do
      echo "p_${c%%:*}_${c##*:}v_${m}_s${s}_r$r $m ${c%%:*} ${c##*:} $s --set train.path_floaters=$r"
    done; done; done; done | xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _
  for m in "$R"/p_*/metrics.json; do
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print(sys.argv[1].split('/')[-2], round(d['psnr'],3), d['num_gaussians'], [round(v['psnr'],2) for v in d.get('per_view',[])], [round(c['psnr'],2) for c in d.get('curve',[])])" "$m"
  done | sort | tee "$OUT/path_floaters.txt"
  # bench/floaters.py on every finished run (FLOATERS=0: not), its summaries in $OUT/floaters/
  if [ "${FLOATERS:-1}" = 1 ]; then
    mkdir -p "$OUT/floaters"
    for m in "$R"/p_*/metrics.json; do n=$(basename "$(dirname "$m")"); [ -f "$OUT/floaters/$n.txt" ] || echo "$n"; done \
      | xargs -P ${JOBS:-12} -I{} bash -c 'timeout 300 python3 bench/floaters.py "$R/{}" --device cuda --data-root "$D" \
          --out "$OUT/floaters/{}.json" 2>&1 | grep -v "^Module\|^Warp" > "$OUT/floaters/{}.txt"'
  fi
  ;;
f)
  declare -A V=([default]="" [norestart]="full.restart_lr=false" [budget]="full.restart_lr=false full.growth_budget=1.0"
                [drop]="full.restart_lr=false full.drop_rate=0.2"
                [captures]="full.restart_lr=false full.growth_budget=1.0 full.drop_rate=0.2")
  for seed in ${SEEDS:-0}; do for scene in llff dtu; do for v in ${VARIANTS:-default norestart budget drop captures}; do
    sets=(); for kv in ${V[$v]}; do sets+=(--set "$kv"); done
    o="$R/f_${scene}_${v}_s$seed"
    [ -f "$o/metrics.json" ] || timeout ${T:-560} python3 -m warpgs.pipelines.sparse --method full --data $scene \
      --data-root "$D" --views 3 --iterations 3000 --seed $seed --device cuda --no-progress --out "$o" "${sets[@]}" \
      > "$OUT/f_${scene}_${v}_s$seed.log" 2>&1 &
  done; done; done; wait
  for m in "$R"/f_*/metrics.json; do
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print(sys.argv[1].split('/')[-2], round(d['psnr'],3), d['num_gaussians'], round(d['train_time_s'],1), [round(c['psnr'],2) for c in d.get('curve',[])])" "$m"
  done | tee "$OUT/full_variants.txt"
  ;;
esac
ls -la "$OUT"
