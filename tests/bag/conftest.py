"""Shared builders for the bag tests: small synthetic missions, no simulator."""

from __future__ import annotations

import numpy as np
import pytest

from hd_bag import Mission, MissionMeta

T0_NS = 1_700_000_000_000_000_000


def make_mission(n: int = 2000, rate: float = 1000.0, seed: int = 0, **meta_kw) -> Mission:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    meta = dict(actuator_id="EMA-0007", mission_index=42, operating_hours=1234.5, gear_ratio=100.0,
                torque_constant=0.12, source="simulation", extra={"seed": "7"})
    meta.update(meta_kw)
    theta_f = 0.3 * np.sin(2 * np.pi * 0.5 * t)
    return Mission(meta=MissionMeta(**meta), t=t, theta_m=100 * theta_f + 1e-3 * rng.normal(size=n),
                   theta_f=theta_f, omega_m=100 * np.gradient(theta_f, t), omega_f=np.gradient(theta_f, t),
                   tau_m=rng.normal(size=n), Q_red=50 * rng.normal(size=n), t_cmd=t[::10],
                   theta_ref=theta_f[::10], temperatures={"gearbox": (t[::100], 20 + t[::100]),
                                                          "motor_winding": (t[::100], 40 + t[::100])},
                   t0_ns=T0_NS)


@pytest.fixture
def mission() -> Mission:
    return make_mission()
