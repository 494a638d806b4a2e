"""Fleets: run-to-failure lives of many actuators, one bag per mission, one folder per actuator.

Two time scales (PHYSICS.md 4): each mission is a short dynamic inspection
episode; between missions the wear state advances quasi-statically by
Archard's law from the episode's own load spectrum (the per-flank integrals
of |T_tr| |omega_m|), times the acceleration factor mission_hours * 3600 / duration. A life ends at
the first mission whose starting mean flank wear reaches ``h_fail`` (that
mission is still written: it is the failed state) or at ``n_missions``.
Actuators are independent, so they run in parallel worker processes.
"""

from __future__ import annotations

import json
import os
import sys
import zlib
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from .effects import EffectSet
from .params import archard_increment, check_params, new_health, sample_population

PROFILE_MIX = ("inspection",)


def bag_name(actuator_id: str, mission_index: int) -> str:
    """File name of a mission bag; sorts by mission index."""
    return f"{actuator_id}_m{mission_index:04d}.mcap"


def advance_health(health: Mapping[str, float], wear: Mapping[str, float], params: Mapping[str, Any],
                   effects: EffectSet, mission_index: int, duration: float) -> dict[str, float]:
    """Health at the start of the next mission (quasi-static wear and fault growth)."""
    h = dict(health)
    lube = h.get("lube_loss", 0.0)
    if effects.is_on("meshing_wear"):
        h["h_plus"] = h["h_plus"] + archard_increment(wear["W_plus"], params, duration, lube)
        h["h_minus"] = h["h_minus"] + archard_increment(wear["W_minus"], params, duration, lube)
    for name, key in FAULT_HEALTH:
        if effects.is_on(name) and mission_index + 1 >= effects.p(name, "onset"):
            h[key] = _grown(h, effects, name, key)
    return h


#: fleet faults -> their health key.
FAULT_HEALTH = (("flexspline_stiffness_loss", "fs_loss"), ("lubrication_loss", "lube_loss"))
#: window of the mission (fraction of its duration) in which a fleet fault's onset is drawn.
ONSET_WINDOW = (0.2, 0.8)


def _grown(h: Mapping[str, float], effects: EffectSet, name: str, key: str) -> float:
    """Fault level after one more mission of growth (``rate`` per mission, capped at 0.9)."""
    return min(h.get(key, 0.0) + effects.p(name, "rate"), 0.9)


def onset_fault(health: Mapping[str, float], effects: EffectSet, mission_index: int, duration: float,
                seed: int) -> dict[str, float] | None:
    """The fault that starts **inside** mission ``mission_index`` of a life, or None.

    A fleet fault (``onset``, ``rate`` per mission) first grows after mission
    ``ceil(onset) - 1``; that mission carries the onset at a time drawn uniformly in
    ``ONSET_WINDOW`` x duration (seeded), stepping to the level the next mission starts
    with, so the fault appears mid-mission as in service, not at a mission boundary. If
    both faults start in the same mission, the flexspline one is injected and the other
    only grows between missions.
    """
    for name, key in FAULT_HEALTH:
        if not effects.is_on(name) or effects.p(name, "rate") <= 0.0:
            continue
        first = max(0, int(np.ceil(effects.p(name, "onset"))) - 1)
        if mission_index == first:
            u = float(np.random.default_rng([int(seed), 0xFA17]).uniform(*ONSET_WINDOW))
            return {"name": name, "severity": _grown(health, effects, name, key), "t_onset": u * duration}
    return None


