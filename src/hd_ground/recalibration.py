"""Recalibration of the twin's physical parameters on recorded missions (least squares, pure numpy).

The twin's quasi-static torque balance (``hd_twin.physics.quasi_static_Q_red``,
PHYSICS.md 1.1-1.2 with the input friction of 2.5) is linear in the
parameters that drift in service, once the measured output torque is moved
to the known side::

    tau_m - Q'/N = T_C sgn_eps(omega_m) + b_visc omega_m + J_in theta_m''
                   + (mu_c/mu_g) |Q'|/N sgn(omega_m) ,   Q' = Q_red + J_CS theta_f''

(motor torque = Coulomb + viscous + inertia + reflected output torque with
the mesh sliding loss). Stacking the samples of the healthy missions of an
actuator gives an ordinary least-squares problem for (T_C, b_visc, J_in,
mu_c/mu_g). Accelerations come from ``hd_twin.data.derivative`` per
gap-free segment; NaN samples and the samples of near-zero speed (where the
regularised sign is ill-defined) are left out. Only contract signals are
used: recalibration never reads ``/sim``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hd_twin import physics as ph
from hd_twin.data import derivative, segment_bounds

FIT_NAMES = ("T_C", "b_visc", "J_in", "mesh_loss_ratio")


def regression_rows(mission, params: ph.TwinParams, min_speed: float | None = None):
    """(A, y) of one mission for the friction/inertia least squares (rows = usable samples)."""
    p = params.with_meta(gear_ratio=mission.meta.gear_ratio)
    dt = 1.0 / mission.fs
    am = np.full(mission.n, np.nan)
    af = np.full(mission.n, np.nan)
    for a, b in segment_bounds(mission.segment):
        if b - a < 16:
            continue
        wm, wf = mission.omega_m[a:b], mission.omega_f[a:b]
        if not (np.isfinite(wm).all() and np.isfinite(wf).all()):
            continue
        am[a:b] = derivative(wm, dt)
        af[a:b] = derivative(wf, dt)
    w = mission.omega_m
    Qp = mission.Q_red + p.J_CS * af
    s = ph.sgn_eps(np, w, p.eps_omega)
    y = mission.tau_m - Qp / p.N
    A = np.column_stack([s, w, am, np.abs(Qp) / p.N * np.sign(w)])
    vmin = 5 * p.eps_omega if min_speed is None else min_speed
    ok = np.isfinite(A).all(axis=1) & np.isfinite(y) & (np.abs(w) > vmin)
    return A[ok], y[ok]


def recalibrate(missions, params: ph.TwinParams, min_rows: int = 2000) -> tuple[ph.TwinParams, dict]:
    """Least-squares update of T_C, b_visc, J_rotor (J_in - J_WG) and mu_c; returns (params, report).

    Parameters whose estimate falls outside the physical bounds keep their
    old value (and the report says so); raises ValueError when the missions
    do not excite the regressors (fewer than ``min_rows`` usable samples or a
    rank-deficient design).
    """
    As, ys = [], []
    for m in missions:
        if not np.isfinite(m.Q_red).any():
            continue
        A, y = regression_rows(m, params)
        As.append(A)
        ys.append(y)
    if not As or sum(len(a) for a in As) < min_rows:
        raise ValueError(f"recalibration: too few usable samples with measured Q_red and motion "
                         f"({sum(len(a) for a in As)} < {min_rows})")
    A = np.concatenate(As)
    y = np.concatenate(ys)
    scale = np.sqrt(np.mean(A**2, axis=0))
    scale[scale == 0] = 1.0
    coef, res, rank, sv = np.linalg.lstsq(A / scale, y, rcond=None)
    if rank < A.shape[1]:
        raise ValueError(f"recalibration: design matrix rank {rank} < {A.shape[1]} (missions do not excite {FIT_NAMES})")
    coef = coef / scale
    resid = y - A @ coef
    sigma2 = float(resid @ resid) / max(len(y) - A.shape[1], 1)
    try:
        cov = sigma2 * np.linalg.inv((A.T @ A))
        se = np.sqrt(np.maximum(np.diag(cov), 0))
    except np.linalg.LinAlgError:
        se = np.full(A.shape[1], np.nan)
    T_C, b, J_in, k = (float(c) for c in coef)
    new = dataclasses.replace(params)
    kept = []
    cand = {"T_C": T_C, "b_visc": b, "J_rotor": J_in - params.J_WG, "mu_c": k * params.mu_g}
    for name, v in cand.items():
        trial = dataclasses.replace(new, **{name: v})
        try:
            trial.validate(f"recalibrated {name}")
            if name == "T_C" and trial.T_S < v:
                trial.T_S = v * (params.T_S / params.T_C if params.T_C > 0 else 1.3)
            new = trial
        except ValueError:
            kept.append(name)
    new.source = "recalibrated by hd_ground (least squares on healthy missions)"
    report = {"estimates": dict(zip(FIT_NAMES, coef.tolist())), "std_errors": dict(zip(FIT_NAMES, se.tolist())),
              "rows": int(len(y)), "rms_before": float(np.sqrt(np.mean((y - A @ np.array([params.T_C, params.b_visc, params.J_in, params.mu_c / params.mu_g]))**2))),
              "rms_after": float(np.sqrt(np.mean(resid**2))), "kept_old": kept}
    return new.validate("recalibrated twin parameters"), report
