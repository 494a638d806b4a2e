"""A loopback Dask "cluster": a separate ``dask scheduler`` process and ``dask worker`` processes on 127.0.0.1.

What a real deployment runs (docs/FLEET.md), on one machine: used by the benchmark and the tests to show
that the code given ``--scheduler tcp://...`` writes the same store as the embedded cluster. The worker
processes inherit this process's environment (``PYTHONPATH``), so they import the same hdphm code.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _dask_cmd() -> list[str]:
    exe = Path(sys.executable).with_name("dask")
    if exe.is_file():
        return [str(exe)]
    found = shutil.which("dask")
    if found:
        return [found]
    return [sys.executable, "-m", "dask"]


class LoopbackCluster:
    """``with LoopbackCluster(2) as lc: run_fleet(..., scheduler=lc.address)``; ``lc.workers`` are Popen objects."""

    def __init__(self, n_workers: int = 2, env: dict | None = None, log_dir: str | os.PathLike | None = None):
        self.n_workers = int(n_workers)
        self.env = {**os.environ, **(env or {})}
        self.port = _free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.log_dir = Path(log_dir) if log_dir else None
        self.scheduler: subprocess.Popen | None = None
        self.workers: list[subprocess.Popen] = []
        self._logs: list = []

    def _spawn(self, args: list[str], name: str) -> subprocess.Popen:
        out = subprocess.DEVNULL
        if self.log_dir:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            out = open(self.log_dir / f"{name}.log", "w")
            self._logs.append(out)
        return subprocess.Popen(_dask_cmd() + args, env=self.env, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)

    def start(self, timeout: float = 60.0) -> "LoopbackCluster":
        from distributed import Client

        self.scheduler = self._spawn(["scheduler", "--host", "127.0.0.1", "--port", str(self.port),
                                      "--no-dashboard"], "scheduler")
        for i in range(self.n_workers):
            self.add_worker(f"worker{i}")
        t0 = time.time()
        with Client(self.address, timeout=timeout) as c:
            while len(c.scheduler_info().get("workers", {})) < self.n_workers:
                if time.time() - t0 > timeout:
                    self.close()
                    raise TimeoutError(f"loopback cluster: {self.n_workers} workers not up within {timeout} s")
                time.sleep(0.2)
        return self

    def add_worker(self, name: str = "") -> subprocess.Popen:
        w = self._spawn(["worker", self.address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard",
                         "--no-nanny", "--name", name or f"w{len(self.workers)}"], name or f"w{len(self.workers)}")
        self.workers.append(w)
        return w

    def kill_worker(self, i: int = 0) -> None:
        """SIGKILL worker ``i`` (no clean shutdown: what a crashed node looks like)."""
        os.killpg(self.workers[i].pid, signal.SIGKILL)
        self.workers[i].wait(10)

    def close(self) -> None:
        for p in self.workers + ([self.scheduler] if self.scheduler else []):
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGTERM)
                    p.wait(10)
                except (ProcessLookupError, subprocess.TimeoutExpired):
                    try:
                        os.killpg(p.pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
        for f in self._logs:
            f.close()

    def __enter__(self) -> "LoopbackCluster":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()
