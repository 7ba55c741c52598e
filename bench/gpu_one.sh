#!/usr/bin/env bash
# Sourced by the GPU session scripts (bench/gpu_session14.sh to gpu_session21.sh).
# sparse_run NAME [python -m warpgs.pipelines.sparse arguments ...]: one run on the GPU into $R/NAME (log: $R/NAME.log),
# on the scenes under $D; skipped when NAME has its metrics (not those of a stop on out of memory), resumed when it has started (a run stopped before its
# first checkpoint resumes from the start); stopped at the deadline $END (epoch seconds), or after ${T:-540} s
# without one. Prints NAME, the exit code and the run's last test PSNR line.
sparse_run() {
  local name=$1; shift
  # finished, unless it stopped on a GPU out of memory (runs sharing the GPU): that one is resumed
  [ -f "$R/$name/metrics.json" ] && ! grep -q '"out_of_memory"' "$R/$name/metrics.json" && return 0
  local resume=(); [ -f "$R/$name/config.yaml" ] && resume=(--resume)
  local t=${T:-540}; [ -n "${END:-}" ] && t=$((END - $(date +%s)))
  [ "$t" -lt 20 ] && { echo "$name: no time left in this call"; return 0; }
  timeout -s INT "$t" python3 -m warpgs.pipelines.sparse "$@" --device cuda --no-progress --data-root "$D" \
    --out "$R/$name" "${resume[@]}" >> "$R/$name.log" 2>&1
  echo "$name rc=$? $(grep -h 'test: PSNR' "$R/$name.log" | tail -1)"
}
export -f sparse_run

# one NAME METHOD SCENE VIEWS SEED [--set k=v ...]: sparse_run of the DL3DV-layout scene SCENE at --downscale ${DS:-8}
# for ${IT:-3000} iterations, 10 evaluations.
one() {
  local name=$1 method=$2 scene=$3 views=$4 seed=$5; shift 5
  sparse_run "$name" --method "$method" --data dl3dv --scene "$scene" --views "$views" --downscale "${DS:-8}" \
    --iterations "${IT:-3000}" --seed "$seed" --set train.eval_every=$(( ${IT:-3000} / 10 )) "$@"
}
export -f one

# cases PREFIX METHOD SEED SETTING: the run lines of METHOD with --set SETTING on DTU, fern (not with FERN=0) and the six
# captures at 384x256, named PREFIX_SCENE[_Nv]_METHOD_sSEED (bench/gpu_session42.sh on).
cases() {
  local pre=$1 m=$2 s=$3 set=$4
  echo "named ${pre}_dtu_${m}_s$s $m dtu scan65 3 $s --set $set"
  [ "${FERN:-1}" = 1 ] && echo "named ${pre}_fern_${m}_s$s $m llff fern 3 $s --set $set"
  for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
    echo "one ${pre}_${c}_${v}v_${m}_s$s $m $c $v $s --set $set"
  done; done
}

# one4 NAME METHOD SCENE VIEWS SEED [--set k=v ...]: one at images_4 (768x512) for 10,000 iterations (the setting of
# --data dl3dv; bench/gpu_session38.sh on).
one4() { DS=4 IT=10000 one "$@"; }
export -f one4

# cuda_tests FILE ...: the tests of FILE that run on CUDA (-k cuda: the machine's packed Warp has no CPU compiler, and
# the files' other tests run on the CPU; session 40's first call failed on them), once per machine: a passed run
# leaves $R/t_ok; the last lines in $OUT/t.log (bench/gpu_session40.sh on).
cuda_tests() {
  [ -f "$R/t_ok" ] && return 0
  timeout 200 python3 -m pytest -q -p no:cacheprovider "$@" -k cuda 2>&1 | tail -3 | tee "$OUT/t.log"
  grep -q " passed" "$OUT/t.log" && ! grep -q "failed\|error" "$OUT/t.log" && python3 -c "import torch; assert torch.cuda.is_available()" \
    && touch "$R/t_ok"
}

# named NAME METHOD DATASET SCENE VIEWS SEED [--set k=v ...]: sparse_run on a named dataset (dtu, llff, ...) for
# 3000 iterations, 10 evaluations.
named() {
  local name=$1 method=$2 data=$3 scene=$4 views=$5 seed=$6; shift 6
  sparse_run "$name" --method "$method" --data "$data" --scene "$scene" --views "$views" --iterations 3000 \
    --seed "$seed" --set train.eval_every=300 "$@"
}
export -f named

# run_lines JOBS: runs each line on stdin (a function of this file and its arguments: sparse_run, one, named, lego),
# ${JOBS:-JOBS} at a time, only the lines matching ${ONLY:-.} (a grep -E pattern); prints the runs that did not end
# with rc=0 (bench/gpu_session35.sh on).
# With NGPU > 1 (a machine of several GPUs) each run takes GPU (xargs slot mod NGPU) (bench/gpu_session38.sh on).
run_lines() {
  grep -E -- "${ONLY:-.}" | xargs -P "${JOBS:-$1}" -L 1 --process-slot-var=SLOT \
    bash -c '[ "${NGPU:-1}" -gt 1 ] && export CUDA_VISIBLE_DEVICES=$((SLOT % NGPU)); "$@"' _ | grep -v "rc=0"
}

