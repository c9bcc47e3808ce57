#!/usr/bin/env bash
# Creates .venv (if missing) and installs parallax into it; sourced by train.sh and test.sh.
# Idempotent: re-installs only when pyproject.toml changed since the last install.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
python="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv with $($python --version 2>&1)"
  "$python" -m venv .venv
fi
# shellcheck disable=SC1091
. .venv/bin/activate
stamp=.venv/.parallax-installed
want="$(sha256sum pyproject.toml | cut -d' ' -f1)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  log=.venv/pip-install.log
  echo "[setup] installing parallax into .venv (log: $log)"
  {
    python -m pip install --upgrade pip
    if ! python -c "import torch"; then
      # torch 2.13.0 first and on its own: on these machines it comes from a local CPU wheel;
      # elsewhere, PARALLAX_TORCH_PIP_ARGS can point pip at a CPU-only index.
      # shellcheck disable=SC2086
      python -m pip install "torch==2.13.0" ${PARALLAX_TORCH_PIP_ARGS:-}
    fi
    python -m pip install -e ".[test,sweeps]"
  } > "$log" 2>&1 || { tail -n 40 "$log"; echo "[setup] installation failed; see $log" >&2; exit 1; }
  echo "$want" > "$stamp"
  echo "[setup] installed parallax into .venv"
fi
# Headless rendering: respect a backend the user chose, default to EGL.
export MUJOCO_GL="${MUJOCO_GL:-egl}"
