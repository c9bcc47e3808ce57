#!/usr/bin/env bash
# Set up .venv and run the test suite (fast tests; add -m slow for the long ones).
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
python -m pytest -q "$@"
