"""False-alarm evaluation of the onboard detector over a directory of (healthy) mission bags.

``hdphm onboard eval PATH... [--ground K] [--model-dir DIR] [--out DIR]``

Every bag is streamed through :func:`hd_onboard.batch.run_mission` exactly as
the onboard node would process it (same core, same thresholds logic). Two
threshold modes:

* self-calibrated (default, ``--ground 0``): each mission calibrates its lines
  on its own first ``warmup_s`` (what the node does before the ground has
  analysed the actuator);
* ground (``--ground K``): per actuator, the lines and the stiffness / friction
  monitor references come from its first K missions
  (``hd_ground.references.calibrate_actuator``, as the ground node computes
  them; passed in as ``calibrate=`` by the caller, ``hdphm onboard eval``, so this
  module never imports the ground) and only the **other** missions are scored (never the calibration
  data). ``skip=K`` with self-calibration scores the same missions, for a
  like-for-like comparison.

The bags are taken as healthy: every WARN/ERROR is counted as a false alarm.
Reported: missions scored, hours scored, missions with WARN or worse, with
ERROR, flags per hour, and per mission the margin ``max |e| / h_warn`` of each
channel (below 1: no sample crossed the line). ``--out`` writes
``onboard_eval.json`` and ``onboard_eval.png``.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from hd_onboard.batch import run_mission
from hd_onboard.config import OnboardConfig
from hd_onboard.core import OnboardCore
from hd_onboard.residuals import CHANNELS
from hd_onboard.detectors.levels import ERROR, WARN


def collect_bags(paths: Iterable[str | os.PathLike]) -> list[str]:
    """MCAP files given directly or found (recursively) under directories, sorted; ValueError naming a missing path."""
    from hd_bag.files import find_bags

    return [str(p) for p in find_bags(paths, sort_key=str)]


def _margins(res: dict, core: OnboardCore) -> dict[str, float]:
    tab = res["table"]
    out = {}
    for c, col in (("Q_red", 4), ("twist", 6)):
        e = np.abs(tab[:, col])
        e = e[np.isfinite(e)]
        out[c] = float(e.max() / core.thresholds[c].h_warn) if len(e) else math.nan
    if tab.shape[1] > 8:  # stiffness: largest loss held for the persistence time / loss_warn
        from hd_onboard.calibration import persistent_peak

        sm = core.stiffness
        out["stiffness"] = float(persistent_peak(tab[:, 8], sm.persistence) / sm.loss_warn) if np.isfinite(tab[:, 8]).any() else math.nan
    if tab.shape[1] > 9:  # friction: largest excess held for the persistence time / excess_warn
        from hd_onboard.calibration import persistent_peak

        fm = core.friction
        out["friction"] = (float(persistent_peak(tab[:, 9], fm.persistence) / fm.excess_warn)
                           if np.isfinite(tab[:, 9]).any() else math.nan)
    return out


def scored(res: dict, core: OnboardCore) -> bool:
    """True when the mission gave at least one evaluated sample on some flag source (a residual channel
    past its calibration, or a monitor): the only missions whose 'no flag' means anything."""
    tab = res["table"]
    return bool(len(tab)) and bool(np.isfinite(tab[:, [4, 6] + ([8] if tab.shape[1] > 8 else [])
                                                  + ([9] if tab.shape[1] > 9 else [])]).any())


def not_scored_reason(m, cfg: OnboardConfig) -> str:
    """Why a mission gave nothing to score (the warm-up takes the twist zero, the self-calibration and the
    monitor references; a flag then needs ``persistence_s``)."""
    need = cfg.warmup_s + max(cfg.settle_s, cfg.persistence_s)
    if m.duration < cfg.warmup_s + cfg.settle_s:
        return (f"too short to calibrate and score: {m.duration:.3g} s of joint states, needs > {need:.3g} s "
                f"(warm-up {cfg.warmup_s:g} s + persistence {cfg.persistence_s:g} s); use longer missions or "
                "--ground K with calibration missions of the same actuator")
    return ("no sample evaluated after the warm-up (joint states NaN, dropouts or stamps not increasing "
            "after it; see the bag's read report)")


def evaluate_missions(missions: Sequence, ground: int = 0, model_dir: str | None = None,
                      config: OnboardConfig | None = None, labels: Sequence[str] | None = None,
                      references: bool = True, skip: int = 0, calibrate: Callable | None = None) -> dict[str, Any]:
    """Score healthy :class:`hd_bag.mission.Mission` objects (see module docstring); returns the summary dict.

    ``ground`` K > 0: per actuator, calibrate on its first K missions and score the others; ``references``
    False gives the ground's lines only (monitor references from each warm-up, the former mode).
    ``skip`` (self-calibration only): leave each actuator's first ``skip`` missions unscored.
    ``calibrate(missions, config=, model_dir=)`` -> ``{"thresholds", "references"}``: the ground's per-actuator
    calibration (``hd_ground.references.calibrate_actuator``; needed when ``ground`` > 0).
    """
    from hd_onboard.detectors.ewma import ChannelThreshold
    from hd_onboard.expected import make_expected
    from hd_twin import physics as ph

    if ground < 0 or ground > 10**5 or skip < 0 or skip > 10**5:
        raise ValueError(f"ground = {ground}, skip = {skip}: numbers of missions per actuator must be in 0..1e5")
    if ground and calibrate is None:
        raise ValueError("ground = %d needs calibrate= (the ground's calibration, "
                         "hd_ground.references.calibrate_actuator)" % ground)
    labels = list(labels) if labels is not None else [f"mission {i}" for i in range(len(missions))]
    cfg = (config or OnboardConfig()).validate()
    by_act: dict[str, list[int]] = {}
    for i, m in enumerate(missions):
        by_act.setdefault(m.meta.actuator_id, []).append(i)
    rows = []
    calib = {}

    def core_for(m, thresholds=None, refs=None):
        p = ph.TwinParams.from_yaml().with_meta(gear_ratio=m.meta.gear_ratio)
        exp = make_expected(model_dir, p, fs_hz=cfg.nominal_fs or None)
        core = OnboardCore(exp, p, None, thresholds, cfg)
        if refs:
            core.set_stiffness_reference(refs.get("stiffness"))
            core.set_friction_reference(refs.get("friction"))
        return core

    for act, idx in by_act.items():
        idx = sorted(idx, key=lambda i: (missions[i].meta.mission_index, labels[i]))
        th = refs = None
        if ground:
            ref = idx[:ground]
            if len(idx) <= ground:
                raise ValueError(f"actuator {act}: {len(idx)} mission(s), need more than --ground {ground} to score any")
            cal = calibrate([missions[i] for i in ref], config=cfg, model_dir=model_dir)
            th = {c: ChannelThreshold.from_dict(v, f"ground thresholds of {act}") for c, v in cal["thresholds"].items()}
            refs = cal["references"] if references else None
            calib[act] = {"missions": [labels[i] for i in ref], "thresholds": cal["thresholds"],
                          "references": refs or {}}
            idx = idx[ground:]
        elif skip:
            idx = idx[skip:]
        for i in idx:
            m = missions[i]
            core = core_for(m, th, refs)
            r = run_mission(m, core)
            ev = r["events"]
            in_lev, in_msg = r["input"]
            sc = scored(r, core)
            rows.append({
                "bag": labels[i], "actuator": act, "mission_index": int(m.meta.mission_index),
                "duration_s": float(m.duration), "max_level": int(r["max_level"]),
                "n_warn": sum(1 for e in ev if e[1] == WARN), "n_error": sum(1 for e in ev if e[1] == ERROR),
                "first_flag_s": r["onset_s"], "reasons": sorted({e[2] for e in ev}),
                "margin": _margins(r, core), "threshold_source": {c: core.thresholds[c].source for c in CHANNELS},
                "reference_source": {"stiffness": core.stiffness_status()["reference"],
                                     "friction": core.friction_status()["reference"]},
                "twin": core.expected.kind,
                "scored": sc, "input_level": int(in_lev),
                "input": "; ".join(v[1] for k, v in core.input_notes.items() if k != "short"),  # short: in note
                "note": "" if sc else not_scored_reason(m, cfg),
            })
    n_scored = sum(1 for r in rows if r["scored"])
    hours = sum(r["duration_s"] for r in rows if r["scored"]) / 3600.0  # missions that gave nothing are not hours scored
    n = n_scored  # rates are per scored mission
    n_w = sum(1 for r in rows if r["max_level"] >= WARN)
    n_e = sum(1 for r in rows if r["max_level"] >= ERROR)
    flags = sum(r["n_warn"] + r["n_error"] for r in rows)
    mode = ((f"ground lines + monitor references from the first {ground} missions per actuator" if references
             else f"ground lines from the first {ground} missions per actuator") if ground
            else "self-calibrated per mission" + (f" (first {skip} missions per actuator not scored)" if skip else ""))
    return {
        "mode": mode,
        "n_missions": len(rows), "n_scored": n_scored, "hours": hours, "missions_warn_or_worse": n_w, "missions_error": n_e,
        "false_alarm_rate_per_mission": n_w / n if n else math.nan,
        "error_rate_per_mission": n_e / n if n else math.nan,
        "flags_per_hour": flags / hours if hours > 0 else math.nan,
        "calibration": calib, "missions": rows,
    }


def evaluate_bags(paths: Iterable[str | os.PathLike], ground: int = 0, model_dir: str | None = None,
                  config: OnboardConfig | None = None, progress: bool = False, references: bool = True,
                  skip: int = 0, calibrate: Callable | None = None) -> dict[str, Any]:
    """:func:`evaluate_missions` on bags (files or directories); unreadable bags are listed, not fatal."""
    from hd_bag import read_mission

    bags = collect_bags(paths)
    ms, labels, bad = [], [], []
    it = bags
    if progress:
        import sys

        from tqdm import tqdm

        it = tqdm(bags, desc="read", unit="bag", file=sys.stderr)
    for b in it:
        try:
            ms.append(read_mission(b))
            labels.append(b)
        except ValueError as e:  # BagError is a ValueError naming the file
            bad.append(str(e))
    if not ms:
        raise ValueError("no readable bag: " + "; ".join(bad[:5]))
    s = evaluate_missions(ms, ground, model_dir, config, labels, references=references, skip=skip, calibrate=calibrate)
    s["unreadable"] = bad
    return s


def plot_summary(s: dict, path: str | os.PathLike) -> None:
    """Per-mission margin max|e|/h_warn of both channels (the line at 1 is the WARN line)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = s["missions"]
    fig, ax = plt.subplots(figsize=(max(6, 0.25 * len(rows) + 2), 4))
    x = np.arange(len(rows))
    for k, c in enumerate(CHANNELS):
        ax.bar(x + (k - 0.5) * 0.4, [r["margin"][c] for r in rows], 0.4, label=c)
    ax.axhline(1.0, color="r", lw=1, label="WARN line")
    ax.set_xlabel("mission (scored)")
    ax.set_ylabel("max |e| / h_warn")
    ax.set_title(f"onboard false alarms: {s['missions_warn_or_worse']}/{s['n_missions']} missions "
                 f"({s['hours']:.2f} h, {s['mode']})", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def cmd_eval(args, calibrate: Callable | None = None) -> int:
    """``hdphm onboard eval``; ``calibrate``: as in :func:`evaluate_missions` (the CLI passes the ground's)."""
    import sys

    try:
        s = evaluate_bags(args.paths, ground=args.ground, model_dir=args.model_dir or None, progress=not args.quiet,
                          calibrate=calibrate)
    except ValueError as e:
        print(f"hdphm onboard eval: {e}", file=sys.stderr)
        return 2
    for r in s["missions"]:
        if not r["scored"]:
            print(f"{r['bag']}: not scored: {r['note']}")
        else:
            print(f"{r['bag']}: max level {r['max_level']}, flags {r['n_warn'] + r['n_error']}, margin "
                  + ", ".join(f"{c} {v:.2f}" for c, v in r["margin"].items())
                  + (f", twin {r['twin']}" if r["twin"] != s["missions"][0]["twin"] else ""))
        if r["input"]:
            print(f"{r['bag']}: input: {r['input']}", file=sys.stderr)
    for b in s["unreadable"]:
        print(f"unreadable: {b}", file=sys.stderr)
    if s["n_scored"] == 0:
        print(f"hdphm onboard eval: error: no mission could be scored ({s['missions'][0]['note']})", file=sys.stderr)
        return 1
    print(f"{s['mode']}: {s['n_scored']} of {s['n_missions']} missions, {s['hours']:.3f} h scored; WARN or worse in "
          f"{s['missions_warn_or_worse']} ({100 * s['false_alarm_rate_per_mission']:.1f} %), ERROR in {s['missions_error']} "
          f"({100 * s['error_rate_per_mission']:.1f} %); {s['flags_per_hour']:.2f} flags/h; twin {s['missions'][0]['twin']}"
          + (f"; {s['n_missions'] - s['n_scored']} not scored" if s["n_scored"] < s["n_missions"] else ""))
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "onboard_eval.json").write_text(json.dumps(s, indent=1, default=float))
        plot_summary(s, out / "onboard_eval.png")
        print(f"wrote {out / 'onboard_eval.json'} and {out / 'onboard_eval.png'}")
    return 0


