#!/usr/bin/env bash
# GPU runs of session 20 (issues 15 and 13), after the packed wheels are installed in /tmp/site and the scenes copied
# to $D.   T=seconds bash bench/gpu_session20.sh PHASE D RUNS
# h: the rasterizer's host path (raw stream handles, direct native launches): the CUDA tests of the rasterizer, the
#    launcher and the optimiser; bench/graph_check.py bit for bit with and without the graphs (plain fern; castle_p30
#    9 views with the far field and dropout); bench/rasterizer_host.py at 138k; bench/rasterizer.py's runs
#    (bench/gpu_one.sh rasterizer_runs: three random configurations, fern's trained Gaussians at 1x-3x).
# c: the captures' default (now with train.path_floaters 10) on the six castle_p30 / herz_jesus_p25 cases at 384x256,
#    3000 it, seeds 0-2, baseline and full (36 runs of bench/gpu_one.sh's one, JOBS at a time; their PSNRs should
#    equal bench/results/s20/path_floaters.txt's _r10 rows to the last digit: the host path changes no arithmetic),
#    then bench/floaters.py --unseen-sweep on each (each test view without the Gaussians the inputs use less than
#    0.05 / 1 / 5 pixels: what train.prune_unseen_at_end would do); FLOATERS=0 leaves that out. PREFIX (default c)
#    names the runs: d for the runs after train.prune_unseen_at_end joined the captures' default.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
case $P in
h)
  timeout ${T:-200} python3 -m pytest -q -x tests/test_rasterizer.py tests/test_launch.py tests/test_sync.py \
    -k "cuda or adam or masked or capacity or launch or stream" 2>&1 | tail -3 | tee "$OUT/tests_cuda.log"
  gc plain
  gc castle_ff --data dl3dv --scene castle_p30 --views 9 --set train.far_field=elevation --set train.drop_rate=0.2
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .device/gsplat/*.whl 2>/dev/null
  timeout ${T:-200} python3 bench/rasterizer_host.py 2>&1 | grep -v "^Module\|^Warp" > "$OUT/host_profile_138k.txt"; head -3 "$OUT/host_profile_138k.txt"
  rasterizer_runs --warmup 10 --iters 20 --rounds 7
  ;;
c)
  export R D T
  for c in castle_p30:3 castle_p30:6 castle_p30:9 herz_jesus_p25:3 herz_jesus_p25:6 herz_jesus_p25:9; do
    for m in baseline full; do for s in 0 1 2; do echo "${PREFIX:-c}_${c%%:*}_${c##*:}v_${m}_s$s $m ${c%%:*} ${c##*:} $s"; done; done
  done | xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _
  summary "${PREFIX:-c}_" "captures_${PREFIX:-c}.txt"
  if [ "${FLOATERS:-1}" = 1 ]; then
    mkdir -p "$OUT/floaters"
    for m in "$R"/${PREFIX:-c}_*/metrics.json; do n=$(basename "$(dirname "$m")"); [ -f "$OUT/floaters/$n.json" ] || echo "$n"; done \
      | xargs -P ${JOBS:-12} -I{} bash -c 'timeout ${T:-300} python3 bench/floaters.py "$R/{}" --device cuda --data-root "$D" \
          --unseen-sweep 0.05,1,5 --out "$OUT/floaters/{}.json" 2>&1 | grep -v "^Module\|^Warp" | grep -v Warning > "$OUT/floaters/{}.txt"'
    ls "$OUT/floaters"/*.json | wc -l
  fi
  ;;
esac
ls -la "$OUT"
