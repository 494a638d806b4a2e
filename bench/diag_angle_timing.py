"""Diagnosis: position harmonics at the logged angle vs at the angle re-timed by the acquisition skew (issue 10, disc29).

``python bench/diag_angle_timing.py BAGS_DIR WORLD EFFECT`` (bags as ``bench_discover.py`` writes them:
BAGS_DIR/*.mcap, the last one held out; e.g. /tmp/s9/b2700/hysteretic-robot/position_periodic_torque/bags).

Runs the bench's own case (``bench_discover.evaluate_world_case``: discover vs greedy on the same bags) three
times, with ``Options.angle_timing`` = "default" (harmonics at the logged angle, the behaviour before), "identify"
(the rule: re-timed only when the fit bags' CV of the final model prefers it, ``core.choose_angle_timing``) and
"retimed" (re-timed whenever a skew is identified: diagnosis only), and prints per mode the held-out RMSE, greedy's,
the paired z and the findings; then the per-block leave-one-block-out CV SSE on the fit bags of the two final
models (logged / re-timed) against each block's mean |omega_m| (a timing error of an order-k harmonic grows as
k omega s: the blocks where the re-timing can matter are the fast ones).
"""

import argparse
import glob
import json
import sys
from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bags_dir")
    ap.add_argument("world")
    ap.add_argument("effect", help="effect id, or clean")
    a = ap.parse_args(argv)
    import bench_discover as B
    from hd_ground.discovery import core
    from hd_ground.discovery.data import dataset_from_missions
    from hd_bag import read_mission

    bags = sorted(glob.glob(str(Path(a.bags_dir) / "*.mcap")))
    if len(bags) < 2:
        raise SystemExit(f"{a.bags_dir}: needs at least two .mcap bags (the last is held out)")
    e = None if a.effect == "clean" else a.effect
    if a.world == "plant2":
        exp = B.PLANT2_EXPECT[a.effect]
        B._plant2_param_errors = lambda *x: (None, None)
    else:
        exp = (B.FAMILY_EFFECTS[e][1],) if e and B.FAMILY_EFFECTS[e][1] else ()
    orig = core.Options
    folds = {}
    for mode in ("default", "identify", "retimed"):
        core.Options = lambda *x, _m=mode, **k: orig(*x, **{**k, "angle_timing": _m})
        res_all = []
        import hd_ground.discovery.pipeline as P
        run0 = P.run_discovery

        def run(*x, _r=res_all, **k):
            out = run0(*x, **k)
            _r.extend(k.get("results_out") or [])  # the bench's own list (its paired z reads it)
            return out
        P.run_discovery = run
        with TemporaryDirectory() as td:
            r = B.evaluate_world_case(a.world, e, bags, exp, None, Path(td))
            rep = json.loads((Path(td) / "report.json").read_text())
        P.run_discovery = run0
        core.Options = orig
        notes = [n for n in rep.get("data_notes", []) if n.startswith("angle timing")]
        print(f"{mode:9s} held-out {r['signal']} RMSE {r['after']:.5g} (greedy {r['greedy_after']:.5g}, paired z "
              f"{r['paired_z']:+.2f}); found {r['found']}; angle_skew_s {rep.get('angle_skew_s')}")
        for n in notes:
            print(f"          {n}")
        sr = next((x for x in res_all if x.signal == r["signal"] and x.identifiable), None)
        if sr is not None and mode in ("default", "retimed"):
            folds[mode] = sr.cv_folds
    if len(folds) == 2 and folds["default"] is not None and folds["retimed"] is not None \
            and len(folds["default"]) == len(folds["retimed"]):
        ms = [read_mission(b) for b in bags[:-1]]
        ds = dataset_from_missions(ms, bags[:-1])
        speed = [float(np.mean(np.abs(ds.signals["omega_m"][ds.block == b]))) for b in np.unique(ds.block)]
        d, rt = folds["default"], folds["retimed"]
        if len(speed) == len(d):
            print("per fit block: mean |omega_m| rad/s, CV SSE logged, re-timed, gain %")
            for s_, x, y in sorted(zip(speed, d, rt)):
                print(f"  {s_:8.2f}  {x:11.5g}  {y:11.5g}  {100 * (1 - y / x):+6.1f}")


if __name__ == "__main__":
    main()
