"""Small synthetic missions for the twin's unit tests (no simulator needed).

A flap driven sinusoidally against an aerodynamic spring; the motor side is
built from the twin's own quasi-static physics (stiffness, Coulomb + viscous
friction, inertia), plus sensor noise. Enough to exercise every code path in
seconds; the simulator's bags are used where the conftest fixture exists.
"""

from __future__ import annotations

import numpy as np

from hd_bag.mission import Mission, MissionMeta
from hd_twin.physics import TwinParams


def synth_mission(actuator: str = "EMA-T1", index: int = 0, fs: float = 200.0, duration: float = 6.0,
                  amp: float = 0.2, freq: float = 0.7, K_aero: float = 300.0, temp: float = 25.0,
                  seed: int = 0, p: TwinParams | None = None) -> Mission:
    p = p or TwinParams()
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration * fs)) / fs
    w = 2 * np.pi * freq
    ph0 = rng.uniform(0, 2 * np.pi)
    th_f = amp * np.sin(w * t + ph0) + 0.3 * amp * np.sin(2.7 * w * t)
    om_f = amp * w * np.cos(w * t + ph0) + 0.3 * amp * 2.7 * w * np.cos(2.7 * w * t)
    al_f = -amp * w**2 * np.sin(w * t + ph0) - 0.3 * amp * (2.7 * w) ** 2 * np.sin(2.7 * w * t)
    Q = K_aero * th_f + 0.05 * al_f + 2.0 * om_f
    twist = Q / p.K_out
    th_m = p.N * (th_f - twist)
    om_m = np.gradient(th_m, t)
    al_m = np.gradient(om_m, t)
    fr = p.T_C * np.tanh(om_m / p.eps_omega) + p.b_visc * om_m
    tau = (Q + p.J_CS * al_f) / p.N + fr + p.J_in * al_m
    temps = {"gearbox": (t[:: int(fs)].copy(), np.full(len(t[:: int(fs)]), temp))}
    meta = MissionMeta(actuator_id=actuator, mission_index=index, operating_hours=float(index),
                       gear_ratio=p.N, torque_constant=p.k_t)
    m = Mission(meta=meta, t=t, theta_m=th_m, theta_f=th_f + rng.normal(0, 1e-6, len(t)),
                omega_m=om_m + rng.normal(0, 0.01, len(t)), omega_f=om_f, tau_m=tau + rng.normal(0, 1e-3, len(t)),
                Q_red=Q + rng.normal(0, 0.2, len(t)), t_cmd=t.copy(), theta_ref=th_f.copy(), temperatures=temps)
    m.report.path = f"synthetic/{actuator}/mission{index}"
    return m


def synth_fleet(n_act: int = 4, per_act: int = 2, **kw) -> list[Mission]:
    return [synth_mission(f"EMA-T{a}", i, seed=10 * a + i, K_aero=200 + 50 * a, **kw)
            for a in range(n_act) for i in range(per_act)]


def tiny_twin_with_and_without(tmp_path, key: str, entry: dict, fleet: list[Mission] | None = None):
    """A tiny twin (1 epoch, no physics path) trained on ``fleet`` (default ``synth_fleet(2, 2, duration=2.0)``) with
    the config entry ``key`` = ``entry`` (``TrainConfig`` field of the same name), and a copy of it whose
    config.json lacks the entry: the same network as every earlier model reads it. Returns (model dir, copy dir);
    asserts that training wrote the entry."""
    import json
    import shutil

    from hd_twin.train import TrainConfig, train_twin

    new, old = tmp_path / "m", tmp_path / "old"
    train_twin(fleet if fleet is not None else synth_fleet(2, 2, duration=2.0), new, TrainConfig.from_preset(
        "tiny", epochs=1, physics_path="none", plots=False, **{key: entry}), progress=False)
    cfg = json.loads((new / "config.json").read_text())
    assert cfg[key] == entry
    shutil.copytree(new, old)
    del cfg[key]
    (old / "config.json").write_text(json.dumps(cfg))
    return new, old
