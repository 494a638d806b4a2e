"""The fleet analysis on Dask: a loopback cluster (separate scheduler and worker processes) writes the same
store as the embedded one, and a run whose worker and client are killed mid-way resumes with no duplicate
and no lost row."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("distributed")
pytest.importorskip("duckdb")

SRC = str(Path(__file__).resolve().parents[2] / "src")


@pytest.fixture(scope="module")
def loopback():
    from hd_ground.fleet.loopback import LoopbackCluster

    env = {"PYTHONPATH": SRC + os.pathsep + os.environ.get("PYTHONPATH", ""), "HDPHM_FLEET_TASK_DELAY_S": "0.4"}
    with LoopbackCluster(2, env=env) as lc:
        yield lc


def _opts():
    from hd_ground.fleet.tasks import FleetOptions

    return FleetOptions(healthy_missions=1, onboard={"warmup_s": 1.0}, n_particles=200)


def test_loopback_equals_embedded_and_resume_after_kill(small_fleet_dir, loopback, tmp_path):
    from distributed import Client, LocalCluster

    from hd_ground.fleet.run import run_fleet
    from hd_ground.fleet.store import FleetStore

    n_bags = len(list(small_fleet_dir.rglob("*.mcap")))
    # 1. clean run on the loopback cluster (scheduler address, bags read by the worker processes)
    s = run_fleet([str(small_fleet_dir)], str(tmp_path / "clean"), loopback.address, _opts(), progress=False,
                  log=lambda s: None)
    assert s["missions_stored"] == n_bags and not s["errors"] and s["workers"] == 2
    clean = FleetStore(tmp_path / "clean").snapshot()
    assert len(clean["missions"]) == n_bags and len(clean["rul"]) == n_bags
    assert (tmp_path / "clean" / "fleet.duckdb").is_file()

    # 2. the embedded cluster (in-process worker) on the same data: identical store contents
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0",
                      silence_logs=50) as cl, Client(cl) as c:
        s2 = run_fleet([str(small_fleet_dir)], str(tmp_path / "local"), opts=_opts(), progress=False, client=c,
                       log=lambda s: None)
        assert s2["missions_stored"] == n_bags
        assert FleetStore(tmp_path / "local").snapshot() == clean
        # a rerun skips every stored mission and changes nothing
        s3 = run_fleet([str(small_fleet_dir)], str(tmp_path / "local"), opts=_opts(), progress=False, client=c,
                       log=lambda s: None)
        assert s3["missions_todo"] == 0 and s3["missions_skipped"] == n_bags
        assert FleetStore(tmp_path / "local").snapshot() == clean

    # 3. a client process on the loopback cluster; kill a worker, then the client, mid-way
    killed = tmp_path / "killed"
    cmd = [sys.executable, "-m", "hdphm.cli", "ground", "fleet", str(small_fleet_dir), "--store", str(killed),
           "--scheduler", loopback.address, "--healthy-missions", "1", "--onboard", "warmup_s=1.0",
           "--particles", "200", "--quiet"]
    env = {**os.environ, "PYTHONPATH": SRC + os.pathsep + os.environ.get("PYTHONPATH", "")}
    client = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    st = FleetStore(killed)
    try:
        t0 = time.time()
        while sum(map(len, st.done_missions().values())) < 1:
            assert client.poll() is None, "the client ended before any mission was stored"
            assert time.time() - t0 < 60, "no mission stored within 60 s"
            time.sleep(0.05)
        loopback.kill_worker(0)
        os.killpg(client.pid, signal.SIGKILL)
        client.wait(10)
    finally:
        if client.poll() is None:
            os.killpg(client.pid, signal.SIGKILL)
    n_at_kill = sum(map(len, st.done_missions().values()))
    assert 1 <= n_at_kill < n_bags, f"kill came too late to test anything ({n_at_kill}/{n_bags} stored)"
    loopback.add_worker("replacement")
    # 4. resume: only the missing missions run; the store equals the clean run's, row for row
    s4 = run_fleet([str(small_fleet_dir)], str(killed), loopback.address, _opts(), progress=False, log=lambda s: None)
    assert s4["missions_skipped"] >= n_at_kill and s4["missions_stored"] == n_bags - s4["missions_skipped"]
    assert st.snapshot() == clean
