#!/usr/bin/env bash
# GPU runs of session 29 (issue 13: the full method's gain over the baseline on the captures), after the packed
# wheels are installed in /tmp/site and the scenes copied to $D.
#   T=seconds bash bench/gpu_session29.sh PHASE D RUNS
# v: session 28's full method with more of the run given to the pseudo views, castle_p30 and herz_jesus_p25 at 3, 6
#    and 9 views, seeds 0-2 (384x256, 3000 it): three pseudo-view cycles instead of two (full.cycles=3; prefix
#    v_c3) and 30% of the iterations on the inputs alone instead of 40% (full.baseline_fraction=0.3; prefix v_bf03).
#    Session 27 measured one cycle (-0.08 dB on average) and session 22 a fraction of 0.6 (-0.05): both less.
# w: the same 18 cases with VARIANT="name --set k=v ..." (prefix v_name), chosen from v.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/gpu_one.sh"
session_env "$@"; P=$1; D=$2; R=$3; shift 3
export R D T
cases() {  # cases NAME SETTINGS...: the 18 full runs of one variant
  local n=$1; shift
  for c in castle_p30 herz_jesus_p25; do for v in 3 6 9; do for s in 0 1 2; do
    echo "v_${n}_${c}_${v}v_full_s$s full $c $v $s $*"
  done; done; done
}
case $P in
v)
  { cases c3 --set full.cycles=3; cases bf03 --set full.baseline_fraction=0.3; } \
    | xargs -P ${JOBS:-36} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary v_ v369.txt
  ;;
w)
  # shellcheck disable=SC2086
  cases ${VARIANT:?set VARIANT} | xargs -P ${JOBS:-18} -L 1 bash -c 'one "$@"' _ | grep -v "rc=0"
  summary "v_${VARIANT%% *}_" "w_${VARIANT%% *}.txt"
  ;;
*) echo "unknown phase $P"; exit 2 ;;
esac
