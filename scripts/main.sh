#!/usr/bin/env bash
# The README's main job: set up, then simulate -> train a small twin -> replay through the ROS 2 stack -> report.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export MPLBACKEND=Agg
exec .venv/bin/hdphm demo --out "${HDPHM_DEMO_OUT:-runs/demo}" "$@"
