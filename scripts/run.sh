#!/usr/bin/env bash
# Sets up the environment if needed, then runs the main job (on the embedded synthetic scene unless
# arguments say otherwise). Any arguments are passed on to `python -m warpgs.pipelines.sparse`.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
cd "$WARPGS_ROOT"
exec "$WARPGS_VENV/bin/python" -m warpgs.pipelines.sparse "$@"
