"""``hdphm bench [NAME ...]``: run the benchmarks in ``bench/``.

Each ``bench/bench_NAME.py`` exposes ``main(argv) -> int`` and prints medians
and ratios against a baseline measured in the same run. Benchmarks live in the
repository (not the installed package) because they compare against
third-party baselines that users need not install.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path


def bench_dir() -> Path:
    """The repository's ``bench/`` folder (the package is installed editable from ``src/``)."""
    return Path(__file__).resolve().parents[2] / "bench"


def available() -> dict[str, Path]:
    d = bench_dir()
    return {p.stem.removeprefix("bench_"): p for p in sorted(d.glob("bench_*.py"))}


def _run(args: argparse.Namespace) -> int:
    benches = available()
    if not benches:
        print(f"no benchmarks found under {bench_dir()}", file=sys.stderr)
        return 2
    if args.list:
        for name, path in benches.items():
            print(f"{name:12s} {path}")
        return 0
    names = args.names or list(benches)
    unknown = [n for n in names if n not in benches]
    if unknown:
        print(f"unknown benchmark(s) {unknown}; available: {list(benches)}", file=sys.stderr)
        return 2
    rc = 0
    for name in names:
        spec = importlib.util.spec_from_file_location(f"hdphm_bench_{name}", benches[name])
        mod = importlib.util.module_from_spec(spec)
        assert spec.loader is not None
        spec.loader.exec_module(mod)
        print(f"=== bench {name} ({benches[name]})", flush=True)
        t0 = time.perf_counter()
        r = int(mod.main(list(args.extra)) or 0)
        print(f"=== bench {name}: exit {r}, {time.perf_counter() - t0:.1f} s wall", flush=True)
        rc = rc or r
    return rc


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="run benchmarks (bench/bench_*.py): medians and ratios against baselines")
    p.add_argument("names", nargs="*", help="benchmark names (default: all); see --list")
    p.add_argument("--list", action="store_true", help="list the benchmarks")
    p.add_argument("--extra", nargs=argparse.REMAINDER, default=[], help="arguments passed to each benchmark's main()")
    p.set_defaults(func=_run)
