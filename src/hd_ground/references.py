"""Per-actuator ground calibration of the onboard monitors from archived healthy missions (pure numpy).

The onboard core learns its stiffness and friction references on each
mission's first ``warmup_s`` seconds when nobody gave it better ones: a fault
already present at mission start is then learnt as "healthy" and a warm-up
that does not load the gear (or move it both ways) defines no law at all.
The ground has the actuator's archived early-life missions; here it fits, per
actuator, on **all** their samples:

* the residual lines (``hd_ground.thresholds.actuator_thresholds``, with the
  onboard configuration's EWMA time constant, persistence and minimum lines);
* the healthy torsion law ``twist = a + b tanh(omega_m/eps) + g(Q)``
  (:func:`hd_onboard.detectors.stiffness.fit_stiffness_reference`, the function the
  onboard warm-up uses; one offset per mission: encoders need not share a
  zero across missions);
* the healthy friction mismatch ``r_Q = a + b tanh(omega_m/eps)``
  (:func:`hd_onboard.detectors.friction.fit_friction_reference`, one offset per
  mission), on the output-torque residual of the same twin (parameters and
  model) the onboard node will run, with ``scale = N T_C`` of those parameters.

The missions are streamed through :func:`hd_onboard.batch.run_mission` exactly
as onboard (same conditioning: out-of-order stamps, NaN, dropouts), so the
residuals are the ones the monitors will see. Only contract signals are used:
``/sim`` is never read.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

#: ``source`` of every ground-made reference (the onboard status reports it as ``reference``)
GROUND_SOURCE = "ground"


def _aligned(mission, table: np.ndarray) -> np.ndarray:
    """Indices into the mission's samples of the rows of a residual table (rows of accepted samples)."""
    n = len(table)
    if n == mission.n:
        return np.arange(n)
    st = mission.t0_ns + np.round(mission.t * 1e9).astype(np.int64)
    ts = np.round(table[:, 0] * 1e9).astype(np.int64)
    idx = np.clip(np.searchsorted(st, ts - 500), 0, mission.n - 1)  # float stamps: nearest within 0.5 us
    return idx


def reference_samples(missions: Sequence, results: Sequence[dict], params) -> dict[str, np.ndarray]:
    """Pooled monitor inputs of healthy missions: ``twist_raw`` [rad] = theta_f - theta_m/N, ``Q`` [N*m]
    (measured Q_red, else the twin's expected one), ``omega_m`` [rad/s], ``r_Q`` [N*m] (output-torque residual,
    NaN where not evaluated or Q_red not measured) and ``group`` (mission number) per sample.

    ``results``: :func:`hd_onboard.batch.run_mission` of each mission (their residual tables give Q_hat and r_Q).
    Samples with a non-finite joint state are NaN (left out by the fits).
    """
    cols: dict[str, list] = {k: [] for k in ("twist_raw", "Q", "omega_m", "r_Q", "group")}
    for k, (m, r) in enumerate(zip(missions, results)):
        tab = r["table"]
        if not len(tab):
            continue
        i = _aligned(m, tab)
        N = float(m.meta.gear_ratio) if np.isfinite(m.meta.gear_ratio) and m.meta.gear_ratio > 0 else params.N
        tm, tf, wm = m.theta_m[i], m.theta_f[i], m.omega_m[i]
        ok = np.isfinite(tm) & np.isfinite(tf) & np.isfinite(wm) & np.isfinite(m.tau_m[i])
        Q = np.where(np.isfinite(tab[:, 1]), tab[:, 1], tab[:, 2])
        cols["twist_raw"].append(np.where(ok, tf - tm / N, np.nan))
        cols["Q"].append(np.where(ok, Q, np.nan))
        cols["omega_m"].append(wm)
        cols["r_Q"].append(np.where(ok, tab[:, 3], np.nan))
        cols["group"].append(np.full(len(tab), k))
    return {k: (np.concatenate(v) if v else np.empty(0)) for k, v in cols.items()}


def actuator_references(missions: Sequence, results: Sequence[dict], params, config=None) -> dict[str, dict]:
    """``{"stiffness": StiffnessReference dict, "friction": FrictionReference dict}`` of one actuator
    (a key is absent when the archive does not define that law: no load variation, no measured
    Q_red, no motion in both directions). ``params``: the twin parameters the onboard core will use
    (``eps_omega``, ``N T_C`` for the friction scale); ``config``: :class:`hd_onboard.config.OnboardConfig`.
    """
    from hd_onboard.config import OnboardConfig
    from hd_onboard.detectors.friction import fit_friction_reference
    from hd_onboard.detectors.stiffness import fit_stiffness_reference

    cfg = config or OnboardConfig()
    s = reference_samples(missions, results, params)
    out: dict[str, dict] = {}
    if len(s["Q"]):
        st = fit_stiffness_reference(s["twist_raw"], s["Q"], s["omega_m"], cfg.stiff_eps_omega,
                                     source=GROUND_SOURCE, group=s["group"])
        if st is not None:
            out["stiffness"] = st.to_dict()
        fr = fit_friction_reference(s["r_Q"], s["omega_m"], params.eps_omega, params.N * params.T_C,
                                    min_var_u=cfg.fric_min_var_u, source=GROUND_SOURCE, group=s["group"])
        if fr is not None:
            out["friction"] = fr.to_dict()
    return out


def calibrate_actuator(missions: Sequence, params=None, config=None, model_dir: str | None = None,
                       log=None) -> dict[str, Any]:
    """Ground calibration of one actuator from its healthy missions (each a :class:`hd_bag.mission.Mission`).

    Streams each mission through an onboard core with ``params`` (default: the twin's defaults) and the
    twin of ``model_dir`` (None/"": physics stand-in), then returns ``thresholds`` (channel -> dict, the
    lines of :func:`hd_ground.thresholds.actuator_thresholds` with the onboard config's EWMA time constant,
    persistence and minimum lines), ``references`` (:func:`actuator_references`) and ``results`` (the
    batch onboard results, for reports). Raises ValueError with no mission.
    """
    from hd_ground.thresholds import actuator_thresholds
    from hd_onboard.batch import run_mission
    from hd_onboard.config import OnboardConfig
    from hd_onboard.core import OnboardCore
    from hd_onboard.expected import make_expected
    from hd_twin import physics as ph

    if not missions:
        raise ValueError("ground calibration: no healthy mission for this actuator")
    cfg = (config or OnboardConfig()).validate()
    params = params or ph.TwinParams.from_yaml()
    results = []
    for m in missions:
        p = params.with_meta(gear_ratio=m.meta.gear_ratio) if np.isfinite(m.meta.gear_ratio) else params
        exp = make_expected(model_dir or None, p, fs_hz=cfg.nominal_fs or 1000.0, **({"log": log} if log else {}))
        results.append(run_mission(m, OnboardCore(exp, p, None, None, cfg)))
    th = actuator_thresholds(results, ewma_tau_s=cfg.ewma_tau_s, persistence_s=cfg.persistence_s,
                             warn_margin=cfg.warn_margin, error_margin=cfg.error_margin,
                             min_h_warn=cfg.default_h_warn, min_h_error=cfg.default_h_error)
    p0 = params.with_meta(gear_ratio=missions[0].meta.gear_ratio) if np.isfinite(missions[0].meta.gear_ratio) else params
    return {"thresholds": {c: t.to_dict() for c, t in th.items()},
            "references": actuator_references(missions, results, p0, cfg),
            "results": results}
