"""A small run folder in the demo's layout, built from real writers where they are cheap."""

from __future__ import annotations

import json

import numpy as np
import pytest


@pytest.fixture(scope="session")
def demo_like_run(tmp_path_factory):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    root = tmp_path_factory.mktemp("run")
    (root / "fleet" / "EMA-A").mkdir(parents=True)
    (root / "fleet" / "EMA-B").mkdir(parents=True)
    eol = 40
    (root / "fleet" / "fleet_truth.json").write_text(json.dumps({"actuators": [
        {"actuator_id": "EMA-A", "eol_mission": 55, "missions": [{}] * 55},
        {"actuator_id": "EMA-B", "eol_mission": eol, "missions": [{}] * eol}]}))
    t = np.arange(5, eol, 1.0)
    true = eol - t
    rh = {"unit": "EMA-B", "time_unit": "missions", "t": t.tolist(), "z": (0.01 * t + 0.02).tolist(),
          "state_mean": [[v] for v in (1e-6 * t).tolist()], "rul_t": t.tolist(), "p50": (true * 1.05).tolist(),
          "p5": (true * 0.7).tolist(), "p95": (true * 1.4).tolist(), "mean": true.tolist(), "threshold": 1.0}
    (root / "rul_history_EMA-B.json").write_text(json.dumps(rh))
    (root / "report.json").write_text(json.dumps({
        "held_out_actuator": "EMA-B", "training_actuators": ["EMA-A"], "wall_s": 12.0,
        "stack": {"health": {"EMA-B": {"h_mean": 3e-5, "rul_p5": 2.0, "rul_p50": 4.0, "rul_p95": 7.0, "risk": 0.3}}},
        "rul_score": {"eol_mission": eol, "coverage_p5_p95": 0.9, "cra": 0.6}}))
    (root / "stack_summary.json").write_text(json.dumps({
        "flags": [{"actuator": "EMA-B", "stamp_s": 12.5, "level": 1, "reason": "twist EWMA above h_warn"},
                  {"actuator": "EMA-B", "stamp_s": 30.0, "level": 2, "reason": "friction excess"}],
        "health_history": {"EMA-B": [{"mission_index": float(i), "h_mean": 1e-6 * i} for i in range(eol)]},
        "health": {"EMA-B": {"h_mean": 3e-5, "rul_p50": 4.0}}}))
    tw = root / "twin"
    tw.mkdir()
    (tw / "config.json").write_text("{}")
    (tw / "metrics.json").write_text(json.dumps({"validation": {"nrmse_pct": 1.2, "r2": 0.995}}))
    fig, ax = plt.subplots(figsize=(4, 3))
    ax.plot(np.sin(np.linspace(0, 6, 100)))
    fig.savefig(tw / "fig4_q_red.png", dpi=60)
    plt.close(fig)
    dd = root / "discover"
    dd.mkdir()
    (dd / "report.json").write_text(json.dumps({"effects": [{"name": "stribeck_friction", "signal": "tau_m",
                                                             "explained": 0.41, "params": {"v_s": 0.8}}],
                                                "comparisons": {"tau_m": {"before": 0.2, "after": 0.1}}}))
    return root
