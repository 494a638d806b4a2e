"""bench/diag_prognostics_gap.py: the truth-informed forecasts that locate the life model's in-cone loss.

Synthetic fleets with a known answer: wear linear in missions, failure at the unit's own h_fail, a perfect model
median. With every unit's HI the same map of its wear, knowing the HI (own HI map, HI now) is as good as knowing
the wear; when the HI's gain differs between units, the population threshold in HI units misplaces the failure and
only the forecasts that read the wear itself stay in the cone.
"""

import importlib.util
from pathlib import Path

import numpy as np

_BENCH = Path(__file__).resolve().parents[2] / "bench" / "diag_prognostics_gap.py"
_spec = importlib.util.spec_from_file_location("diag_prognostics_gap_for_tests", _BENCH)
gap = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(gap)


def _fleet(gains, curv=0.0, h_fail=(1.0, 1.0, 1.0, 1.0, 1.0), eol=60):
    """Units whose wear grows 1/eol per mission to h_fail = 1 at mission eol (the same for all: every population
    threshold is exact); HI = offset + gain x (wear + curv wear^2); exposure = missions."""
    R = {}
    for i, (gn, hf) in enumerate(zip(gains, h_fail)):
        mi = np.arange(0, eol + 1, dtype=float)
        h = hf * mi / eol
        t = mi[:-1]
        y = 0.3 + 0.01 * i + gn * (h[:-1] + curv * h[:-1] ** 2)
        R[f"U{i}"] = dict(t=t, p50=eol - t, L50=h[:-1] / hf, y=y, E=t.copy(), eol=float(eol), h_fail=hf, h=h, mi=mi,
                          b=1.0, c=gn * (1.0 + curv), label="power latent")
    return R


def test_equal_hi_gain_hi_forecasts_match_the_wear_bound():
    res = gap.decompose(_fleet([1.0] * 5))
    for r in res.values():
        assert r["model"] == 1.0 and r["wear bound"] == 1.0
        assert r["wear now"] == 1.0
        assert r["own HI map"] == 1.0
        assert r["HI now"] == 1.0
        assert abs(r["HI rise at failure / pop"] - 1.0) < 1e-9
    # a convex HI extrapolated along the path L ~ E^1 (the shape's error) is called late; its own map is not
    curved = gap.decompose(_fleet([1.0] * 5, curv=0.5))
    assert all(r["own HI map"] == 1.0 for r in curved.values())
    assert all(r["HI now"] < 0.8 for r in curved.values())


def test_hi_gain_scatter_costs_the_hi_forecasts_only():
    # unit U0's HI rises 25 % faster per unit wear: its HI reaches the population's rise at failure at 80 % of its
    # life, so the HI forecasts call it early; the wear forecasts are unaffected
    res = gap.decompose(_fleet([1.25, 1.0, 1.0, 1.0, 1.0]))
    u0 = res["U0"]
    assert u0["wear bound"] == 1.0 and u0["wear now"] == 1.0
    assert abs(u0["HI rise at failure / pop"] - 1.25) < 1e-6
    assert u0["own HI map"] < 0.2 and u0["HI now"] < 0.2
    for k in ("U1", "U2", "U3", "U4"):  # the others: the median rise is still theirs
        assert res[k]["own HI map"] == 1.0
    lines = gap.report("synthetic", res)
    assert "U0 | 1.000 | 1.250" in lines and "lambda [0.9, 1.01)" in lines
