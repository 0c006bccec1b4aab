#!/usr/bin/env bash
# Set up orbitdata on a fresh Debian/Ubuntu machine: headless OpenGL, a venv, CPU PyTorch, the project.
#   bash scripts/setup.sh            # runtime + test dependencies into ./.venv
# Environment: PYTHON (default python3, 3.11 or later), VENV (default .venv),
#   TORCH_INDEX_URL (the index to take the CPU wheel from; by default the configured index, then
#   https://download.pytorch.org/whl/cpu when that one lacks it).
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
VENV=${VENV:-.venv}

# Headless OpenGL for MuJoCo: EGL on Mesa (default) and OSMesa (fallback); a C++ compiler and
# Python's headers for torch.compile's CPU backend (the planner's `compile` setting).
need=() packages=()
libraries=$(ldconfig -p)  # read whole: `ldconfig -p | grep -q` can die of SIGPIPE under pipefail
for lib in libEGL.so.1 libEGL_mesa.so.0 libOSMesa.so; do
  grep -q "$lib" <<<"$libraries" || need+=("$lib")
done
[ ${#need[@]} -eq 0 ] || packages+=(libegl1 libegl-mesa0 libgl1-mesa-dri libgl1 libosmesa6)
command -v c++ >/dev/null || command -v g++ >/dev/null || { need+=(c++) && packages+=(g++); }
"$PYTHON" -c 'import os, sys, sysconfig; sys.exit(not os.path.isfile(os.path.join(sysconfig.get_paths()["include"], "Python.h")))' 2>/dev/null ||
  { need+=(Python.h) && packages+=(python3-dev); }
if [ ${#packages[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${packages[@]}" >/dev/null
  else
    echo "missing ${need[*]}: install ${packages[*]}" >&2
  fi
fi

usable() {  # a venv that a killed or failed setup did not leave half-made, on a Python this project takes
  "$VENV/bin/python" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null &&
    "$VENV/bin/python" -m pip --version >/dev/null 2>&1
}
if [ -e "$VENV" ] && ! usable; then
  echo "remaking $VENV: it has no pip or a Python older than 3.11" >&2
  "$PYTHON" -m venv --clear "$VENV"
elif [ ! -e "$VENV" ]; then
  "$PYTHON" -m venv "$VENV"
fi
if ! usable; then
  echo "$PYTHON cannot make a venv with pip on Python 3.11 or later: install python3-venv (Debian/Ubuntu)" \
    "or name another interpreter with PYTHON=" >&2
  exit 1
fi
PIP=("$VENV/bin/python" -m pip --quiet --disable-pip-version-check)
# CPU PyTorch first, by its local version (+cpu): no index can hand over the multi-GB CUDA build, and
# nothing installed after it pulls another torch.
TORCH=torch==2.13.0+cpu
[ "$(uname -s)" = Linux ] || TORCH=torch==2.13.0  # elsewhere the wheels carry no +cpu and no CUDA
if [ -n "${TORCH_INDEX_URL:-}" ]; then
  "${PIP[@]}" install "$TORCH" --index-url "$TORCH_INDEX_URL"
elif ! "${PIP[@]}" install "$TORCH" 2>/dev/null; then
  echo "the configured index has no $TORCH: taking it from https://download.pytorch.org/whl/cpu" >&2
  "${PIP[@]}" install "$TORCH" --index-url https://download.pytorch.org/whl/cpu
fi
"${PIP[@]}" install -e ".[test]"
"$VENV/bin/python" -c "import torch; assert not torch.version.cuda, 'CUDA torch installed; use the CPU wheel'"
echo "orbitdata is set up in $VENV"
