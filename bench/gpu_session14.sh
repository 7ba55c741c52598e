#!/usr/bin/env bash
# GPU runs of session 14, after the packed wheels are installed in /tmp/site and the scenes copied to $D.
#   bash bench/gpu_session14.sh PHASE D RUNS
# a: issue 13 diagnosis of the captures' sudden test-PSNR drops (bench/floaters.py on the finished runs:
#    castle 9 views full seed 1, which fell from 21.2 to 18.8 at step 2100 in session 13; castle 9 views with
#    the far field, seed 0; castle 6 views baseline seed 2, 16.2 -> 13.8; castle 9 baseline seed 1 as a
#    reference), and train.alpha_binary with the far field on castle 9 (seeds 0-2), castle 3, herz 3 and 9.
# b: the same failures again with their models (point_cloud.ply, for bench/floaters.py and the path-clearance
#    analysis), and train.path_clearance 0.1 / 0.2 on each of them (and on herz 6 views baseline seed 1, which
#    fell at step 1200 in session 13).
# c: train.path_clearance 0.2 on the six capture cases (castle_p30 / herz_jesus_p25 at 3, 6, 9 views), seeds
#    0-2: the baseline and the full method, each without and with the far field (72 runs, 24 at a time; a run
#    stopped by the call's time limit resumes from its checkpoint in the next call).
# d: issue 13's acceptance setting with the new capture defaults (configs/nerfstudio.yaml: far field and path
#    clearance for both methods): castle_p30 / herz_jesus_p25 at 3, 6, 9 views, images_4 (768x512), 10,000
#    iterations, seed 0, baseline and full (12 runs at once, resumed across calls).
# e: train.view_clearance 0.5 (also nothing nearer than half the near depth in front of any pose of the path)
#    on the failures of d (castle 9 and 6 views at images_4, 10k, seed 0: black Gaussians 0.2-0.5 near depths
#    from the path, just outside the path clearance, in front of frame 8) and of c (castle 9 / 6 baseline seed 0).
# Each run: python -m warpgs.pipelines.sparse on images_8, 3000 iterations, as bench/suite.py's switch cases.
set -u
P=$1; D=$2; R=$3; mkdir -p "$R" "$OUT"
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
FF=(--set full.far_field=elevation)
AB=(--set full.far_field=elevation --set train.alpha_binary=0.1)
case $P in
a)
  one d_c9_full_s1 full castle_p30 9 1 &
  one d_c9_fullff_s0 full castle_p30 9 0 "${FF[@]}" &
  one d_c6_base_s2 baseline castle_p30 6 2 &
  one d_c9_base_s1 baseline castle_p30 9 1 &
  for s in 0 1 2; do one ab_c9_s$s full castle_p30 9 $s "${AB[@]}" & done
  one ab_c3_s0 full castle_p30 3 0 "${AB[@]}" &
  one ab_h3_s0 full herz_jesus_p25 3 0 "${AB[@]}" &
  one ab_h9_s0 full herz_jesus_p25 9 0 "${AB[@]}" &
  wait
  ;;
b)
  one d_c9_full_s1 full castle_p30 9 1 &
  one d_c9_fullff_s0 full castle_p30 9 0 "${FF[@]}" &
  one d_c6_base_s2 baseline castle_p30 6 2 &
  one d_h6_base_s1 baseline herz_jesus_p25 6 1 &
  for f in 0.1 0.2; do
    PC=(--set train.path_clearance=$f)
    one pc${f}_c9_full_s1 full castle_p30 9 1 "${PC[@]}" &
    one pc${f}_c9_fullff_s0 full castle_p30 9 0 "${FF[@]}" "${PC[@]}" &
    one pc${f}_c6_base_s2 baseline castle_p30 6 2 "${PC[@]}" &
    one pc${f}_h6_base_s1 baseline herz_jesus_p25 6 1 "${PC[@]}" &
  done
  wait
  ;;
c)
  export R D T END=$(( $(date +%s) + ${T:-540} ))
  for s in 0 1 2; do for sc in castle_p30 herz_jesus_p25; do for v in 3 6 9; do
    c=${sc%%_*}$v
    echo "pcff_${c}_full_s$s full $sc $v $s --set train.path_clearance=0.2 --set full.far_field=elevation"
    echo "pc_${c}_base_s$s baseline $sc $v $s --set train.path_clearance=0.2"
    echo "pc_${c}_full_s$s full $sc $v $s --set train.path_clearance=0.2"
    echo "pcff_${c}_base_s$s baseline $sc $v $s --set train.path_clearance=0.2 --set train.far_field=elevation"
  done; done; done | xargs -P 24 -L 1 bash -c 'one "$@"' _
  ;;
d)
  export R D T DS=4 IT=10000 END=$(( $(date +%s) + ${T:-540} ))
  for sc in castle_p30 herz_jesus_p25; do for v in 3 6 9; do for m in baseline full; do
    echo "i4_${sc%%_*}${v}_${m}_s0 $m $sc $v 0"
  done; done; done | xargs -P 12 -L 1 bash -c 'one "$@"' _
  ;;
e)
  export R D T END=$(( $(date +%s) + ${T:-540} ))
  VC="--set train.view_clearance=0.5"
  { for m in baseline full; do for v in 9 6; do echo "vc_i4_castle${v}_${m}_s0 $m castle_p30 $v 0 $VC"; done; done
    for v in 9 6; do echo "vc_castle${v}_base_s0 baseline castle_p30 $v 0 $VC"; done; } |
  while read -r n rest; do
    case $n in vc_i4*) DS=4 IT=10000 one $n $rest & ;; *) one $n $rest & ;; esac
  done; wait
  ;;
esac
for d in "$R"/*/; do
  n=$(basename "$d")
  [ -f "$d/metrics.json" ] || continue
  [ "$P" = a ] || [ "$P" = b ] || [ "$P" = e ] || continue
  [ -f "$d/floaters.json" ] || timeout 90 python3 bench/floaters.py "$d" --device cuda --data-root "$D" > "$d/floaters.txt" 2>&1 &
done
wait
X=(); [ "$P" != a ] && [ "$P" != b ] && X=(--exclude=test --exclude='cycle_*' --exclude=charts --exclude='*.md')
tar cf "$OUT/runs_$P.tar" -C "$R" "${X[@]}" --exclude='checkpoint*.pt' --exclude='*.gif' --exclude='point_cloud.ply' \
  --exclude='pseudo' --exclude='*.ply' .
for f in $(ls "$R"/d_*/point_cloud.ply 2>/dev/null); do n=$(basename "$(dirname "$f")"); cp "$f" "$OUT/$n.ply"; done
ls -la "$OUT"
