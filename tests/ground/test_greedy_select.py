"""The greedy reference's two selection modes (``hd_ground.discovery.greedy.greedy_discover``): scored on the
held-out bag (the bench's reference) or by leave-one-bag-out CV over the fit bags (``select="cv"``, a reference
that never sees the held-out bag). Known answer on a synthetic motor torque: a 2/rev ripple is found by both, a
clean motor gives nothing to either, bad arguments are refused."""

import numpy as np
import pytest

from hd_ground.discovery.data import Dataset
from hd_ground.discovery.greedy import greedy_discover


def _dataset(ripple: float, n_bags: int = 4, n: int = 3000, seed: int = 0) -> tuple[Dataset, np.ndarray]:
    rng = np.random.default_rng(seed)
    sig = {k: [] for k in ("omega_m", "alpha_m", "theta_m", "tau_m")}
    bag = []
    for b in range(n_bags):
        t = np.arange(n) * 1e-3
        f = 0.4 + 0.15 * b
        omega = 20.0 * np.sin(2 * np.pi * f * t) + 3.0
        theta = np.cumsum(omega) * 1e-3 + rng.uniform(0, 2 * np.pi)
        alpha = np.gradient(omega, t)
        tau = (2e-4 * alpha + 0.05 * np.tanh(omega / 0.5) + 1e-3 * omega + ripple * np.sin(2 * theta + 0.3)
               + 0.004 * rng.standard_normal(n))
        for k, v in (("omega_m", omega), ("alpha_m", alpha), ("theta_m", theta), ("tau_m", tau)):
            sig[k].append(v)
        bag.append(np.full(n, b))
    sig = {k: np.concatenate(v) for k, v in sig.items()}
    bag = np.concatenate(bag)
    m = len(bag)
    ds = Dataset(signals=sig, bag=bag, block=bag * 5 + (np.arange(m) % n) * 5 // n, tfrac=(np.arange(m) % n) / n,
                 t=(np.arange(m) % n) * 1e-3, segment=bag, bag_names=[f"b{i}" for i in range(n_bags)],
                 gear_ratio=100.0, torque_constant=0.1)
    return ds, bag == n_bags - 1


@pytest.mark.parametrize("select", ["heldout", "cv"])
def test_both_modes_find_the_ripple_and_nothing_on_a_clean_motor(select):
    ds, ho = _dataset(ripple=0.02)
    r = greedy_discover(ds, "tau_m", ho, select=select)
    assert r["select"] == select
    assert r["effects"] and (r["effects"][0]["name"], r["effects"][0]["variable"], r["effects"][0]["order"]) == (
        "position_periodic_torque", "theta_m", 2.0)
    assert r["error_after"]["rmse"] < 0.5 * r["error_before"]["rmse"]
    ds0, ho0 = _dataset(ripple=0.0, seed=1)
    clean = greedy_discover(ds0, "tau_m", ho0, select=select)
    assert clean["effects"] == []


def test_cv_mode_never_reads_the_heldout_bag_for_its_choice():
    ds, ho = _dataset(ripple=0.02)
    a = greedy_discover(ds, "tau_m", ho, select="cv")
    sig = dict(ds.signals)
    tau = sig["tau_m"].copy()
    tau[ho] = np.random.default_rng(5).standard_normal(int(ho.sum()))  # the held-out bag replaced by noise
    sig["tau_m"] = tau
    b = greedy_discover(Dataset(**{**ds.__dict__, "signals": sig}), "tau_m", ho, select="cv")
    assert [e["name"] for e in a["effects"]] == [e["name"] for e in b["effects"]]
    assert a["effects"][0]["parameters"] == b["effects"][0]["parameters"]


def test_bad_arguments_are_refused():
    ds, ho = _dataset(ripple=0.02)
    with pytest.raises(ValueError, match="select"):
        greedy_discover(ds, "tau_m", ho, select="bic")
    two, ho2 = _dataset(ripple=0.02, n_bags=2)
    with pytest.raises(ValueError, match="fit bags"):
        greedy_discover(two, "tau_m", ho2, select="cv")
