"""Forward selection does not stop at an inconsistent candidate (issue 10, fourteenth pass).

A group that lowers the pooled CV error a lot but only in a minority of blocks (a term that fits a few blocks'
structure) fails the fold-majority rule. Before, ``select_groups`` stopped there, so a consistent effect with a
smaller pooled gain behind it was never considered (seen on hysteretic-robot kinematic error, seed 2500: the twist
hysteresis helped in 8 of 15 blocks and hid the position-periodic stiffness). Now that family is skipped at this step
only: the next best family is considered, and the skipped one competes again once the model has changed.
"""
import numpy as np

from hd_ground.discovery.core import Options, _BlockGram, select_groups
from hd_ground.discovery.library import Candidate


def _cand(name, family):
    return Candidate(name=name, family=family, variable=None, order=None, basis=[], form=name)


def test_inconsistent_best_does_not_hide_a_consistent_effect():
    rng = np.random.default_rng(3)
    nb, per = 15, 400
    n = nb * per
    block = np.repeat(np.arange(nb), per)
    x_base = rng.normal(size=n)
    # "local": in y in 4 of 15 blocks only (a burst); its one coefficient, fitted across all blocks, lowers the error
    # a lot there and adds error in the other 11
    x_local = rng.normal(size=n)
    burst = np.isin(block, [0, 1, 2, 3])
    x_cons = np.sin(np.linspace(0, 60 * np.pi, n))  # a consistent effect present everywhere
    y = 2.0 * x_base + 0.35 * x_cons + np.where(burst, 3.0 * x_local, 0.0) + 0.3 * rng.normal(size=n)
    X = np.stack([x_base, x_local, x_cons], 1)
    gram = _BlockGram(X, y, block)
    groups = [(_cand("local_burst", "a"), [1]), (_cand("ripple", "b"), [2])]
    opt = Options()
    base = [0]
    # the local group has the larger pooled gain, in a minority of blocks
    cur = gram.cv_sse(base)
    e_loc, e_cons = gram.cv_sse([0, 1]), gram.cv_sse([0, 2])
    assert (cur.sum() - e_loc.sum()) > (cur.sum() - e_cons.sum())
    assert np.mean(e_loc < cur) < opt.fold_majority <= np.mean(e_cons < cur)
    selected, trace = select_groups(gram, base, groups, opt)
    steps = [(t["step"], t.get("candidate")) for t in trace]
    assert ("reject (inconsistent)", "local_burst[a]") in steps
    assert 1 in selected, steps  # the consistent ripple is admitted
    assert ("add", "ripple[b]") in steps
