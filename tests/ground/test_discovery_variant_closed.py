"""A variant refused for its own shape closes itself, not its family (issue 10, thirty-eighth pass).

Seen on default current ripple at seed 17300 (`hdphm bench discover --all`): the band-limited variant of the order-30
current ripple won its family (CV gain 16 % against the plain harmonic's 10 %), but its corner ran onto the low end of
its range and was refused as unidentified; the refusal closed the whole family, so the plain harmonic, which session
20's code had admitted there (held-out 0.1418 -> 0.1387), was never asked again. ``core.select_groups`` now closes the
refused variant alone; the family's other variants still compete, and the family is closed once all are.

Synthetic columns, numpy only: a baseline column and a ripple whose size fades with a speed-like variable; the
family's plain reading sin(theta) and its shaped reading sin(theta) g(v), the shaped one refused by ``confirm``.
< 1 s.
"""
import numpy as np

from hd_ground.discovery.core import Options, _BlockGram, select_groups
from hd_ground.discovery.library import Candidate
from hd_twin.identify import Shape

NB, PER = 15, 600


def _case(seed=0):
    rng = np.random.default_rng(seed)
    block = np.repeat(np.arange(NB), PER)
    t = np.tile(np.linspace(0, 1, PER), NB)
    v = 10.0 * np.sin(2 * np.pi * (0.7 + 0.05 * (block % 4)) * t + block)
    th = np.cumsum(v) / PER
    g = 1.0 / (1.0 + (v / 3.0) ** 2)
    x0 = np.sin(2 * np.pi * 0.4 * t + 0.3 * block)
    y = 2.0 * x0 + 0.5 * np.sin(8 * th) * g + 0.1 * rng.normal(size=len(t))
    X = np.column_stack([x0, np.sin(8 * th), np.cos(8 * th), np.sin(8 * th) * g, np.cos(8 * th) * g])
    plain = Candidate(name="cogging_torque", family="theta_m:8", variable="theta_m", order=8.0, basis=[], form="plain")
    band = Candidate(name="cogging_torque", family="theta_m:8", variable="theta_m", order=8.0, basis=[], form="band",
                     shapes=[Shape("omega_b", 1.0, 100.0)], nonlinear={"omega_b": 24.0}, screened=True)
    return _BlockGram(X, y, block), [(plain, [1, 2]), (band, [3, 4])]


def test_a_shaped_variant_refused_for_its_shape_leaves_its_family_open():
    gram, groups = _case()
    asked = []

    def confirm(gi, cur_idx):
        asked.append(gi)
        return False, "omega_b: the data only bound it (optimum at the lower bound)"

    sel, trace = select_groups(gram, [0], groups, Options(), reshape=lambda gi, cur: True, confirm=confirm)
    steps = [(r["step"], r.get("note", "")[:7]) for r in trace]
    assert asked == [1], steps  # the shaped variant won the family and was refused for its shape ...
    assert trace[1]["step"] == "reject (shape unidentified)" and trace[1]["note"].startswith("omega_b"), steps
    assert sel == [0], steps  # ... and the plain reading of the same ripple was asked next and admitted
    assert trace[2]["step"] == "add" and trace[2]["candidate"] == "cogging_torque[theta_m:8]", steps


def test_a_family_whose_variants_are_all_refused_is_closed():
    gram, groups = _case()
    band = groups[1][0]
    band.screened = False  # the family's only variant here (nothing listed before it to screen it)
    asked = []

    def confirm(gi, cur_idx):
        asked.append(gi)
        return False, "unidentified"

    sel, trace = select_groups(gram, [0], [(band, groups[1][1])], Options(), reshape=lambda gi, cur: True,
                               confirm=confirm)
    steps = [r["step"] for r in trace]
    assert sel == [] and asked == [0], steps  # refused once, then the family is closed: never asked again
    assert steps.count("reject (shape unidentified)") == 1 and "add" not in steps, steps