# ---------------------------------------------------------------------------------------------
# Detection study: delay per fault type and severity, false alarms on healthy bags
# ---------------------------------------------------------------------------------------------
#: (fault name, severity) cases of the detection study; names of hd_sim's mid-mission faults
#: (a third entry: fault onset [s], here 0: present from the mission start, the case a warm-up reference cannot see)
DEFAULT_CASES = (("lubrication_loss", 2.0), ("lubrication_loss", 3.0),
                 ("flexspline_stiffness_loss", 0.3), ("flexspline_stiffness_loss", 0.5),
                 ("flexspline_stiffness_loss", 0.7),
                 ("flexspline_stiffness_loss", 0.5, 0.0), ("flexspline_stiffness_loss", 0.7, 0.0),
                 ("lubrication_loss", 3.0, 0.0))


def first_crossings(res: dict, core: OnboardCore) -> dict[str, float | None]:
    """First time [s since the mission start] each flag source held its WARN condition for its persistence.

    Sources: ``Q_red``, ``twist`` (|EWMA| above h_warn), ``stiffness`` (loss above loss_warn), ``friction``
    (excess above excess_warn), read back from the residual table of :func:`run_mission`; None when never.
    A NaN sample ends a run here (the EWMA channels' own counters hold across NaN), so this can only be later.
    """
    from hd_onboard.detectors.levels import run_lengths

    tab = res["table"]
    if not len(tab):
        return {}
    t = tab[:, 0] - tab[0, 0]
    pers_e = core.detectors["Q_red"].persistence
    srcs = {"Q_red": (np.abs(tab[:, 4]), core.thresholds["Q_red"].h_warn, pers_e),
            "twist": (np.abs(tab[:, 6]), core.thresholds["twist"].h_warn, pers_e),
            "stiffness": (tab[:, 8], core.stiffness.loss_warn, core.stiffness.persistence)}
    if tab.shape[1] > 9:
        srcs["friction"] = (tab[:, 9], core.friction.excess_warn, core.friction.persistence)
    out = {}
    for k, (x, line, pers) in srcs.items():
        hit = np.flatnonzero(run_lengths(np.nan_to_num(x, nan=-np.inf) > line, 0) >= pers)
        out[k] = float(t[hit[0]]) if len(hit) else None
    return out


