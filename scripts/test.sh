#!/usr/bin/env bash
# Sets up the environment if needed, then runs the test suite on the CPU.
# Any arguments are passed on to pytest (e.g. `scripts/test.sh tests/test_rasterizer.py -k grad`).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
cd "$WARPGS_ROOT"
exec "$WARPGS_VENV/bin/python" -m pytest -q "$@"
