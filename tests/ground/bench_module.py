"""``bench/bench_discover.py`` loaded once for the discovery tests that run its cases (it is a script, not a package
module): ``from .bench_module import bd``."""

import importlib.util
import sys
from pathlib import Path

_NAME = "bench_discover_for_tests"
_BENCH = Path(__file__).resolve().parents[2] / "bench" / "bench_discover.py"

if _NAME in sys.modules:
    bd = sys.modules[_NAME]
else:
    _spec = importlib.util.spec_from_file_location(_NAME, _BENCH)
    bd = importlib.util.module_from_spec(_spec)
    sys.modules[_NAME] = bd
    _spec.loader.exec_module(bd)