#: offset of the seeds of the healthy missions the ground calibrates on (never a fault mission's seed)
GROUND_SEED_OFFSET = 1000


def study_calibration(ground: int, actuator: int = 2, pop_seed: int = 7, seed0: int = 40, duration: float = 16.0,
                      config: OnboardConfig | None = None, *, simulate: Callable, calibrate: Callable) -> dict[str, Any]:
    """Ground calibration of the study's unit: ``ground`` healthy missions of the same unit (seeds
    ``seed0 + GROUND_SEED_OFFSET + j``, never a fault mission's), through
    :func:`hd_ground.references.calibrate_actuator`; returns its ``thresholds`` and ``references``.
    ``simulate(actuator, pop_seed, seed, duration, mission_index, fault)`` makes a mission (the
    scoring harness passes the plant's, :func:`hdphm.onboard_study.sim_mission`: estimators never
    import the simulator); ``calibrate``: the ground's calibration, as in :func:`evaluate_missions`."""
    ms = [simulate(actuator, pop_seed, seed0 + GROUND_SEED_OFFSET + j, duration, j) for j in range(ground)]
    cal = calibrate(ms, config=config)
    return {"seeds": [seed0 + GROUND_SEED_OFFSET + j for j in range(ground)], "thresholds": cal["thresholds"],
            "references": cal["references"]}


