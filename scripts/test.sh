#!/usr/bin/env bash
# Sets up the environment if needed, then runs the test suite on the CPU.
# Any arguments are passed on to pytest (e.g. `scripts/test.sh tests/test_rasterizer.py -k grad`).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
cd "$WARPGS_ROOT"
# Worker processes (pytest-xdist): WARPGS_TEST_WORKERS, default the CPUs up to 4 (Warp's CPU kernels run on one
# thread each, so the suite scales with them); 1 runs it in this process.
workers=${WARPGS_TEST_WORKERS:-$(n=$(nproc 2>/dev/null || echo 1); echo $(( n < 4 ? n : 4 )))}
if [ "$workers" -gt 1 ]; then set -- -n "$workers" "$@"; fi
exec "$WARPGS_VENV/bin/python" -m pytest -q "$@"