# summary PREFIX FILE: one line per run $R/PREFIX*/metrics.json (name, test PSNR, Gaussians, per-view PSNRs, the
# curve's PSNRs), sorted, into $OUT/FILE and on stdout.
summary() {
  for m in "$R"/$1*/metrics.json; do
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print(sys.argv[1].split('/')[-2], round(d['psnr'],3), d['num_gaussians'], [round(v['psnr'],2) for v in d.get('per_view',[])], [round(c['psnr'],2) for c in d.get('curve',[])])" "$m"
  done | sort | tee "$OUT/$2"
}

# lego NAME METHOD SEED ITERATIONS [--set k=v ...]: sparse_run of Blender lego, 8 views, 10 evaluations (the lego
# phases of bench/gpu_session31.sh to gpu_session33.sh). LEGO_BEST: session 17's best baseline setting.
LEGO_BEST="--set train.drop_rate=0.2 --set train.opacity_noise=0.8 --set model.sh_degree=1"
lego() {
  local name=$1 method=$2 seed=$3 it=$4; shift 4
  sparse_run "$name" --method "$method" --data blender --scene lego --views 8 --iterations "$it" --seed "$seed" \
    --set train.eval_every=$((it / 10)) "$@"
}
export -f lego

# install_gsplat: gsplat 1.5.3 from .device/gsplat into /tmp/site (its CUDA kernels compile on first use).
install_gsplat() {
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
}

# rasterizer_configs [bench/rasterizer.py timing arguments ...]: gsplat installed, then bench/rasterizer.py on the
# random configurations $CONFIGS (default: 138k, 256k and 1M Gaussians, the first again at the end) into
# $OUT/rasterizer_cuda.json and rasterizer.log.
rasterizer_configs() {
  install_gsplat
  timeout ${T:-300} python3 bench/rasterizer.py "$@" --out "$OUT/rasterizer_cuda.json" \
    --configs "${CONFIGS:-138766x648x420,256000x1280x720,1000000x1920x1080,138766x648x420}" 2>&1 \
    | tee "$OUT/rasterizer.log" | grep -E "Gaussians|ratio|paired|wrote"
}

# rasterizer_runs [bench/rasterizer.py timing arguments ...] (bench/gpu_session18.sh, gpu_session19.sh phase r,
# gpu_session32.sh t): rasterizer_configs, then fern's baseline trained into $R/fern_base unless it is there (3 views,
# 3000 it, frustum start), and bench/rasterizer.py on its Gaussians at 1x, 2x and 3x the test view; JSON and logs in
# $OUT.
rasterizer_runs() {
  rasterizer_configs "$@"
  [ -f "$R/fern_base/point_cloud.ply" ] || python3 -m warpgs.pipelines.sparse --method baseline --data llff \
    --data-root "$D" --iterations 3000 --set model.init=frustum --device cuda --no-progress --out "$R/fern_base" \
    > "$OUT/fern_base.log" 2>&1
  tail -2 "$OUT/fern_base.log"
  timeout ${T:-300} python3 bench/rasterizer.py --ply "$R/fern_base/point_cloud.ply" --data llff --data-root "$D" \
    --scales 1,2,3 "$@" --out "$OUT/rasterizer_cuda_trained.json" 2>&1 \
    | tee "$OUT/rasterizer_trained.log" | grep -E "Gaussians|ratio|paired|wrote"
}

# session_env PHASE D RUNS (bench/gpu_session20.sh on): makes RUNS and $OUT, exports the environment of the GPU runs
# (the packed wheels in /tmp/site first, one thread per process for OpenMP/MKL, CUDA tests and builds for sm_90, the
# machine's GPU count NGPU).
session_env() {
  mkdir -p "$3" "$OUT"
  export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
  export MAX_JOBS=16 TORCH_CUDA_ARCH_LIST=9.0 WARPGS_TEST_DEVICES=cuda
  export NGPU=${NGPU:-$(nvidia-smi -L 2>/dev/null | grep -c GPU)}  # run_lines spreads the runs over them
}

# gc NAME [graph_check arguments ...] (bench/gpu_session19.sh g, gpu_session20.sh h): bench/graph_check.py on $D with
# ${ITERS:-1000} iterations into $OUT/graph_check_NAME.json and .log, then its verdict: whether the parameters and
# losses with the graphs equal those without, bit for bit, and the speed-up.
gc() {  # name, then graph_check's arguments
  local n=$1; shift
  timeout ${T:-200} python3 bench/graph_check.py --data-root "$D" --iterations ${ITERS:-1000} --out "$OUT/graph_check_$n.json" "$@" \
    2>&1 | grep -v "^Module\|^Warp" > "$OUT/graph_check_$n.log"
  echo "== $n"; grep -E "^(eager|graph|graph_again) |CUDA graphs off|Error|error" "$OUT/graph_check_$n.log" | cut -c1-400
  python3 -c "import json,sys; t=json.load(open(sys.argv[1]))['trainer']; print({k: (t[k].get('params_bit_equal'), t[k].get('losses_equal')) for k in ('graph','graph_again')}, 'speedup', t['speedup'])" "$OUT/graph_check_$n.json" 2>&1 | tail -1
}
