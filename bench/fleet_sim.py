"""Simulated fleets with faults injected mid-life, for the fleet classification study and benchmarks.

Bench/test helper (imports hd_sim; estimators never import this). ``family`` is either a name of
``hd_sim.families`` (``default``, ``smooth-cubic``, ``deadzone-lugre``, ``hysteretic-robot``: laws, gear
ratio, sensors and log rate drawn per unit) or one of three local variants of the default plant:

* ``A``: the simulator's realistic defaults;
* ``B``: no Stribeck friction, no hysteresis, no position-dependent mesh stiffness, no cogging
  (a smoother, more linear plant);
* ``C``: defaults without load-dependent (mesh sliding) friction, T_C x 1.2 and a stronger kinematic
  error (A2 x 1.5).

A unit whose simulation diverges or whose drawn parameters the plant refuses is left out (and said so): the plant, not the analysis, failed.

Each unit's life gets one of three fault plans: none (tooth wear only), lubrication loss, or
flexspline stiffness loss, with onset drawn mid-life (missions ``onset_range``). ``fleet_truth.json``
holds the truth per mission (scoring only).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

FAULTS = ("none", "lubrication_loss", "flexspline_stiffness_loss")


def family_effects(family: str):
    from hd_sim import EffectSet

    e = EffectSet.default()
    if family == "A":
        return e
    if family == "B":
        return e.with_off("stribeck_friction", "hysteresis", "position_dependent_stiffness", "cogging_torque")
    if family == "C":
        return e.with_off("load_dependent_friction").with_params(
            **{"coulomb_friction.T_C": 1.8, "kinematic_error_harmonic.A2": 6.0e-5})
    raise ValueError(f"unknown plant variant {family!r} (A, B, C)")


def _life(job):
    from hd_sim.fleet import simulate_life

    import shutil

    p, n_missions, out, eff, kw = job
    if kw.get("family"):  # an hd_sim plant family: its laws, gear ratio, sensors and log rate for this unit
        from hd_sim.families import family_unit

        kw = dict(kw)
        u = family_unit(kw.pop("family"), p, base=eff, seed=kw["seed"])
        p, eff, kw["fs"] = u.params, u.effects, u.fs
    try:
        return p["actuator_id"], simulate_life(p, n_missions, out, effects=eff, **kw)
    except (FloatingPointError, ValueError) as e:  # the plant cannot simulate this unit's draw
        print(f"unit {p['actuator_id']} left out: {type(e).__name__}: {e}", flush=True)
        shutil.rmtree(Path(out) / p["actuator_id"], ignore_errors=True)
        return p["actuator_id"], None


def simulate_fault_fleet(out_dir, family: str = "A", n_units: int = 9, n_missions: int = 12, *, seed: int = 0,
                         duration: float = 3.0, mission_hours: float = 3.0e3, onset_range=(4, 7),
                         fault_rate: float = 0.15, workers: int = 1, id_prefix: str | None = None) -> dict:
    """``n_units`` lives of ``family``; unit i gets fault plan ``FAULTS[i % 3]``. Skips if already written."""
    from hd_sim.params import sample_population

    out = Path(out_dir)
    truth_path = out / "fleet_truth.json"
    if truth_path.exists():
        return json.loads(truth_path.read_text())
    out.mkdir(parents=True, exist_ok=True)
    fam_name = None
    if family in ("A", "B", "C"):
        base = family_effects(family)
    else:  # a plant family of hd_sim.families (structurally different laws and sensors)
        from hd_sim import EffectSet

        base, fam_name = EffectSet.default(), family
    rng = np.random.default_rng([seed, 0xF1EE7])
    jobs, plans = [], {}
    for i, p in enumerate(sample_population(n_units, seed, id_prefix=id_prefix or f"{family}{seed}")):
        p["mission_hours"] = float(mission_hours)
        fault = FAULTS[i % len(FAULTS)]
        onset = int(rng.integers(onset_range[0], onset_range[1] + 1))
        eff = base if fault == "none" else base.with_on(fault).with_params(
            **{f"{fault}.onset": float(onset), f"{fault}.rate": float(fault_rate)})
        plans[p["actuator_id"]] = {"fault": fault, "onset": onset if fault != "none" else None}
        jobs.append((p, n_missions, str(out), eff, dict(duration=duration, seed=seed, sim_internal_every=0,
                                                        **({"family": fam_name} if fam_name else {}))))
    if workers > 1:
        import multiprocessing as mp

        with mp.get_context("spawn").Pool(workers) as pool:
            res = dict(pool.map(_life, jobs))
    else:
        res = dict(map(_life, jobs))
    summary = {"family": family, "seed": seed, "duration_s": duration, "actuators": [
        {"actuator_id": aid, "plan": plans[aid], "h_fail": float(job[0]["h_fail"]), "missions": res[aid]}
        for aid, job in zip(plans, jobs) if res[aid] is not None]}
    truth_path.write_text(json.dumps(summary, default=float))
    return summary


if __name__ == "__main__":  # python bench/fleet_sim.py OUT FAMILY SEED N_UNITS
    import sys

    o, fam, sd, n = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    s = simulate_fault_fleet(o, fam, n, seed=sd, workers=int(os.environ.get("WORKERS", "1")))
    print(o, len(s["actuators"]), "units")
