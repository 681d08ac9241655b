#!/usr/bin/env bash
# Makes a fresh GPU machine ready for `cargo xtask bench gpu` (which runs this first):
# - the Vulkan loader (libvulkan1) through apt when it is missing; the NVIDIA driver brings
#   its own Vulkan ICD (nvidia_icd.json);
# - .venv-gpu with the pinned torch, diffusers and transformers of tools/bench/requirements.txt
#   (the diffusers reference), unless it already imports them.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$root"

if ! ldconfig -p 2>/dev/null | grep -q 'libvulkan.so.1'; then
    echo "gpu_setup: installing the Vulkan loader (libvulkan1)" >&2
    export DEBIAN_FRONTEND=noninteractive
    sudo_cmd=""
    if [ "$(id -u)" != 0 ] && command -v sudo >/dev/null; then sudo_cmd=sudo; fi
    $sudo_cmd apt-get update -qq
    $sudo_cmd apt-get install -y -qq libvulkan1 vulkan-tools
fi

venv="$root/.venv-gpu"
if ! "$venv/bin/python" -c 'import torch, diffusers, transformers' 2>/dev/null; then
    echo "gpu_setup: making $venv (torch, diffusers, transformers from PyPI)" >&2
    "${PYTHON:-python3}" -m venv "$venv"
    pins=$(grep -E '^(torch|numpy|diffusers|transformers)==' tools/bench/requirements.txt | cut -d' ' -f1)
    # shellcheck disable=SC2086
    "$venv/bin/python" -m pip install --disable-pip-version-check -q $pins
fi
"$venv/bin/python" -c 'import torch; print(f"gpu_setup: torch {torch.__version__}, cuda {torch.cuda.is_available()}")' >&2
