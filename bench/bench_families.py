"""What today's estimators score on each plant family and on the independent plant2 (issue 9 baseline).

``hdphm bench families [--extra --worlds default,smooth-cubic,... --out runs/bench_families --quick]``
(or ``python bench/bench_families.py ...``). Per world (an ``hd_sim`` family, ``hdphm sim family
--list``, or ``plant2`` = ``tests/plants/ema2.py``, written without any of our code):

* **discovery**: four missions of one actuator with one hidden effect (the world's case below), the
  public ``hd_ground.discovery.run_discovery`` (what ``hdphm discover`` runs) on the first three, the
  fourth held out whole. Scored: is the *first* effect reported on the signal the hidden effect shows in
  the hidden one (name, variable, and order where it has one; a stiffness-law finding on Q_red is
  skipped in worlds whose torsion law is not linear), and the held-out RMSE after/before on that signal.
* **twin**: the same world's four *clean* missions; ``hd_twin.train.train_twin`` with the ``small``
  preset (what ``hdphm train --preset small`` runs) on the first three, ``eval_model`` (``hdphm twin eval``)
  on the fourth: held-out NRMSE of Q_red. Reference in the same run: a 4-term least-squares torque
  balance ``Q_red ~ a tau_m + b domega_m/dt + c tanh(omega_m/eps) + d omega_m`` fitted on the same three
  missions (eps picked from 8 values on the fit missions; domega_m/dt a 2nd-order Savitzky-Golay
  derivative over 21 ms), NRMSE = RMSE / range of the held-out Q_red.
* **prognostics**: a small run-to-failure fleet (wear accelerated, ``--set mission_hours``), today's
  wear-truth-calibrated path: ``hd_prognostic.evaluate.load_fleet`` + ``fleet_eval`` (what ``hdphm
  prognostic eval`` runs: ``fit-obs`` on the other actuators' ``/sim/health`` wear truth, particle-filter
  ``prognose``, leave-one-actuator-out). Scored: P5-P95 coverage and the fraction of predictions in the
  alpha = 0.2 cone for lambda >= 0.5 (mean over units). plant2 has no ``/sim`` topics, so today's
  calibration cannot run on it (the error is recorded); it is scored with the *packaged* observation
  model (``hdphm prognose`` without ``--obs-model``) instead, which is what a user can do today.

Raw results: ``OUT/bench_families.json``; the table is printed (markdown). Sizes are small on purpose
(a loaded 2-core machine): single seeds, 4 missions per case, a few units per fleet; read the numbers
as a baseline with large spread, not a ranking of the families.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

WORLDS = ("default", "smooth-cubic", "deadzone-lugre", "hysteretic-robot", "plant2")

#: world -> (hidden effect, its parameters, expected first finding (signal, name, variable, order or None))
HIDDEN = {
    "default": ("position_periodic_torque", {"position_periodic_torque.P1": 0.6, "position_periodic_torque.P2": 0.0},
                ("tau_m", "position_periodic_torque", "theta_m", 1.0)),
    "smooth-cubic": ("kinematic_error_harmonic", {"kinematic_error_harmonic.order": 2},
                     ("Q_red", "kinematic_error_harmonic", "theta_m", 2.0)),
    "deadzone-lugre": ("stribeck_friction", {"stribeck_friction.ratio": 2.5},
                       ("tau_m", "stribeck_friction", "omega_m", None)),
    "hysteretic-robot": ("position_periodic_friction",
                         {"position_periodic_friction.order": 2, "position_periodic_friction.F2": 0.8},
                         ("tau_m", "position_periodic_friction", "theta_m", 2.0)),
    # plant2's 2/rev motor torque ripple (direction-independent): the catalogue's position-periodic torque
    "plant2": ("ripple", None, ("tau_m", "position_periodic_torque", "theta_m", 2.0)),
}


# ---------------------------------------------------------------------------------------------
# data
# ---------------------------------------------------------------------------------------------
def case_bags(world: str, effect: str | None, params, out: Path, *, duration: float, seed: int) -> list[Path]:
    """Four missions of one actuator; the last is the held-out one."""
    if world == "plant2":
        from tests.plants import ema2

        return list(ema2.write_case(out, effect or "clean", seed=seed, duration=duration)["bags"])
    from hd_sim.families import write_family_case

    return list(write_family_case(out, world, effect, params, n_missions=4, duration=duration, seed=seed)["bags"])


def fleet_dir(world: str, out: Path, *, units: int, missions: int, duration: float, hours: float, seed: int) -> dict:
    if world == "plant2":
        from tests.plants import ema2

        tr = ema2.fleet(out, units=units, missions=missions, duration=duration, seed=seed,
                        life_missions=0.6 * missions)
        return {"eol": {u["actuator_id"]: u["failure_mission"] for u in tr["units"]}}
    from hd_sim.fleet import simulate_fleet

    s = simulate_fleet(units, missions, out, seed=seed, duration=duration, progress=False, sim_internal_every=0,
                       family=None if world == "default" else world, overrides={"mission_hours": hours})
    return {"eol": {a["actuator_id"]: a["eol_mission"] for a in s["actuators"]}}


# ---------------------------------------------------------------------------------------------
# discovery
# ---------------------------------------------------------------------------------------------
def run_discovery_case(world: str, out: Path, *, duration: float, seed: int) -> dict:
    from hd_ground.discovery.pipeline import run_discovery

    effect, params, expect = HIDDEN[world]
    bags = case_bags(world, effect, params, out / "bags", duration=duration, seed=seed)
    t0 = time.perf_counter()
    rep = run_discovery([str(b) for b in bags], out / "discovery", heldout=[str(bags[-1])], plots=False,
                        log=lambda s: None)
    keys = [(e["signal"], e["name"], e["variable"], e["order"]) for e in rep["effects"]]
    # scored: the first finding on the hidden effect's signal; a stiffness-law finding on Q_red is not held
    # against a world whose torsion is not linear (every world but default: its baseline torsion is linear)
    on_sig = [k for k in keys if k[0] == expect[0] and not (world != "default" and k[1] == "nonlinear_stiffness")]
    first = on_sig[0] if on_sig else None
    right = bool(first is not None and first[0] == expect[0] and first[1] == expect[1] and first[2] == expect[2]
                 and (expect[3] is None or (first[3] is not None and abs(float(first[3]) - expect[3]) < 1e-9)))
    sig = next((s for s in rep["signals"] if s["signal"] == expect[0]), None)
    before = sig["error_before"].get("rmse") if sig else float("nan")
    after = sig["error_after"].get("rmse") if sig else float("nan")
    return {"effect": effect, "expected": list(expect), "first": list(first) if first else None,
            "first_overall": list(keys[0]) if keys else None,
            "found": [list(k) for k in keys], "first_named_right": right, "signal": expect[0],
            "rmse_before": before, "rmse_after": after,
            "after_over_before": float(after / before) if before and np.isfinite(before) else float("nan"),
            "seconds": time.perf_counter() - t0}


# ---------------------------------------------------------------------------------------------
# twin vs least squares
# ---------------------------------------------------------------------------------------------
EPS_GRID = np.geomspace(0.02, 10.0, 8)  # rad/s, motor speed


def _ls_design(m, eps: float) -> tuple[np.ndarray, np.ndarray]:
    from scipy.signal import savgol_filter

    t = np.asarray(m.t, float)
    fs = 1.0 / float(np.median(np.diff(t)))
    win = max(5, int(round(0.021 * fs)) | 1)
    w = np.asarray(m.omega_m, float)
    dw = savgol_filter(w, win, 2, deriv=1, delta=1.0 / fs)
    X = np.column_stack([m.tau_m, dw, np.tanh(w / eps), w])
    y = np.asarray(m.Q_red, float)
    ok = np.all(np.isfinite(X), axis=1) & np.isfinite(y)
    return X[ok], y[ok]


def ls_balance(fit, held) -> dict:
    """The 4-term least-squares torque balance (eps picked on the fit missions)."""
    best = None
    for eps in EPS_GRID:
        parts = [_ls_design(m, eps) for m in fit]
        X = np.vstack([p[0] for p in parts])
        y = np.concatenate([p[1] for p in parts])
        c, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = float(np.sqrt(np.mean((X @ c - y) ** 2)))
        if best is None or r < best[0]:
            best = (r, eps, c)
    _, eps, c = best
    X, y = _ls_design(held, eps)
    e = X @ c - y
    rmse = float(np.sqrt(np.mean(e**2)))
    return {"eps": float(eps), "coef": c.tolist(), "rmse": rmse, "nrmse_pct": 100.0 * rmse / float(np.ptp(y)),
            "max_err": float(np.max(np.abs(e)))}


def run_twin_case(world: str, out: Path, *, duration: float, seed: int, epochs: int | None, threads: int) -> dict:
    from hd_bag import read_mission
    from hd_twin.train import TrainConfig, eval_model, train_twin

    bags = case_bags(world, None, None, out / "bags", duration=duration, seed=seed)
    ms = [read_mission(b) for b in bags]
    t0 = time.perf_counter()
    over = {"threads": threads, "seed": 0, "export_onnx": False, "plots": False}  # accuracy unaffected
    if epochs:
        over["epochs"] = epochs
    cfg = TrainConfig.from_preset("small", **over)
    res = train_twin(ms[:3], out / "model", cfg, progress=False)
    met = eval_model(out / "model", [ms[3]])
    ls = ls_balance(ms[:3], ms[3])
    return {"twin_nrmse_pct": met["nrmse_pct"], "twin_max_err": met["max_err"], "twin_rmse": met.get("rmse"),
            "physics_only_nrmse_pct": (met.get("physics_only") or {}).get("nrmse_pct"),
            "twin_notes": met.get("notes", []), "ls": ls, "ratio_twin_over_ls": met["nrmse_pct"] / ls["nrmse_pct"],
            "train_seconds": res.metrics.get("train_time_s"), "seconds": time.perf_counter() - t0}


# ---------------------------------------------------------------------------------------------
# prognostics
# ---------------------------------------------------------------------------------------------
def run_prog_case(world: str, out: Path, *, units: int, missions: int, duration: float, hours: float,
                  particles: int, seed: int) -> dict:
    from hd_prognostic.evaluate import fleet_eval, load_fleet

    t0 = time.perf_counter()
    fd = out / "fleet"
    truth = fleet_dir(world, fd, units=units, missions=missions, duration=duration, hours=hours, seed=seed)
    t_sim = time.perf_counter() - t0
    fleet = load_fleet(fd, cache_dir=out / "cache", progress=False)
    r: dict = {"eol": truth["eol"], "sim_seconds": t_sim}
    if world != "plant2":
        s = fleet_eval(fleet, out / "eval", folds=len(fleet), n_particles=particles, seed=0, with_ukf=False,
                       progress=False)
        ag = s["aggregate"]
        r.update(model="wear-truth-calibrated (fit-obs on the other units, leave-one-out)",
                 coverage=ag.get("coverage_p5_p95"), in_cone=ag.get("frac_in_cone_lambda_ge_0.5"),
                 cra=ag.get("cra"), n_scored=ag.get("n_units"), censored=s.get("censored"))
    else:
        from hd_prognostic import metrics as M
        from hd_prognostic.pipeline import DEFAULT_OBS_MODEL, fit_population, prognose
        from hd_prognostic.observation import ObservationModel

        try:
            fit_population(fleet)
            r["calibration"] = "fit-obs ran (unexpected)"
        except Exception as e:  # noqa: BLE001 - record why today's calibration cannot run
            r["calibration"] = f"fit-obs impossible: {type(e).__name__}: {e}"
        obs = ObservationModel.from_json(DEFAULT_OBS_MODEL)
        per = []
        for a in fleet:
            eol = truth["eol"].get(a.actuator_id)
            if eol is None:
                continue
            hist = prognose(a, obs, n_particles=particles, seed=0)
            per.append(M.score_history(hist.rul_t, hist.p50, hist.p5, hist.p95, float(eol), alpha=0.2,
                                       samples=hist.samples or None))
        ag = M.aggregate(per) if per else {}
        r.update(model="packaged observation model (no calibration possible)",
                 coverage=ag.get("coverage_p5_p95"), in_cone=ag.get("frac_in_cone_lambda_ge_0.5"),
                 cra=ag.get("cra"), n_scored=len(per))
    r["seconds"] = time.perf_counter() - t0
    return r


# ---------------------------------------------------------------------------------------------
def _f(x, fmt="{:.2f}") -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else fmt.format(x)


def format_table(res: dict) -> str:
    lines = ["| world | hidden effect | discovery: first named right? (first finding) | held-out after/before | "
             "twin NRMSE % | twin's physics-only % | LS balance NRMSE % | twin / LS | prognostics: P5-P95 coverage | "
             "in cone (alpha 0.2) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for w, r in res.items():
        d, t, p = r.get("discovery", {}), r.get("twin", {}), r.get("prognostics", {})
        first = d.get("first")
        ftxt = "none" if not first else f"{first[1]} ({first[2]}" + ("" if first[3] is None else f", {first[3]:g}") + ")"
        right = "-" if not d else ("yes" if d.get("first_named_right") else "no")
        pm = "" if w != "plant2" else " (packaged model)"
        err = lambda x: f"error: {x['error'][:60]}" if "error" in x else None  # noqa: E731
        if err(d):
            ftxt, right = err(d), "-"
        lines.append(f"| {w} | {d.get('effect', '-')} | {right}: {ftxt} | {_f(d.get('after_over_before'))} | "
                     f"{_f(t.get('twin_nrmse_pct'))} | {_f(t.get('physics_only_nrmse_pct'))} | "
                     f"{_f((t.get('ls') or {}).get('nrmse_pct'), '{:.3f}')} | "
                     f"{_f(t.get('ratio_twin_over_ls'), '{:.1f}')} | {_f(p.get('coverage'))}{pm} | "
                     f"{_f(p.get('in_cone'))}{pm} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench families", description=__doc__.split("\n\n")[0])
    ap.add_argument("--worlds", default=",".join(WORLDS), help="comma-separated: hd_sim families and/or plant2")
    ap.add_argument("--parts", default="discovery,twin,prognostics")
    ap.add_argument("--out", default="runs/bench_families")
    ap.add_argument("--duration", type=float, default=6.0, help="s per case mission (hd_sim; plant2: its own 12 s)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--epochs", type=int, default=None, help="twin epochs (default: the small preset's 15)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--units", type=int, default=5, help="actuators per prognostic fleet")
    ap.add_argument("--missions", type=int, default=40, help="max missions per unit")
    ap.add_argument("--fleet-duration", type=float, default=6.0, help="s per fleet mission")
    ap.add_argument("--mission-hours", type=float, default=3500.0,
                    help="hd_sim wear acceleration (hours one fleet mission stands for)")
    ap.add_argument("--particles", type=int, default=1000)
    ap.add_argument("--table", action="store_true", help="only print the table of OUT/bench_families.json")
    ap.add_argument("--merge", action="store_true",
                    help="update OUT/bench_families.json (rerun some worlds/parts, keep the others)")
    a = ap.parse_args(argv)
    worlds = [w for w in a.worlds.split(",") if w]
    parts = [p for p in a.parts.split(",") if p]
    from hd_sim.families import FAMILIES

    bad = [w for w in worlds if w not in FAMILIES and w != "plant2"] + [p for p in parts if p not in
                                                                        ("discovery", "twin", "prognostics")]
    if bad:
        print(f"unknown world(s)/part(s) {bad}; worlds: {list(FAMILIES) + ['plant2']}", file=sys.stderr)
        return 2
    if "plant2" in worlds:
        root = Path(__file__).resolve().parents[1]
        if str(root) not in sys.path:
            sys.path.insert(0, str(root))  # tests.plants.ema2 lives in the repository, not in the package
    out = Path(a.out)
    if a.table:
        print(format_table(json.loads((out / "bench_families.json").read_text())["results"]))
        return 0
    out.mkdir(parents=True, exist_ok=True)
    res: dict = {}
    jpath = out / "bench_families.json"
    if a.merge and jpath.exists():
        res = json.loads(jpath.read_text())["results"]
    t_all = time.perf_counter()
    for w in worlds:
        res.setdefault(w, {})
        wd = out / w
        for part in parts:
            t0 = time.perf_counter()
            print(f"[{w}] {part} ...", flush=True)
            try:
                if part == "discovery":
                    r = run_discovery_case(w, wd / "discovery", duration=a.duration, seed=a.seed)
                    print(f"    first {r['first']} (expected {r['expected']}), after/before "
                          f"{r['after_over_before']:.3f}", flush=True)
                elif part == "twin":
                    r = run_twin_case(w, wd / "twin", duration=a.duration, seed=a.seed, epochs=a.epochs,
                                      threads=a.threads)
                    print(f"    twin NRMSE {r['twin_nrmse_pct']:.3f} %, LS {r['ls']['nrmse_pct']:.3f} % "
                          f"(eps {r['ls']['eps']:.3g})", flush=True)
                else:
                    r = run_prog_case(w, wd / "prognostics", units=a.units, missions=a.missions,
                                      duration=a.fleet_duration, hours=a.mission_hours, particles=a.particles,
                                      seed=a.seed)
                    print(f"    EOL {r['eol']}; coverage {_f(r.get('coverage'))}, in-cone {_f(r.get('in_cone'))}"
                          + (f"; {r['calibration']}" if "calibration" in r else ""), flush=True)
            except Exception as e:  # noqa: BLE001 - a world that breaks an estimator is a result, not a crash
                import traceback

                r = {"error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc(limit=3)}
                print(f"    ERROR {r['error']}", flush=True)
            r["wall_s"] = time.perf_counter() - t0
            r["args"] = dict(vars(a))
            res[w][part] = r
            jpath.write_text(json.dumps({"args": vars(a), "results": res}, indent=1, default=str))
    print()
    print(format_table(res))
    print(f"\n{time.perf_counter() - t_all:.0f} s wall; raw results in {jpath}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
