#!/usr/bin/env bash
# GPU runs of session 25 (issue 13: castle_p30 at 3 views; semi-global matching in the plane-sweep stereo), after the
# packed wheels are installed in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session25.sh PHASE D RUNS
# g: the captures at 3 views (castle_p30, herz_jesus_p25; 384x256, 3000 it, seeds 0-2), baseline and full, with the
#    initial stereo aggregated by semi-global matching (geometry.stereo.sgm_paths 4; prefix g). The 3-view runs start
#    from that stereo (held), so this is where it acts; the 6- and 9-view runs start from SfM and do not use it.
# k: the same runs without it, train.path_clearance 1.0 instead of 0.2 (prefix k).
# o: DTU scan65 and LLFF fern at 3 views (3000 it, seeds 0-2, baseline and full) with it (their points come from
#    sfm+stereo; prefix o).
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T
SGM="--set geometry.stereo.sgm_paths=${SGM_PATHS:-4}"
case $P in
g)
  for c in castle_p30 herz_jesus_p25; do for m in baseline full; do for s in 0 1 2; do
    echo "g_${c}_3v_${m}_s$s $m $c 3 $s $SGM"
  done; done; done | xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary g_ sgm3.txt
  ;;
o)
  for c in ${SCENES:-dtu llff}; do sc=scan65; [ $c = llff ] && sc=fern
    for m in baseline full; do for s in 0 1 2; do
      echo "o_${c}_${m}_s$s $m $c $sc 3 $s $SGM"
    done; done
  done | xargs -P ${JOBS:-12} -L 1 bash -c 'named "$@"' _ | grep -v "rc=0"
  summary o_ sgm_other.txt
  ;;
k)  # the 3-view captures without SGM, train.path_clearance x5 (the bounds' near depth moved 3.05 -> 15.1 with SGM)
  for c in castle_p30 herz_jesus_p25; do for m in baseline full; do for s in 0 1 2; do
    echo "k_${c}_3v_${m}_s$s $m $c 3 $s --set train.path_clearance=1.0"
  done; done; done | xargs -P ${JOBS:-12} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary k_ clearance3.txt
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
