#!/usr/bin/env bash
# The README's test command: set up the venv from scratch if needed, then run the whole suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} MKL_NUM_THREADS=${MKL_NUM_THREADS:-1} MPLBACKEND=Agg
exec .venv/bin/python -m pytest -q -n "${HDPHM_TEST_WORKERS:-2}" --timeout 900 "$@"
