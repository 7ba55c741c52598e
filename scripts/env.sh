#!/usr/bin/env bash
# Creates (or refreshes) the project's isolated environment in .venv and installs warpgs into it.
# Sourced by scripts/run.sh and scripts/test.sh; safe to run again (it only reinstalls when
# pyproject.toml or this file changed). Overrides:
#   WARPGS_VENV=path        where the environment lives (default: <repo>/.venv)
#   PYTHON=python3.12       interpreter used to create it
#   WARPGS_TORCH="torch==X" torch requirement (default: CUDA build if an NVIDIA GPU is visible, else CPU build)
set -euo pipefail
WARPGS_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WARPGS_VENV=${WARPGS_VENV:-$WARPGS_ROOT/.venv}
_py=${PYTHON:-python3}

_say() { printf 'warpgs setup: %s\n' "$*" >&2; }

# open3d's wheel links against libusb-1.0 (a system library, not a Python package).
if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    _say "installing libusb-1.0-0 (needed by open3d)"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null 2>&1 || {
      apt-get update -qq >/dev/null 2>&1 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null; }
  else
    _say "open3d needs the system library libusb-1.0, which is missing. Install it with:"
    _say "    sudo apt-get install -y libusb-1.0-0"
    _say "then run this command again."
    exit 1
  fi
fi

if ! command -v "$_py" >/dev/null 2>&1; then
  _say "no '$_py' interpreter found; install Python >= 3.10 or set PYTHON=/path/to/python3"; exit 1
fi

_stamp="$WARPGS_VENV/.warpgs-setup"
_want=$(cat "$WARPGS_ROOT/pyproject.toml" "$WARPGS_ROOT/scripts/env.sh" | cksum | cut -d' ' -f1)
if [ ! -x "$WARPGS_VENV/bin/python" ] || [ "$(cat "$_stamp" 2>/dev/null)" != "$_want" ]; then
  _say "creating the environment in $WARPGS_VENV (first run takes a few minutes)"
  [ -x "$WARPGS_VENV/bin/python" ] || "$_py" -m venv "$WARPGS_VENV"
  _pip=("$WARPGS_VENV/bin/python" -m pip install -q --disable-pip-version-check)
  # _install NAME PIP-ARGS...: pip's messages less its harmless warnings; a failed install stops the set-up naming
  # NAME (the tests need every one: a package that is not there must not turn into skipped tests)
  _install() {
    local name=$1 log rc=0
    shift
    log=$(mktemp)
    "${_pip[@]}" "$@" >"$log" 2>&1 || rc=$?
    # (grep's own status is 1 when every line was filtered out: not a failure of the install)
    grep -v -e '^WARNING: Location' -e '^WARNING: Retrying' -e 'dependency resolver' -e 'requires torchvision' \
      "$log" >&2 || [ $? -eq 1 ]
    rm -f "$log"
    if [ "$rc" -ne 0 ]; then
      _say "installing $name failed (pip's messages above); the tests need it, so the set-up stops here"
      exit 1
    fi
  }
  if ! "$WARPGS_VENV/bin/python" -c 'import torch' >/dev/null 2>&1; then
    if [ -n "${WARPGS_TORCH:-}" ]; then
      "${_pip[@]}" "$WARPGS_TORCH"
    elif command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1; then
      _say "NVIDIA GPU found: installing the CUDA build of torch"
      "${_pip[@]}" torch
    else
      # No GPU: the CPU build (a local wheel where one is provided, else PyTorch's CPU index);
      # an unpinned 'torch' from PyPI would pull several GB of CUDA libraries for nothing.
      _say "no NVIDIA GPU: installing the CPU build of torch"
      "${_pip[@]}" "torch==2.13.0" --extra-index-url https://download.pytorch.org/whl/cpu 2>&1 \
        | grep -v -e '^WARNING: Location' -e '^WARNING: Retrying' >&2 || true  # tried again below, where a failure stops
      "$WARPGS_VENV/bin/python" -c 'import torch' 2>/dev/null || "${_pip[@]}" torch --index-url https://download.pytorch.org/whl/cpu
    fi
  fi
  _install "warpgs with its test dependencies (pycolmap, open3d, diffusers, transformers, ray, viser, playwright, gsplat)" \
    -e "$WARPGS_ROOT[test]"
  # The viewer's browser test (tests/test_view.py) drives a real Chromium through playwright's pip package
  # (no `playwright install`): Debian's chromium-headless-shell. An install that fails stops the set-up; where it
  # cannot be tried (not root), the set-up says so and CI's run fails on that test's skip (.ci/run).
  if [ -z "${WARPGS_CHROMIUM:-}" ] && ! command -v chromium-headless-shell >/dev/null 2>&1 \
      && ! command -v chromium >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
      _say "installing chromium-headless-shell (the viewer's browser test)"
      DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium-headless-shell >/dev/null 2>&1 || {
          apt-get update -qq >/dev/null 2>&1 \
          && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium-headless-shell >/dev/null 2>&1; } \
        || { _say "installing chromium-headless-shell failed (apt-get); the viewer's browser test needs it"; exit 1; }
    else
      _say "warning: no headless Chromium for the viewer's browser test, which then skips (and CI fails); install:"
      _say "    sudo apt-get install -y chromium-headless-shell   (or set WARPGS_CHROMIUM=/path/to/chromium)"
    fi
  fi
  # LPIPS: the lpips package declares torchvision, whose PyPI build would replace the CPU torch; warpgs
  # needs only lpips's code (it supplies AlexNet's layout itself), so install it without dependencies.
  _install lpips --no-deps "lpips>=0.1.4"
  _install scipy "scipy>=1.8"
  # every module the tests import, by name: the first missing one is named
  "$WARPGS_VENV/bin/python" - <<'PY' || { _say "installation incomplete (see the line above)"; exit 1; }
import importlib, sys
for name in ("warpgs", "warp", "torch", "open3d", "kornia", "trimesh", "pycolmap", "plyfile", "cv2", "lpips", "scipy",
             "diffusers", "transformers", "ray", "viser", "playwright.sync_api", "gsplat"):
    try:
        if name == "lpips":  # as warpgs imports it: without torchvision, with its own AlexNet layout
            from warpgs.losses import _import_lpips
            _import_lpips()
        else:
            importlib.import_module(name)
    except Exception as e:
        sys.exit(f"warpgs setup: {name} does not import ({type(e).__name__}: {e})")
PY
  echo "$_want" > "$_stamp"
fi
export WARPGS_ROOT WARPGS_VENV
