"""Discovery (issue 10, thirty-fifth pass): a lost motion whose teeth take up load over a range of twist.

Synthetic twist-side plant (``synthetic.torsion_plant``, numpy only): the torsion law is a gap whose half-width
varies from tooth to tooth, uniformly over [J - A, J + A] (flank profile errors and the spread of the gap along the
mesh): the mean of hard dead zones, a law with parabolic corners of width 2 A around |w| = J. No softplus anywhere:
the estimator's rounded zone (softplus corners) is not the plant's form. Discover must keep the lost motion named
``backlash``, read its edge (``edgeshape.refine_dead_zone_edge``), and predict the held-out bag better than the
hard zone it had; on a hard gap the edge is tried and the hard zone kept.
"""

import numpy as np
import pytest

from hd_ground.discovery.core import discover_signal

from .synthetic import torsion_plant

K, J = 1e6, 3e-4


def _spread_gap(a):
    def spring(x):
        js = J + a * np.linspace(-1, 1, 41)  # 41 teeth, gaps uniform over [J - a, J + a]
        ax = np.abs(x)[:, None]
        return K * np.sign(x) * np.mean(np.maximum(ax - js[None, :], 0.0), axis=1)
    return spring


def _gap(r):
    return next(e for e in r.effects if e["name"] == "backlash")


def test_a_gap_closing_over_a_range_of_twist_is_read_with_its_edge():
    ds, ho = torsion_plant(_spread_gap(1.5e-4))
    r = discover_signal(ds, "Q_red", ho)
    p = _gap(r)["parameters"]
    assert p.get("edge_used") == 1.0, [s for s in r.statements if "edge" in s]
    assert p["edge_ratio_se"] < 0.2 * p["edge_ratio"], p
    # parabolic corners of half-width A against softplus ones: the widths correspond only roughly
    assert 0.05 < p["edge_ratio"] < 0.6, p
    assert p["j"] == pytest.approx(J, rel=0.15), p
    # the hard zone's held-out error on the same rows: the final model with the edge taken off
    hard = discover_signal(ds, "Q_red", ho, opt=_no_edge())
    assert r.error_after["rmse"] < 0.9 * hard.error_after["rmse"], (r.error_after, hard.error_after)


def test_a_hard_gap_keeps_its_hard_zone():
    ds, ho = torsion_plant(_spread_gap(0.0))
    r = discover_signal(ds, "Q_red", ho)
    p = _gap(r)["parameters"]
    assert p.get("edge_used") == 0.0, p  # tried, and not admitted
    assert any("the hard dead zone is kept" in s for s in r.statements), r.statements


def _no_edge():
    from hd_ground.discovery.core import Options

    return Options(dead_zone_edge=False)