def simulate_life(params: Mapping[str, Any], n_missions: int, out_dir: str | os.PathLike | None = None, *,
                  effects: EffectSet | None = None, duration: float = 20.0, fs: float = 1000.0,
                  seed: int = 0, profiles: Iterable[str] = PROFILE_MIX, n_sub: int | None = None,
                  stop_at_failure: bool = True, tick=None, sim_internal_every: int = 10) -> list[dict[str, Any]]:
    """One actuator's life; writes bags under ``out_dir/<actuator_id>/`` when given.

    Every bag carries ``/sim/health`` and ``/sim/effects``; the bulky per-sample
    ``/sim/internal`` goes into missions 0, k, 2k, ... (k = ``sim_internal_every``;
    1 = all, 0 = none) and the last one, so a life stays a few hundred MB.

    Returns one record per mission: index, file, health at start, wear integrals.
    """
    effects = effects if effects is not None else EffectSet.default()
    profiles = tuple(profiles)
    aid = str(params["actuator_id"])
    health = new_health()
    rows: list[dict[str, Any]] = []
    hours = 0.0
    if out_dir is not None:
        adir = Path(out_dir) / aid
        adir.mkdir(parents=True, exist_ok=True)

    for m in range(n_missions):
        mseed = int(np.random.default_rng([int(seed), int(params.get("seed", 0)), zlib.crc32(aid.encode()), m]).integers(2**31))
        prof = profiles[m % len(profiles)]
        fault = onset_fault(health, effects, m, duration, mseed)
        try:
            mission, truth, refined = _mission_refining(params, effects, prof, mseed, duration=duration, fs=fs,
                                                        health=health, mission_index=m, operating_hours=hours,
                                                        n_sub=n_sub, fault=fault)
        except FloatingPointError as e:
            if not rows:
                raise FloatingPointError(f"{aid}: {e}") from None
            # the unit's life ends where the plant cannot be simulated; what was simulated is kept (bags, truth)
            rows[-1]["life_ended"] = f"plant diverged in mission {m}: {e}"
            print(f"{aid}: life ended before mission {m}: {e}", file=sys.stderr, flush=True)
            break
        failed = 0.5 * (health["h_plus"] + health["h_minus"]) >= params["h_fail"]
        rec = {"mission_index": m, "seed": mseed, "profile": prof, "operating_hours": hours,
               **{k: float(v) for k, v in health.items()}, "h": 0.5 * (health["h_plus"] + health["h_minus"]),
               **truth["wear"], "failed": bool(failed)}
        if fault is not None:
            rec["fault"] = truth["effects"]["fault"]
        if refined is not None:
            rec["n_sub"] = refined  # integrated with a finer step than the default (it diverged there)
        if out_dir is not None:
            from hd_bag import write_mission

            path = Path(out_dir) / aid / bag_name(aid, m)
            k = int(sim_internal_every)
            last = failed or m == n_missions - 1
            sim = dict(truth)
            if not (k > 0 and (m % k == 0 or last)):
                sim.pop("internal")
            write_mission(path, mission, sim=sim)
            rec["has_internal"] = "internal" in sim
            rec["file"] = str(path.relative_to(out_dir))
        rows.append(rec)
        if tick is not None:
            tick()
        if failed and stop_at_failure:
            break
        health = advance_health(health, truth["wear"], params, effects, m, duration)
        hours += float(params["mission_hours"])
    return rows


#: how many times a diverging mission is re-integrated with the internal step halved before the life ends there
REFINE_STEPS = 2


def _mission_refining(params, effects, prof, mseed, *, fs: float, n_sub: int | None, **kw):
    """``simulate_mission``; where the explicit integration diverges (a stiff contact inside the backlash gap of a
    worn unit, beyond the default step's stability limit), the same mission again with the internal step halved, up
    to :data:`REFINE_STEPS` times (the seeds are unchanged, so the mission is the same one, only integrated more
    finely). Missions that do not diverge are untouched (bit for bit). Returns (mission, truth, the finer n_sub or
    None); raises the last FloatingPointError, naming the steps tried, if every step diverged."""
    from .plant import default_n_sub, simulate_mission

    base = int(n_sub) if n_sub is not None else default_n_sub(fs)
    tried = []
    for k in range(REFINE_STEPS + 1):
        ns = base * 2**k
        if k and ns > 1000:  # simulate_mission's own limit on the step count
            break
        try:
            mission, truth = simulate_mission(params, effects, prof, mseed, fs=fs, n_sub=n_sub if k == 0 else ns,
                                              **kw)
            return mission, truth, (ns if k else None)
        except FloatingPointError as e:
            tried.append(ns)
            err = e
    raise FloatingPointError(f"{err} (n_sub tried: {', '.join(map(str, tried))})")


def _life_worker(args):
    """(actuator_id, mission records, or the message of a plant that cannot simulate its first mission)."""
    params, n_missions, out_dir, kw = args
    q = _QUEUE
    tick = (lambda: q.put(1)) if q is not None else None
    try:
        return params["actuator_id"], simulate_life(params, n_missions, out_dir, tick=tick, **kw)
    except FloatingPointError as e:
        return params["actuator_id"], str(e)


_QUEUE = None


def _init_worker(q):
    global _QUEUE
    _QUEUE = q


