#!/usr/bin/env bash
# Set up .venv and run the default experiment (conf/experiment/quickstart.yaml): our recipe on
# multiple lateral positions 5–20 cm with weighting, built-in stimuli, about 20 minutes on a
# 2-core CPU. Extra arguments are Hydra overrides, e.g.  bash launch/train.sh seed=1
set -euo pipefail
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
parallax-train experiment=quickstart "$@"
