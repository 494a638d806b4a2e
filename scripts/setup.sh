#!/usr/bin/env bash
# Creates .venv and installs hdphm with its pinned dependencies.
# Idempotent: re-installs only when pyproject.toml changed since the last run.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv with $($PY --version)"
  "$PY" -m venv .venv
fi
# Headless browser for the report page's test (Debian's chromium); the test says why it skips if this fails.
if ! command -v chromium >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
  echo "[setup] installing Debian's chromium (headless browser test of 'hdphm report')"
  if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium; } >/tmp/hdphm-apt.log 2>&1; then
    echo "[setup] chromium could not be installed (see /tmp/hdphm-apt.log): the browser test will be skipped"
  fi
fi
stamp=.venv/.hdphm-installed
want=$(sha256sum pyproject.toml | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && .venv/bin/python -c "import hdphm" 2>/dev/null; then
  exit 0
fi
echo "[setup] installing dependencies into .venv (first time: several minutes)"
.venv/bin/python -m pip install -q --upgrade pip
# torch first and pinned: any other version pulls gigabytes of CUDA packages
.venv/bin/python -m pip install -q "torch==2.13.0"
.venv/bin/python -m pip install -q -e ".[dev]"
echo "$want" > "$stamp"
echo "[setup] done"