def detection_study(cases=DEFAULT_CASES, n: int = 6, actuator: int = 2, pop_seed: int = 7, seed0: int = 40,
                    duration: float = 16.0, config: OnboardConfig | None = None, progress: bool = False,
                    ground: int = 0, missions: dict | None = None, *, simulate: Callable,
                    calibrate: Callable | None = None) -> dict[str, Any]:
    """Detection delay of the onboard core (physics stand-in) on simulated faults.

    Mission ``k`` of a case: unit ``actuator`` of the ``pop_seed`` population, seed ``seed0 + k``,
    profile inspection, fault onset ``8 + 0.5 k`` s inside the simulator kernel (50 ms ramp), or the
    case's third entry [s] (0: present from the first sample). ``ground`` 0: self-calibrated lines and
    warm-up references; K > 0: lines and monitor references from K healthy missions of the same unit
    (:func:`study_calibration`; never the fault missions). The simulator is the scoring harness only:
    the core sees the contract signals. A flag before the onset counts as a false alarm of that mission
    (delay not scored). ``missions``: a dict reused across calls (simulated fault missions cached by
    case and seed, so both modes score the same missions). Returns per case the rows ``(seed, onset,
    first flag [s] or None, delay [s] or None, reasons, first crossing per source)`` and a summary
    (detected, missed, early, median / max delay). ``simulate``, ``calibrate`` (needed when ``ground`` > 0):
    as in :func:`study_calibration`.
    """
    from hd_onboard.detectors.ewma import ChannelThreshold

    cfg = (config or OnboardConfig()).validate()
    cache = missions if missions is not None else {}
    cal = None
    if ground:
        if calibrate is None:
            raise ValueError(f"ground = {ground} needs calibrate= (hd_ground.references.calibrate_actuator)")
        cal = study_calibration(ground, actuator, pop_seed, seed0, duration, cfg, simulate=simulate, calibrate=calibrate)
        th = {c: ChannelThreshold.from_dict(v, "study ground thresholds") for c, v in cal["thresholds"].items()}
    out = []
    it = [(c, k) for c in cases for k in range(n)]
    if progress:
        import sys

        from tqdm import tqdm

        it = tqdm(it, desc="fault missions" + (f" (ground {ground})" if ground else " (self-calibrated)"),
                  unit="mission", file=sys.stderr)
    rows: dict[tuple, list] = {tuple(c): [] for c in cases}
    for c, k in it:
        name, sev = c[0], c[1]
        t_on, seed = (float(c[2]) if len(c) > 2 else 8.0 + 0.5 * k), seed0 + k
        key = (actuator, pop_seed, seed, name, float(sev), t_on, duration)
        if key not in cache:
            cache[key] = simulate(actuator, pop_seed, seed, duration, k,
                                      {"name": name, "severity": float(sev), "t_onset": t_on})
        m = cache[key]
        core = OnboardCore(gear_ratio=m.meta.gear_ratio, config=cfg, thresholds=th if cal else None)
        if cal:
            core.set_stiffness_reference(cal["references"].get("stiffness"))
            core.set_friction_reference(cal["references"].get("friction"))
        r = run_mission(m, core)
        on = r["onset_s"]
        why = r["events"][0][2] if r["events"] else ""
        rows[tuple(c)].append((seed, t_on, on, None if on is None or on < t_on else on - t_on, why,
                               first_crossings(r, r["core"])))
    for c, rr in rows.items():
        name, sev = c[0], c[1]
        d = [x[3] for x in rr if x[3] is not None]
        out.append({"fault": name, "severity": sev, "onset": "mid-mission" if len(c) < 3 else f"{c[2]:g} s",
                    "n": len(rr), "detected": len(d),
                    "early": sum(1 for x in rr if x[2] is not None and x[2] < x[1]),
                    "missed": sum(1 for x in rr if x[2] is None),
                    "delay_median_s": float(np.median(d)) if d else math.nan,
                    "delay_max_s": float(np.max(d)) if d else math.nan, "rows": rr,
                    # per source: missions whose source crossed after the onset / before it
                    "by_source": {s: {"after_onset": sum(1 for x in rr if x[5].get(s) is not None and x[5][s] >= x[1]),
                                      "before_onset": sum(1 for x in rr if x[5].get(s) is not None and x[5][s] < x[1])}
                                  for s in ("Q_red", "twist", "stiffness", "friction")}})
    return {"actuator": actuator, "pop_seed": pop_seed, "seed0": seed0, "duration_s": duration, "cases": out,
            "mode": f"ground ({ground} healthy missions of the unit)" if ground else "self-calibrated", "calibration": cal}


