"""False-alarm evaluation of the onboard detector over a directory of (healthy) mission bags.

``hdphm onboard eval PATH... [--ground K] [--model-dir DIR] [--out DIR]``

Every bag is streamed through :func:`hd_onboard.core.run_mission` exactly as
the onboard node would process it (same core, same thresholds logic). Two
threshold modes:

* self-calibrated (default, ``--ground 0``): each mission calibrates its lines
  on its own first ``warmup_s`` (what the node does before the ground has
  analysed the actuator);
* ground (``--ground K``): per actuator, the lines come from its first K
  missions (``hd_ground.thresholds.actuator_thresholds``, as the ground node
  computes them) and only the **other** missions are scored (never the
  calibration data).

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
from typing import Any, Iterable, Sequence

import numpy as np

from hd_onboard.core import CHANNELS, OnboardConfig, OnboardCore, run_mission
from hd_onboard.detector import ERROR, WARN


def collect_bags(paths: Iterable[str | os.PathLike]) -> list[str]:
    """MCAP files given directly or found (recursively) under directories, sorted; ValueError naming a missing path."""
    out: list[str] = []
    for p in paths:
        p = Path(p)
        if p.is_dir():
            out += sorted(str(f) for f in p.rglob("*.mcap"))
        elif p.is_file():
            out.append(str(p))
        else:
            raise ValueError(f"{p}: no such bag file or directory")
    if not out:
        raise ValueError(f"no .mcap bags under {', '.join(map(str, paths))}")
    return out


def _margins(res: dict, core: OnboardCore) -> dict[str, float]:
    tab = res["table"]
    out = {}
    for c, col in (("Q_red", 4), ("twist", 6)):
        e = np.abs(tab[:, col])
        e = e[np.isfinite(e)]
        out[c] = float(e.max() / core.thresholds[c].h_warn) if len(e) else math.nan
    return out


def evaluate_missions(missions: Sequence, ground: int = 0, model_dir: str | None = None,
                      config: OnboardConfig | None = None, labels: Sequence[str] | None = None) -> dict[str, Any]:
    """Score healthy :class:`hd_bag.mission.Mission` objects (see module docstring); returns the summary dict."""
    from hd_ground.thresholds import actuator_thresholds
    from hd_onboard.expected import make_expected
    from hd_twin import physics as ph

    if ground < 0 or ground > 10**5:
        raise ValueError(f"ground = {ground}: number of calibration missions per actuator must be in 0..1e5")
    labels = list(labels) if labels is not None else [f"mission {i}" for i in range(len(missions))]
    cfg = (config or OnboardConfig()).validate()
    by_act: dict[str, list[int]] = {}
    for i, m in enumerate(missions):
        by_act.setdefault(m.meta.actuator_id, []).append(i)
    rows = []
    calib = {}

    def core_for(m, thresholds=None):
        p = ph.TwinParams.from_yaml().with_meta(gear_ratio=m.meta.gear_ratio)
        exp = make_expected(model_dir, p, fs_hz=cfg.nominal_fs or 1000.0)
        return OnboardCore(exp, p, None, thresholds, cfg)

    for act, idx in by_act.items():
        idx = sorted(idx, key=lambda i: (missions[i].meta.mission_index, labels[i]))
        th = None
        if ground:
            ref = idx[:ground]
            if len(idx) <= ground:
                raise ValueError(f"actuator {act}: {len(idx)} mission(s), need more than --ground {ground} to score any")
            th = actuator_thresholds([run_mission(missions[i], core_for(missions[i])) for i in ref])
            calib[act] = {"missions": [labels[i] for i in ref], "thresholds": {c: t.to_dict() for c, t in th.items()}}
            idx = idx[ground:]
        for i in idx:
            m = missions[i]
            core = core_for(m, th)
            r = run_mission(m, core)
            ev = r["events"]
            rows.append({
                "bag": labels[i], "actuator": act, "mission_index": int(m.meta.mission_index),
                "duration_s": float(m.duration), "max_level": int(r["max_level"]),
                "n_warn": sum(1 for e in ev if e[1] == WARN), "n_error": sum(1 for e in ev if e[1] == ERROR),
                "first_flag_s": r["onset_s"], "reasons": sorted({e[2] for e in ev}),
                "margin": _margins(r, core), "threshold_source": {c: core.thresholds[c].source for c in CHANNELS},
                "twin": core.expected.kind,
            })
    hours = sum(r["duration_s"] for r in rows) / 3600.0
    n = len(rows)
    n_w = sum(1 for r in rows if r["max_level"] >= WARN)
    n_e = sum(1 for r in rows if r["max_level"] >= ERROR)
    flags = sum(r["n_warn"] + r["n_error"] for r in rows)
    return {
        "mode": f"ground thresholds from the first {ground} missions per actuator" if ground else "self-calibrated per mission",
        "n_missions": n, "hours": hours, "missions_warn_or_worse": n_w, "missions_error": n_e,
        "false_alarm_rate_per_mission": n_w / n if n else math.nan,
        "error_rate_per_mission": n_e / n if n else math.nan,
        "flags_per_hour": flags / hours if hours > 0 else math.nan,
        "calibration": calib, "missions": rows,
    }


def evaluate_bags(paths: Iterable[str | os.PathLike], ground: int = 0, model_dir: str | None = None,
                  config: OnboardConfig | None = None, progress: bool = False) -> dict[str, Any]:
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
    s = evaluate_missions(ms, ground, model_dir, config, labels)
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


def cmd_eval(args) -> int:
    import sys

    try:
        s = evaluate_bags(args.paths, ground=args.ground, model_dir=args.model_dir or None, progress=not args.quiet)
    except ValueError as e:
        print(f"hdphm onboard eval: {e}", file=sys.stderr)
        return 2
    for r in s["missions"]:
        print(f"{r['bag']}: max level {r['max_level']}, flags {r['n_warn'] + r['n_error']}, margin "
              + ", ".join(f"{c} {v:.2f}" for c, v in r["margin"].items()))
    for b in s["unreadable"]:
        print(f"unreadable: {b}", file=sys.stderr)
    print(f"{s['mode']}: {s['n_missions']} missions, {s['hours']:.3f} h scored; WARN or worse in "
          f"{s['missions_warn_or_worse']} ({100 * s['false_alarm_rate_per_mission']:.1f} %), ERROR in {s['missions_error']} "
          f"({100 * s['error_rate_per_mission']:.1f} %); {s['flags_per_hour']:.2f} flags/h; twin {s['missions'][0]['twin']}")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "onboard_eval.json").write_text(json.dumps(s, indent=1, default=float))
        plot_summary(s, out / "onboard_eval.png")
        print(f"wrote {out / 'onboard_eval.json'} and {out / 'onboard_eval.png'}")
    return 0
