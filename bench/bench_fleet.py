"""Fleet analysis on Dask (``hdphm bench fleet``): throughput with 1 and 2 local workers, worker memory over a
long run, a loopback cluster giving the same store, and the arithmetic for a 10 TB fleet.

1. Simulates once (cached, ``--root``, default ``bags/fleet_bench``) ``--units`` x ``--missions`` missions of
   ``--duration`` s at 1 kHz (family A of ``bench/fleet_sim.py``, faults mid-life).
2. Throughput: ``run_fleet`` (the code of ``hdphm ground fleet``) into a fresh store on an embedded
   ``LocalCluster`` of 1, then 2 single-threaded worker processes; the cluster is started before the clock
   (its start-up is a one-off). Missions per second and the ratio 2 / 1 workers.
3. Memory: ``--rounds`` more runs on the 1-worker cluster into fresh stores (the same bags, every mission
   analysed again); the worker's RSS after each round; prints the growth per 100 missions.
4. Loopback: a separate ``dask scheduler`` process and 2 ``dask worker`` processes on 127.0.0.1; the same
   bags into a fresh store; its contents (every table, row for row, timing columns excepted) compared
   with the 2-worker embedded store.
5. Per-mission cost (median analysis time per mission and per sample, bag bytes per sample) and, from those
   measured numbers, the 10 TB fleet (1,000 actuators x 500 missions at 1 kHz): tasks, bytes per task,
   hours per worker count.

The 2-core machine this was written on is shared: the scaling ratio is what the cores gave at that time.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _rss(client) -> list[float]:
    def rss():
        import psutil

        return psutil.Process().memory_info().rss / 2**20

    return list(client.run(rss).values())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench fleet")
    ap.add_argument("--root", default="bags/fleet_bench")
    ap.add_argument("--units", type=int, default=4)
    ap.add_argument("--missions", type=int, default=12)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=4, help="extra 1-worker rounds for the memory curve")
    ap.add_argument("--skip-loopback", action="store_true")
    a = ap.parse_args(argv)
    from distributed import Client, LocalCluster

    from fleet_sim import simulate_fault_fleet
    from hd_ground.fleet.run import run_fleet
    from hd_ground.fleet.store import FleetStore
    from hd_ground.fleet.tasks import FleetOptions

    root = Path(a.root)
    bags = root / f"bags_{a.units}x{a.missions}x{a.duration:g}s"
    t0 = time.perf_counter()
    simulate_fault_fleet(bags, "A", a.units, a.missions, seed=5, duration=a.duration, mission_hours=1.5e3,
                         workers=2)
    n_bags = len(list(bags.rglob("*.mcap")))
    print(f"fleet: {n_bags} bags under {bags} ({time.perf_counter() - t0:.0f} s)", flush=True)
    opts = FleetOptions(healthy_missions=3)
    tmp = Path(tempfile.mkdtemp(prefix="hdphm_fleet_bench_"))
    quiet = dict(progress=False, log=lambda s: None)
    res = {}
    try:
        for nw in (1, 2):
            with LocalCluster(n_workers=nw, threads_per_worker=1, dashboard_address=":0", silence_logs=50) as cl, \
                    Client(cl) as c:
                st = tmp / f"local{nw}"
                s = run_fleet([str(bags)], str(st), opts=opts, client=c, **quiet)
                res[nw] = s
                print(f"{nw} worker(s): {s['missions_stored']} missions in {s['wall_s']:.1f} s = "
                      f"{s['missions_stored'] / s['wall_s']:.2f} missions/s (errors {len(s['errors'])}; machine load "
                      f"average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)", flush=True)
                if nw == 1:
                    mem = [_rss(c)[0]]
                    for r in range(a.rounds):
                        run_fleet([str(bags)], str(tmp / f"mem{r}"), opts=opts, client=c, **quiet)
                        shutil.rmtree(tmp / f"mem{r}")
                        mem.append(_rss(c)[0])
        r1 = res[1]["missions_stored"] / res[1]["wall_s"]
        r2 = res[2]["missions_stored"] / res[2]["wall_s"]
        print(f"\nscaling: {r2 / r1:.2f} x with 2 workers vs 1 ({os.cpu_count()} cores on this machine, shared)")
        slope = np.polyfit(np.arange(len(mem)) * n_bags, mem, 1)[0] * 100 if len(mem) > 1 else float("nan")
        print(f"worker RSS after each round of {n_bags} missions [MiB]: " + ", ".join(f"{m:.0f}" for m in mem)
              + f"; growth {slope:+.1f} MiB per 100 missions over {len(mem) * n_bags} missions")
        if not a.skip_loopback:
            from hd_ground.fleet.loopback import LoopbackCluster

            env = {"PYTHONPATH": os.pathsep.join(p for p in sys.path if p.endswith("src")) + os.pathsep
                   + os.environ.get("PYTHONPATH", "")}
            tl = time.perf_counter()
            with LoopbackCluster(2, env=env) as lc:
                s = run_fleet([str(bags)], str(tmp / "loopback"), lc.address, opts, **quiet)
            same = FleetStore(tmp / "loopback").snapshot() == FleetStore(tmp / "local2").snapshot()
            print(f"loopback cluster (dask scheduler + 2 dask worker processes, {lc.address}): "
                  f"{s['missions_stored']} missions in {s['wall_s']:.1f} s; store identical to the embedded "
                  f"2-worker store: {same} ({time.perf_counter() - tl:.0f} s with start-up)")
        st = FleetStore(tmp / "local1")
        _, rows = st.query("SELECT median(task_s), median(task_s / samples), median(bag_bytes / samples), "
                           "median(bag_bytes), median(samples), median(duration_s) FROM missions")
        t_m, t_s, b_s, b_m, n_m, d_m = rows[0]
        _, rows = st.query("SELECT count(*) FROM rul")
        print(f"\nper mission (1 worker): median task {t_m:.3f} s for {n_m:.0f} samples ({d_m:.0f} s at 1 kHz) = "
              f"{t_s * 1e6:.1f} us per sample; bag {b_m / 1e6:.2f} MB = {b_s:.0f} bytes per sample")
        act_s = res[1]["actuator_task_s"] / max(res[1]["actuators"], 1)
        act_per_mission = res[1]["actuator_task_s"] / max(n_bags, 1)
        print(f"per actuator (RUL update over its {n_bags / a.units:.0f} missions + classes; 1 worker): {act_s:.2f} s "
              f"= {act_per_mission:.3f} s per mission of history (the particle filter is linear in missions)")
        fleet_bytes = 10e12
        n_act, n_mis = 1000, 500
        tasks = n_act * n_mis
        per_task = fleet_bytes / tasks
        samples_task = per_task / b_s
        # one full pass: every mission task + every actuator's RUL/classes over its 500 missions
        cpu_h = tasks * samples_task * t_s / 3600 + n_act * n_mis * act_per_mission / 3600
        print(f"\n10 TB fleet ({n_act} actuators x {n_mis} missions): {tasks:,} mission tasks + {n_act:,} calibration "
              f"and {n_act:,} actuator tasks; {per_task / 1e6:.0f} MB per mission task (= {samples_task / 1e3 / 3600:.1f} h "
              f"of 1 kHz data at {b_s:.0f} B/sample); ~{cpu_h:,.0f} worker-hours in all")
        print("| workers | hours (perfect scaling) | hours at the measured 2-worker efficiency |\n|---|---|---|")
        eff = (r2 / r1) / 2
        for w in (1, 16, 64, 256, 1024):
            print(f"| {w} | {cpu_h / w:,.1f} | {cpu_h / (w * min(eff, 1.0)):,.1f} |")
        print(f"(read bandwidth needed at 256 workers: {256 * per_task / (samples_task * t_s) / 1e9:.2f} GB/s)")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