def plot_study(study: dict, fa: dict | None, path: str | os.PathLike) -> None:
    """PNG: detection delay vs severity per fault type (misses at the top), false alarms in the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def panel(c):
        return c["fault"] + ("" if c.get("onset", "mid-mission") == "mid-mission" else f", onset {c['onset']}")

    faults = sorted({panel(c) for c in study["cases"]})
    fig, axes = plt.subplots(1, len(faults), figsize=(4.2 * len(faults), 4), squeeze=False)
    for ax, f in zip(axes[0], faults):
        cs = [c for c in study["cases"] if panel(c) == f]
        top = max([x[3] for c in cs for x in c["rows"] if x[3] is not None] + [1.0]) * 1.3
        for c in cs:
            d = [x[3] for x in c["rows"] if x[3] is not None]
            ax.scatter([c["severity"]] * len(d), d, color="C0", s=18)
            if c["missed"] or c["early"]:
                ax.scatter([c["severity"]], [top], marker="x", color="r", s=40)
                ax.annotate(f"{c['missed']} missed, {c['early']} early", (c["severity"], top), fontsize=7,
                            textcoords="offset points", xytext=(4, -10))
        ax.set_xlabel("severity")
        ax.set_ylabel("delay after onset [s]")
        ax.set_title(f, fontsize=9)
        ax.set_ylim(0, top * 1.1)
    t = f"onboard detection delay ({study.get('mode', 'self-calibrated')}, physics stand-in)"
    if fa:
        t += f"; false alarms {fa['missions_warn_or_worse']}/{fa['n_missions']} healthy missions"
    fig.suptitle(t, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def study_table(study: dict, fa: dict | None = None) -> str:
    """Markdown table of a :func:`detection_study` (and a false-alarm summary)."""
    lines = [f"{study.get('mode', 'self-calibrated')}:",
             "| fault | severity | onset | detected | missed | flagged before onset | median delay [s] | max delay [s] | "
             "by source after onset (before) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for c in study["cases"]:
        bs = c.get("by_source", {})
        src = ", ".join(f"{k} {v['after_onset']} ({v['before_onset']})" for k, v in bs.items())
        lines.append(f"| {c['fault']} | {c['severity']:g} | {c.get('onset', 'mid-mission')} | {c['detected']}/{c['n']} | "
                     f"{c['missed']} | {c['early']} | "
                     f"{c['delay_median_s']:.2f} | {c['delay_max_s']:.2f} | {src} |")
    if fa:
        lines.append(f"\nfalse alarms ({fa['mode']}): WARN or worse in {fa['missions_warn_or_worse']}/{fa['n_missions']} "
                     f"healthy missions, ERROR in {fa['missions_error']}; reasons: "
                     + ", ".join(sorted({x for r in fa["missions"] for x in r["reasons"]})) )
    return "\n".join(lines)


def run_study(a, simulate: Callable, calibrate: Callable | None = None) -> int:
    """Run the study for parsed :func:`add_study_args` options; print the table, write JSON + PNG.
    ``simulate``, ``calibrate``: as in :func:`study_calibration` (``hdphm onboard study`` passes the plant's
    and the ground's)."""
    import sys

    kw = {}
    for kv in a.set:
        k, _, v = kv.partition("=")
        if k not in OnboardConfig.__dataclass_fields__:
            print(f"unknown onboard parameter {k!r}", file=sys.stderr)
            return 2
        kw[k] = float(v)
    ground = int(getattr(a, "ground", 0) or 0)
    try:
        cfg = OnboardConfig(**kw).validate()
        if not 1 <= a.n <= 1000:
            raise ValueError(f"--n {a.n}: 1..1000 missions per case")
        if not 0 <= ground <= 100:
            raise ValueError(f"--ground {ground}: 0..100 calibration missions")
        fa = evaluate_bags(a.healthy, config=cfg, progress=True, skip=ground) if a.healthy else None
        cache: dict = {}
        st = detection_study(n=a.n, actuator=a.actuator, pop_seed=a.pop_seed, seed0=a.seed0, config=cfg, progress=True,
                             missions=cache, simulate=simulate)
        fa_g = st_g = None
        if ground:
            fa_g = (evaluate_bags(a.healthy, ground=ground, config=cfg, progress=True, calibrate=calibrate)
                    if a.healthy else None)
            st_g = detection_study(n=a.n, actuator=a.actuator, pop_seed=a.pop_seed, seed0=a.seed0, config=cfg,
                                   progress=True, ground=ground, missions=cache, simulate=simulate, calibrate=calibrate)
    except ValueError as e:
        print(f"onboard study: {e}", file=sys.stderr)
        return 2
    print(study_table(st, fa))
    if st_g is not None:
        print()
        print(study_table(st_g, fa_g))
    if a.out:
        out = Path(a.out)
        out.mkdir(parents=True, exist_ok=True)
        doc = {"study": st, "false_alarms": fa, "config": kw}
        if st_g is not None:
            doc.update(ground=ground, study_ground=st_g, false_alarms_ground=fa_g)
        (out / "detection_study.json").write_text(json.dumps(doc, indent=1, default=float))
        plot_study(st, fa, out / "detection_study.png")
        wrote = [out / "detection_study.json", out / "detection_study.png"]
        if st_g is not None:
            plot_study(st_g, fa_g, out / "detection_study_ground.png")
            wrote.append(out / "detection_study_ground.png")
        print("wrote " + ", ".join(map(str, wrote)))
    return 0
