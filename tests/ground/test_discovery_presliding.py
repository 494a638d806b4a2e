"""The friction transition law is identified, not assumed (issue 10): tanh(omega_m / eps) or a rate-independent
pre-sliding (Dahl / LuGre bristle) state of the motor angle, chosen by the cross-validated error.

Synthetic plants written here (numpy only, no hd_sim): the same motion with a Dahl-state friction and with a
tanh friction; discovery must pick the law that generated the data, identify the pre-sliding distance, and
hand the twin only terms it can evaluate.
"""

import numpy as np
import pytest

from hd_ground.discovery.core import discover_signal, static_term, uses_state
from hd_ground.discovery.data import Dataset
from hd_ground.discovery.library import state_var
from hd_twin.identify import IdentifyError, presliding_state

from .synthetic import dataset

FS, T_BAG, N_BAGS = 500.0, 8.0, 4
J, T_C, B, D_TRUE, EPS_TRUE = 0.01, 1.0, 0.01, 2e-3, 0.5


def test_presliding_state_is_rate_independent_and_restarts_per_segment():
    rng = np.random.default_rng(1)
    x = np.cumsum(rng.normal(size=400) * 1e-3)
    s1 = presliding_state(x, 2e-3)
    # the same path, every step cut into three monotone sub-steps (a 3x faster log): same state at the same points
    fine = np.concatenate([np.linspace(a, b, 4)[:-1] for a, b in zip(x[:-1], x[1:])] + [x[-1:]])
    s3 = presliding_state(fine, 2e-3)
    assert np.allclose(s3[::3], s1, atol=1e-12)
    assert np.all(np.abs(s1) <= 1.0)
    # a long monotone travel saturates at the direction; a new segment starts with no history
    ramp = np.r_[np.linspace(0, 0.1, 50), np.linspace(0.1, 0.0, 50)]
    s = presliding_state(ramp, 2e-3, segment=np.r_[np.zeros(50, int), np.ones(50, int)])
    assert s[49] == pytest.approx(1.0, abs=1e-6) and s[50] == 0.0 and s[-1] == pytest.approx(-1.0, abs=1e-6)
    with pytest.raises(IdentifyError, match="distance"):
        presliding_state(x, 0.0)


def _plant(law: str, seed: int = 0) -> tuple[Dataset, np.ndarray]:
    """Four bags: a slow sweep plus a small fast dither (reversals with short strokes), friction by ``law``."""
    rng = np.random.default_rng(seed)
    n = int(FS * T_BAG)
    t = np.arange(n) / FS
    cols = {k: [] for k in ("theta_m", "omega_m", "alpha_m", "tau_m")}
    for i in range(N_BAGS):
        a1, f1, a2, f2 = 6.0 + 2 * i, 0.2 + 0.05 * i, 0.004 * (1 + i % 2), 4.0 + i
        th = a1 * np.sin(2 * np.pi * f1 * t) + a2 * np.sin(2 * np.pi * f2 * t)
        w = a1 * 2 * np.pi * f1 * np.cos(2 * np.pi * f1 * t) + a2 * 2 * np.pi * f2 * np.cos(2 * np.pi * f2 * t)
        al = -a1 * (2 * np.pi * f1) ** 2 * np.sin(2 * np.pi * f1 * t) - a2 * (2 * np.pi * f2) ** 2 * np.sin(2 * np.pi * f2 * t)
        fr = presliding_state(th, D_TRUE) if law == "dahl" else np.tanh(w / EPS_TRUE)
        tau = J * al + T_C * fr + B * w + rng.normal(0, 0.02, n)
        for k, v in (("theta_m", th), ("omega_m", w + rng.normal(0, 0.005, n)), ("alpha_m", al), ("tau_m", tau)):
            cols[k].append(v)
    return dataset(cols, t, ratio=100.0)


@pytest.mark.parametrize("law", ["dahl", "tanh"])
def test_transition_law_is_identified_from_the_data(law):
    ds, ho = _plant(law)
    r = discover_signal(ds, "tau_m", ho)
    bp = r.baseline_params
    if law == "dahl":
        assert "presliding_distance" in bp, r.statements
        d, sd = bp["presliding_distance"], bp["presliding_distance_sd"]
        assert abs(d - D_TRUE) < 0.2 * D_TRUE and 0 < sd < 0.5 * d, (d, sd)
        assert bp["T_C"] == pytest.approx(T_C, rel=0.05)
    else:
        assert "presliding_distance" not in bp, r.statements
        assert bp["eps_omega"] == pytest.approx(EPS_TRUE, rel=0.2)
    # either way the right law leaves the noise floor and nothing to discover
    assert r.error_before["rmse"] < 0.025 and r.effects == [], (r.error_before, [e["name"] for e in r.effects])


def test_terms_on_the_presliding_state_reach_the_twin_in_static_form():
    z = {"op": "var", "var": state_var("theta_m", 1e-3)}
    term = {"name": "stribeck_friction", "signal": "tau_m", "variable": "omega_m", "order": None, "form": "f",
            "coef": [1.0, 0.5], "basis": [z, {"op": "prod", "factors": [{"op": "exp_decay", "var": "omega_m",
                                                                           "v_s": 2.0, "delta": 1.0}, z]}]}
    assert uses_state(term)
    st = static_term(term, 0.3)
    assert not uses_state(st) and st["basis"][0] == {"op": "sgn", "var": "omega_m", "eps": 0.3}
    assert st["basis"][1]["factors"][1] == {"op": "sgn", "var": "omega_m", "eps": 0.3}
    hyst = dict(term, signal="Q_red", basis=[{"op": "var", "var": state_var("windup", 1e-4)}], coef=[1.0])
    assert static_term(hyst, 0.3) is None  # a twist state has no static form: kept out of the twin
    plain = dict(term, basis=[{"op": "var", "var": "omega_m"}], coef=[1.0])
    assert static_term(plain, 0.3) == plain
