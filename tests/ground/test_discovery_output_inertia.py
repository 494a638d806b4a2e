"""The Q_red baseline's output inertia (hd_ground.discovery.core.baseline_columns).

The torque sensor does not sit at the spring: between the measured twist w = theta_m/N - theta_f and the
sensor there is inertia (PHYSICS.md r4: F_m r_m - Q_red - J_CS theta_f'' = 0), so Q_red = K w + c w' -
J_out theta_f''. Without that column the inertia torque at the profiles' hard reversals (at one end of the
theta_f range) was "found" on clean data of the default world as a cubic in theta_f (bench seed 1100:
6.8 % of the held-out residual; docs/DISCOVERY_PASSES.md, seventh pass). One default-world case, 4 missions
x 4 s as the bench acquires them (bench_discover.make_family_bags), Q_red only.
"""

import numpy as np
import pytest

from hd_bag import read_mission
from hd_ground.discovery.core import baseline_columns
from hd_ground.discovery.data import dataset_from_missions
from hd_ground.discovery.pipeline import run_discovery

from .bench_module import bd


def test_q_red_baseline_has_the_output_inertia_only_when_the_acceleration_is_there():
    cols = baseline_columns("Q_red", {"windup", "windup_dot", "alpha_f"}, [], [], 1.0, {})[0]
    assert [c.param for c in cols] == ["K", "c", "minus_J_out"]
    assert cols[2].basis == {"op": "var", "var": "alpha_f"}
    assert [c.param for c in baseline_columns("Q_red", {"windup", "windup_dot"}, [], [], 1.0, {})[0]] == ["K", "c"]


@pytest.fixture(scope="module")
def default_clean(tmp_path_factory):
    """The default world's clean case of the bench at seed 1100 (the case the cubic was found on)."""
    root = tmp_path_factory.mktemp("output_inertia")
    return root, bd.make_family_bags(root / "bags", "default", None, {}, duration=4.0, seed=1100)


def test_inertia_column_lowers_the_held_out_q_red_error_and_is_physical(default_clean):
    _, bags = default_clean
    ds = dataset_from_missions([read_mission(b) for b in bags], bags)
    s, ho = ds.signals, ds.bag == len(bags) - 1
    assert np.allclose(s["alpha_f"], s["alpha_m"] / ds.gear_ratio, equal_nan=True)

    def heldout_rmse(cols):
        X = np.stack([s[c] for c in cols], 1)
        p = np.linalg.lstsq(X[~ho], s["Q_red"][~ho], rcond=None)[0]
        return float(np.sqrt(np.mean((s["Q_red"] - X @ p)[ho] ** 2))), p

    e0, _ = heldout_rmse(["windup", "windup_dot"])
    e1, p = heldout_rmse(["windup", "windup_dot", "alpha_f"])
    assert e1 < 0.95 * e0, (e0, e1)  # the inertia torque is a real part of Q_red, not noise
    assert p[2] < 0.0  # Q_red = ... - J_out theta_f'': a positive inertia


def test_clean_default_world_q_red_has_no_finding(default_clean):
    root, bags = default_clean
    rep = run_discovery(bags, root / "out", heldout=[bags[-1]], plots=False, within_bag_check=False,
                        signals=["Q_red"], log=lambda s: None)
    s = rep["signals"][0]
    assert s["identifiable"]
    assert max([e["explained"] for e in rep["effects"]] or [0.0]) < 0.05, rep["effects"]
    assert s["baseline_parameters"]["minus_J_out"] < 0.0
