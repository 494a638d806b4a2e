"""An effect discovery declares *and* writes as an identified term is evaluated by the term alone.

Discovery adds the found effect's name to ``declared_effects`` (the model's record) and its identified term to
``extra_terms``. hd_twin.physics has its own default-parameter equations for some friction effects; evaluating
both would count the effect twice (a default Stribeck bump on top of the identified one)."""

import numpy as np
import torch

from hd_twin import physics as ph
from hd_twin.data import FEATURES
from hd_twin.model import PINN, LossConfig, TwinLSTM

STRIBECK_TERM = {"name": "stribeck_friction", "signal": "tau_m", "variable": "omega_m", "order": None,
                 "form": "dT sgn(omega_m) exp(-|omega_m/v_s|^delta)",
                 "basis": [{"op": "stribeck", "var": "omega_m", "v_s": 3.0, "delta": 1.5, "eps": 0.05}],
                 "coef": [0.07], "parameters": {}}


def test_equation_effects_leaves_term_carried_friction_to_the_term():
    effects = list(ph.DEFAULT_EFFECTS) + ["stribeck_friction", "temperature_dependent_friction"]
    assert ph.equation_effects(effects, []) == effects  # no terms: every declared effect keeps its equation
    got = ph.equation_effects(effects, [STRIBECK_TERM])
    assert "stribeck_friction" not in got and "temperature_dependent_friction" in got
    assert [e for e in effects if e != "stribeck_friction"] == got
    # a term named after a structural or baseline effect does not remove that effect's equation
    coul = dict(STRIBECK_TERM, name="coulomb_friction")
    assert ph.equation_effects(effects, [coul]) == effects


def test_pinn_physics_counts_a_term_carried_effect_once():
    p = ph.TwinParams.from_yaml()
    effects = list(ph.DEFAULT_EFFECTS) + ["stribeck_friction"]
    net = TwinLSTM(len(FEATURES), 5, 4, 1, 0.0)
    pinn = PINN(net, p, effects, 0.0, 100.0, LossConfig(), extra_terms=[STRIBECK_TERM])
    assert "stribeck_friction" not in pinn.effects and pinn.declared_effects == effects
    # its motor-side friction: baseline equations + the identified term, not + the default Stribeck bump too
    w = torch.linspace(-20.0, 20.0, 81, dtype=torch.float64)
    tau = torch.zeros_like(w)
    q_once = ph.q_res(torch, p, pinn.effects, tau, w, extra_in=None)
    q_twice = ph.q_res(torch, p, effects, tau, w, extra_in=None)
    bump = (p.T_S - p.T_C) * torch.exp(-((w.abs() / p.omega_s) ** p.stribeck_delta)) * ph.sgn_eps(torch, w, p.eps_omega)
    np.testing.assert_allclose((q_once - q_twice).numpy(), bump.numpy(), rtol=1e-9, atol=1e-12)
    assert float(bump.abs().max()) > 1e-3  # the default bump is not negligible: the test can fail