def simulate_fleet(n_actuators: int, n_missions: int, out_dir: str | os.PathLike, *, seed: int = 0,
                   effects: EffectSet | None = None, duration: float = 20.0, fs: float = 1000.0,
                   workers: int = 1, profiles: Iterable[str] | None = None, n_sub: int | None = None,
                   stop_at_failure: bool = True, progress: bool = True,
                   sim_internal_every: int = 10,
                   overrides: Mapping[str, float] | None = None, family: str | None = None) -> dict[str, Any]:
    """Simulate ``n_actuators`` lives of up to ``n_missions`` missions into ``out_dir``.

    ``overrides`` sets actuator parameters for every unit of the population
    (e.g. ``{"mission_hours": 400}`` for shorter lives), checked like any other.
    ``family`` (``hd_sim.families``) draws each actuator's laws, gear ratio, sensors and log
    rate on top of ``effects`` (seeded by ``seed``); ``None`` or ``"default"``: today's plant
    (``fs`` for every unit). ``profiles`` default: the family's fleet profiles (inspection).

    Writes ``out_dir/<actuator_id>/<actuator_id>_mNNNN.mcap`` and
    ``out_dir/fleet_truth.json`` (ground truth per actuator: parameters, the
    health before every mission, failure mission: for scoring only). Returns
    that summary.
    """
    if n_actuators < 1 or n_missions < 1:
        raise ValueError(f"need >= 1 actuator and >= 1 mission (got {n_actuators}, {n_missions})")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    effects = effects if effects is not None else EffectSet.default()
    from .families import family_unit, get_family

    fam = get_family(family or "default")
    profiles = tuple(profiles) if profiles is not None else fam.fleet_profiles
    pop = sample_population(n_actuators, seed)
    units = [family_unit(fam.name, p, effects, seed, fs=fs if fam.name == "default" else None) for p in pop]
    pop = [u.params for u in units]
    if overrides:
        for p in pop:
            unknown = set(overrides) - set(p)
            if unknown:
                raise KeyError(f"unknown actuator parameter(s) {sorted(unknown)}; see hd_sim.params.NOMINAL")
            p.update({k: float(v) for k, v in overrides.items()})
            check_params(p)
    kw = dict(duration=duration, seed=seed, profiles=profiles, n_sub=n_sub,
              stop_at_failure=stop_at_failure, sim_internal_every=sim_internal_every)
    jobs = [(p, n_missions, str(out), dict(kw, effects=u.effects, fs=u.fs)) for p, u in zip(pop, units)]
    results: dict[str, list] = {}
    from tqdm import tqdm

    bar = tqdm(total=n_actuators * n_missions, unit="mission", desc="sim fleet", disable=not progress)
    if workers <= 1:
        for params, n_m, od, kw_u in jobs:
            try:
                results[params["actuator_id"]] = simulate_life(params, n_m, od, tick=lambda: bar.update(1), **kw_u)
            except FloatingPointError as e:
                results[params["actuator_id"]] = str(e)
    else:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        q = ctx.Manager().Queue()
        with ctx.Pool(workers, initializer=_init_worker, initargs=(q,)) as pool:
            pending = pool.map_async(_life_worker, jobs)
            while not pending.ready():
                pending.wait(0.2)
                while not q.empty():
                    bar.update(q.get())
            for aid, rows in pending.get():
                results[aid] = rows
            while not q.empty():
                bar.update(q.get())
    bar.close()
    # a unit whose plant cannot simulate even its first mission is left out, and said so (the plant failed, not
    # the unit: its parameter draw is beyond what the integrator handles)
    left_out = {a: r for a, r in results.items() if isinstance(r, str)}
    for a, msg in left_out.items():
        print(f"sim fleet: {a} left out: {msg}", file=sys.stderr, flush=True)
    keep = [(p, u) for p, u in zip(pop, units) if p["actuator_id"] not in left_out]
    if not keep:
        raise FloatingPointError(f"no actuator could be simulated: {next(iter(left_out.values()))}")
    summary = {
        "seed": seed, "duration_s": duration, "fs": fs, "effects": effects.to_json_dict(),
        **({"family": fam.name} if fam.name != "default" else {}),
        "actuators": [
            {"actuator_id": p["actuator_id"],
             **({"family": u.truth(), "unit_effects": u.effects.to_json_dict()} if fam.name != "default" else {}),
             "params": {k: v for k, v in p.items() if k != "effect_scale"},
             "effect_scale": p.get("effect_scale", {}),
             "eol_mission": next((r["mission_index"] for r in results[p["actuator_id"]] if r["failed"]), None),
             "missions": results[p["actuator_id"]],
             **({"life_ended": results[p["actuator_id"]][-1]["life_ended"]}
                if results[p["actuator_id"]] and "life_ended" in results[p["actuator_id"]][-1] else {})}
            for p, u in keep
        ],
        **({"left_out": left_out} if left_out else {}),
    }
    with open(out / "fleet_truth.json", "w") as f:
        json.dump(summary, f, indent=1, default=float)
    return summary
