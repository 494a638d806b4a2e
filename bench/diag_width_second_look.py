"""Diagnosis: the friction width's second look beside a selected Stribeck group (issue 10, branch disc32).

``python bench/diag_width_second_look.py BAGS_DIR WORLD EFFECT [--timing]`` (bags as ``bench_discover.py`` writes
them: BAGS_DIR/*.mcap, the last one held out; e.g. /tmp/s9/b3700/plant2/load_friction/bags).

Runs the bench's own case (``bench_discover.evaluate_world_case``: discover vs greedy on the same bags) with
``Options.width_second_look`` = "skip" (the behaviour before: no second look once a Stribeck group is selected) and
"beside" (asked given the other selected groups, the Stribeck group left out), and prints per mode the held-out RMSE,
greedy's, the paired z, the findings, the baseline width and the Stribeck shape of each final model, the gate's trace
(``width_second_look``) and the selection trace of the target signal. ``--timing``: the same for each of
``Options.angle_timing`` "default" (harmonics at the logged angle) and "retimed" (at the re-timed angle whenever a
skew is identified), with both final models' fit-block CV SSE: how the width's second look and the angle re-timing
interact (seed 2700 hysteretic-robot periodic torque).
"""

import argparse
import glob
import json
import sys
from pathlib import Path
from tempfile import TemporaryDirectory

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bags_dir")
    ap.add_argument("world")
    ap.add_argument("effect", help="effect id, or clean")
    ap.add_argument("--timing", action="store_true", help="also cross with the angle timing (default / retimed)")
    a = ap.parse_args(argv)
    import bench_discover as B
    from hd_ground.discovery import core
    import hd_ground.discovery.pipeline as P

    bags = sorted(glob.glob(str(Path(a.bags_dir) / "*.mcap")))
    if len(bags) < 2:
        raise SystemExit(f"{a.bags_dir}: needs at least two .mcap bags (the last is held out)")
    e = None if a.effect == "clean" else a.effect
    if a.world == "plant2":
        exp = B.PLANT2_EXPECT[a.effect]
        B._plant2_param_errors = lambda *x: (None, None)
    else:
        exp = (B.FAMILY_EFFECTS[e][1],) if e and B.FAMILY_EFFECTS[e][1] else ()
    orig, run0 = core.Options, P.run_discovery
    timings = ("default", "retimed") if a.timing else ("identify",)
    for timing in timings:
        for look in ("skip", "beside"):
            over = {"width_second_look": look, "angle_timing": timing}
            core.Options = lambda *x, _o=over, **k: orig(*x, **{**k, **_o})
            res_all = []

            def run(*x, _r=res_all, **k):
                out = run0(*x, **k)
                _r.extend(k.get("results_out") or [])
                return out
            P.run_discovery = run
            try:
                with TemporaryDirectory() as td:
                    r = B.evaluate_world_case(a.world, e, bags, exp, None, Path(td))
                    rep = json.loads((Path(td) / "report.json").read_text())
            finally:
                P.run_discovery, core.Options = run0, orig
            sig = next(s for s in rep["signals"] if s["signal"] == r["signal"])
            sr = next((x for x in res_all if x.signal == r["signal"] and x.identifiable), None)
            cv = float(sr.cv_folds.sum()) if sr is not None and sr.cv_folds is not None else float("nan")
            strib = next((x["parameters"] for x in sig["effects"] if x["name"] == "stribeck_friction"), None)
            print(f"timing {timing:8s} second look {look:6s}: held-out {r['signal']} RMSE {r['after']:.5g} (greedy "
                  f"{r['greedy_after']:.5g}, paired z {r['paired_z']:+.2f}); found {[f[1] for f in r['found']]}; "
                  f"eps {sig['baseline_parameters'].get('eps_omega', float('nan')):.4g} +- "
                  f"{sig['baseline_parameters'].get('eps_omega_sd', float('nan')):.2g}; fit-block CV SSE {cv:.5g}; "
                  f"angle_skew_s {rep.get('angle_skew_s')}")
            if strib:
                print("    stribeck: " + ", ".join(f"{k} {strib[k]:.3g}" for k in ("omega_s", "delta", "eps",
                                                                                    "T_S_minus_T_C") if k in strib))
            if sig.get("width_second_look"):
                print(f"    width_second_look: {sig['width_second_look']}")
            for t in sig["selection_trace"]:
                if t["step"] != "baseline":
                    print("    " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                                             for k, v in t.items() if k in ("step", "candidate", "gain", "folds_better",
                                                                           "t", "wald", "eps", "eps_first")))
            for n in rep.get("data_notes", []):
                if n.startswith("angle timing"):
                    print(f"    {n}")


if __name__ == "__main__":
    main()
