#!/usr/bin/env bash
# Set up orbitdata on a fresh Debian/Ubuntu machine: headless OpenGL, a venv, CPU PyTorch, the project.
#   bash scripts/setup.sh            # runtime + test dependencies into ./.venv
# Environment: PYTHON (default python3), VENV (default .venv),
#   TORCH_INDEX_URL (e.g. https://download.pytorch.org/whl/cpu where the CPU wheel is not the default).
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
VENV=${VENV:-.venv}

# Headless OpenGL for MuJoCo: EGL on Mesa (default) and OSMesa (fallback).
need=()
for lib in libEGL.so.1 libEGL_mesa.so.0 libOSMesa.so; do
  ldconfig -p | grep -q "$lib" || need+=("$lib")
done
if [ ${#need[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
      libegl1 libegl-mesa0 libgl1-mesa-dri libgl1 libosmesa6 >/dev/null
  else
    echo "missing headless OpenGL libraries (${need[*]}): install libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6" >&2
  fi
fi

[ -x "$VENV/bin/python" ] || "$PYTHON" -m venv "$VENV"
PIP=("$VENV/bin/python" -m pip --quiet --disable-pip-version-check)
# CPU PyTorch first, so that nothing below can pull the multi-GB CUDA build.
if [ -n "${TORCH_INDEX_URL:-}" ]; then
  "${PIP[@]}" install torch==2.13.0 --index-url "$TORCH_INDEX_URL"
else
  "${PIP[@]}" install torch==2.13.0
fi
"${PIP[@]}" install -e ".[test]"
"$VENV/bin/python" -c "import torch; assert not torch.version.cuda, 'CUDA torch installed; use the CPU wheel'"
echo "orbitdata is set up in $VENV"
