"""The fault classifier's covariance choice across plant types (leave one plant out)."""

from __future__ import annotations

import numpy as np
import pytest

from hd_ground.fleet.classify import (CLASSES, COVARIANCES, FEATURES, GaussianFaultClassifier, fit_across_plants,
                                      macro_recall)

D = len(FEATURES)


def _plant(rng, n, spread_of):
    """Four classes with one mean (0) and class-specific spreads along the first two coordinates: only per-class
    covariances (QDA) separate them."""
    X, y = [], []
    for c in CLASSES:
        s = np.ones(D)
        s[:2] = spread_of[c]
        X.append(rng.standard_normal((n, D)) * s)
        y += [c] * n
    return np.concatenate(X), y


SPREADS = {"healthy": (0.2, 0.2), "tooth_wear": (5.0, 0.2), "lubrication_loss": (0.2, 5.0),
           "flexspline_stiffness_loss": (5.0, 5.0)}


def test_leave_one_plant_out_chooses_the_structure_that_transfers():
    rng = np.random.default_rng(3)
    parts = [_plant(rng, 40, SPREADS) for _ in range(3)]
    X = np.concatenate([p[0] for p in parts])
    y = sum((p[1] for p in parts), [])
    g = sum(([f"P{i}"] * len(p[1]) for i, p in enumerate(parts)), [])
    m = fit_across_plants(X, y, g)
    ch = m.info["covariance_choice"]
    assert m.covariance == "class"  # the classes differ only in spread: a shared covariance cannot tell them apart
    assert ch["chosen"] == m.covariance and ch["plants"] == ["P0", "P1", "P2"]
    assert set(ch["mean_macro_recall"]) == set(COVARIANCES)
    assert ch["mean_macro_recall"][ch["chosen"]] == max(ch["mean_macro_recall"].values())
    assert ch["mean_macro_recall"]["pooled"] < 0.4 < 0.6 < ch["mean_macro_recall"][ch["chosen"]]  # chance: 0.25
    Xt, yt = _plant(rng, 40, SPREADS)  # a fourth plant, never seen
    assert macro_recall(yt, m.predict(Xt)) > 0.6
    m2 = GaussianFaultClassifier.from_json(m.to_json())
    assert m2.covariance == m.covariance
    assert np.allclose(m2.predict_proba(Xt[:7]), m.predict_proba(Xt[:7]))


def test_one_plant_is_not_a_choice_and_bad_input_is_named():
    rng = np.random.default_rng(4)
    X, y = _plant(rng, 20, SPREADS)
    m = fit_across_plants(X, y, ["only"] * len(y))
    assert "not chosen" in m.info["covariance_choice"]["rule"] and m.covariance == COVARIANCES[0]
    with pytest.raises(ValueError, match="plant labels"):
        fit_across_plants(X, y, ["a"] * 3)
    with pytest.raises(ValueError, match="covariance"):
        GaussianFaultClassifier(covariance="full")
