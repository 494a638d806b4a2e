"""The pair step (core._pair_step): two groups that mask each other are admitted together where a forward step
admits neither alone, each held to the single step's tests beside its partner; nothing is admitted from noise.

Known answer: y = 0.5 x0 + a + r + noise over 15 blocks, the second effect r correlated with the first a in every
block (|rho| = 0.9) with a sign that changes from block to block (a ripple whose phase against a loop's state differs
between missions), so that either column alone fits the other's share with the wrong sign in about half the blocks:
each is refused as inconsistent; the pair explains 86 % of the CV error in every block.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from hd_ground.discovery.core import Options, _BlockGram, select_groups


def _case(seed: int, effects: bool, nb: int = 15, n: int = 200, rho: float = 0.9, noise: float = 0.3):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n)
    X, y, blk = [], [], []
    for i in range(nb):
        a = np.sin(2 * np.pi * (1 + rng.uniform(0, 2)) * t + rng.uniform(0, 6))
        v = np.sin(2 * np.pi * (3 + rng.uniform(0, 3)) * t + rng.uniform(0, 6))
        r = rng.choice([-1.0, 1.0]) * rho * a + np.sqrt(1 - rho**2) * v
        x0 = rng.normal(size=n)
        yy = 0.5 * x0 + ((a + r) if effects else 0.0) + noise * rng.normal(size=n)
        X.append(np.column_stack([x0, a, r, rng.normal(size=n), np.sin(7 * t + i)]))
        y.append(yy)
        blk.append(np.full(n, i))
    return _BlockGram(np.concatenate(X), np.concatenate(y), np.concatenate(blk))


def _groups():
    def cand(name):
        return SimpleNamespace(name=name, family=name, shapes=[], positive=False, level_carrier=None, test_cols=None,
                               replace_idx=[], after=None)
    return [(cand("A"), [1]), (cand("R"), [2]), (cand("N1"), [3]), (cand("N2"), [4])]


def test_two_masking_effects_are_admitted_together():
    g, groups = _case(1, effects=True), _groups()
    sel0, tr0 = select_groups(g, [0], groups, Options(pair_step=False))
    assert sel0 == [], tr0
    refused = {r["candidate"]: r for r in tr0 if r["step"] == "reject (inconsistent)"}
    assert set(refused) == {"A[A]", "R[R]"}, tr0
    assert all(r["gain"] >= 0.02 and r["folds_better"] < 0.6 for r in refused.values())
    sel, tr = select_groups(g, [0], groups, Options())
    assert sorted(groups[i][0].name for i in sel) == ["A", "R"], tr
    adds = [r for r in tr if r["step"] == "add"]
    assert len(adds) == 2 and all("pair_with" in r for r in adds)
    # each beside its partner: the single step's tests (gain, folds, Wald) with a wide margin
    assert all(r["gain"] > 0.5 and r["folds_better"] == 1.0 and r["wald"] > 100 for r in adds), adds
    beta = g.coef([0, 1, 2])
    assert np.allclose(beta, [0.5, 1.0, 1.0], atol=0.05), beta


def test_no_pair_from_noise():
    for seed in range(3):
        g, groups = _case(seed, effects=False), _groups()
        sel, tr = select_groups(g, [0], groups, Options())
        assert sel == [], tr
        assert not any("pair_with" in r for r in tr)


def test_one_effect_alone_is_a_single_step():
    # only a in the data: it enters alone; r (correlated with a, not in the data) is not pulled in by the pair step
    rng = np.random.default_rng(5)
    g0 = _case(2, effects=False)
    X, y = g0._Xs * g0.scale, np.asarray(g0._y).copy()
    y = y + X[:, 1]
    blk = np.concatenate([np.full(int(m.sum()), i) for i, m in enumerate(g0._masks)])
    g = _BlockGram(X, y + 0.0 * rng.normal(size=len(y)), blk)
    groups = _groups()
    sel, tr = select_groups(g, [0], groups, Options())
    assert [groups[i][0].name for i in sel] == ["A"], tr
    assert not any("pair_with" in r for r in tr)
