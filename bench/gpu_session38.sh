#!/usr/bin/env bash
# GPU runs prepared in session 37 for the next session (wheels in /tmp/site, pycolmap among them; scenes in $D:
# llff_fern, dtu_scan65, blender_lego and the captures, images_4 included).
#   T=seconds bash bench/gpu_session38.sh PHASE D RUNS          (ONLY=REGEX keeps the runs whose line matches)
# Session 37 made full.pseudo_weight 0.2 the captures' and DTU's default (384x256, seeds 0-2: full - baseline +0.13 ->
# +0.38 dB on average over the six capture cases; DTU -0.58 -> +0.25). The images_4 rows of the README have seed 0 of
# session 36's default only (s36/g.txt), with the full method at weight 1.
# i: the captures at images_4 (768x512, 10,000 it) with today's defaults: the full method at seeds 0-2 (18 runs), the
#    baseline at seeds 1-2 (12 runs; seed 0 is s36/g.txt, the baseline did not change). About three calls. i.txt.
# l: lego 8 views (10,000 it), the full method with full.pseudo_weight=0.2 at seeds 0-2 (3 runs; blender.yaml keeps
#    1.0: 24.48 against the baseline's 24.80, s36/e.txt, f.txt), and fern's full method with its growth stopped at
#    half the run (full.refine_stop_fraction=0.5: 22.98 at seed 0 in s37/t.txt) at seeds 1-2 (2 runs). l.txt.
# v: the full method's settings over today's default (pseudo weight 0.2), seed 0, the six capture cases at 384x256 and
#    DTU (28 runs, one call): c3 (full.cycles=3), rel (full.pseudo_mask=reliable), n17 (pseudo.trajectory.n_frames=17:
#    more poses per pair of inputs), bf6 (full.baseline_fraction=0.6: the first pseudo views after the binocular term
#    starts; at weight 1 it gave +0.21 on average, s37/t.txt). Against s37/t.txt's t_p_ runs. v.txt.
# d: DTU scan65 3 views at 10,000 iterations (configs/dtu.yaml's own train.iterations; the README's DTU rows are
#    3000), both methods, seeds 0-2 (6 runs). d.txt.
# q: one queue over every GPU of the machine (NGPU, from nvidia-smi): i, then d, then l, then v's c3 and bf6 at seeds
#    0-2 (VARIANTS, SEEDS), ${JOBS:-36} runs at a time, pairs of images_4 runs between pairs of the others; a second call resumes what the first left. Summaries i.txt,
#    d.txt, l.txt, v.txt.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T END=$(( $(date +%s) + ${T:-540} ))  # every run of the call stops by then
declare -A V=([c3]="--set full.cycles=3" [rel]="--set full.pseudo_mask=reliable"
              [n17]="--set pseudo.trajectory.n_frames=17" [bf6]="--set full.baseline_fraction=0.6")
lines_i() {
  for s in 0 1 2; do for m in full baseline; do for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
    [ "$m" = baseline ] && [ "$s" = 0 ] && continue
    echo "one4 i_${c}_${v}v_${m}_s$s $m $c $v $s"
  done; done; done; done
}
lines_d() {
  for s in 0 1 2; do for m in baseline full; do
    echo "sparse_run d_dtu10k_${m}_s$s --method $m --data dtu --scene scan65 --views 3 --iterations 10000 --seed $s --set train.eval_every=1000"
  done; done
}
lines_l() {
  for s in 0 1 2; do echo "lego l_lego_full_pw02_s$s full $s 10000 --set full.pseudo_weight=0.2"; done
  for s in 1 2; do echo "named l_fern_full_rs05_s$s full llff fern 3 $s --set full.refine_stop_fraction=0.5"; done
}
lines_v() {
  for s in ${SEEDS:-0}; do for v in ${VARIANTS:-c3 rel n17 bf6}; do
    echo "named v_${v}_dtu_full_s$s full dtu scan65 3 $s ${V[$v]}"
    for c in castle_p30 herz_jesus_p25; do for n in 3 6 9; do
      echo "one v_${v}_${c}_${n}v_full_s$s full $c $n $s ${V[$v]}"
    done; done
  done; done
}
case $P in
q)
  # pairs of images_4 runs alternate with pairs of the others, so that each GPU holds about as many of each
  lines_i > "$R/q_a.txt"
  { lines_d; lines_l; VARIANTS=${VARIANTS:-"c3 bf6"} SEEDS=${SEEDS:-"0 1 2"} lines_v; } > "$R/q_b.txt"
  python3 -c "import sys; a, b = (open(f).read().split(chr(10))[:-1] for f in sys.argv[1:]); out = []
while a or b: out += a[:2] + b[:2]; a, b = a[2:], b[2:]
print(chr(10).join(out))" "$R/q_a.txt" "$R/q_b.txt" | run_lines 36
  summary i_ i.txt; summary d_ d.txt; summary l_ l.txt; summary v_ v.txt
  ;;
d)
  lines_d | run_lines 6
  summary d_ d.txt
  ;;
i)
  lines_i | run_lines 12
  summary i_ i.txt
  ;;
l)
  lines_l | run_lines 5
  summary l_ l.txt
  ;;
v)
  lines_v | run_lines 28
  summary v_ v.txt
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
