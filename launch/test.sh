#!/usr/bin/env bash
# Set up .venv, check lint and formatting (ruff), and run the test suite (fast tests; add
# -m slow for the long ones).
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
ruff check .
ruff format --check .
python -m pytest -q "$@"
