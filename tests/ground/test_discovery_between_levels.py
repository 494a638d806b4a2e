"""A function of a position is not credited with levels between blocks where the position stands still (issue 10,
fifteenth pass; core.within_block_sse).

Seen at seed 1900 (hysteretic-robot, clean): a cubic in the output angle, unknown(theta_f), took 51 % of the held-out
Q_red residual. The hysteresis state discover could build from a 16-bit twist was wrong by a level per mission (the
state starts from 0 in every mission), and the parked and dither missions, each at its own theta_f, let a smooth
function of theta_f fit those levels. A synthetic tau_m design with the same structure: the motor torque of a drive
with a per-mission offset that no declared term models (an unmodelled state starting at each mission's start), two
fit missions parked (the motor dithering) at two output angles, one sweeping the output over the stroke; the held-out
mission is parked where the first one was, so the levels "carry over" and the held-out arbiter cannot tell. Main's
selection admitted a position term on the levels; now the position term must also lower the CV error with a level
per block free, judged where the position moves, and it does not. The same design with a real torque periodic in the
output angle over its short stroke (the second plant's output_periodic) and no levels: still found.
"""
import numpy as np
import pytest

from hd_ground.discovery.core import Options, discover_signal
from hd_ground.discovery.data import Dataset

N, FS, DUR, BLOCKS = 50.0, 250.0, 10.0, 5


def _mission(kind: str, x0: float, level: float, periodic: float, rng) -> dict:
    t = np.arange(int(DUR * FS)) / FS
    if kind == "sweep":  # the output over its stroke, +-0.3 rad (0.1 rev: periodicity not identifiable)
        a, w = 0.3, 2 * np.pi / 5.0
        thf, om_f, al_f = a * np.sin(w * t), a * w * np.cos(w * t), -a * w**2 * np.sin(w * t)
    else:  # parked at x0, the motor dithering +-0.2 rad (the output +-0.004 rad)
        a, w = 0.2 / N, 2 * np.pi * 2.0
        thf, om_f, al_f = x0 + a * np.sin(w * t), a * w * np.cos(w * t), -a * w**2 * np.sin(w * t)
    th_m, om_m, al_m = N * thf, N * om_f, N * al_f
    q = 15.0 * np.sin(2 * np.pi * 0.3 * t + 7 * x0 + 1.0)  # an output load torque (Q_red), N*m
    # the motor torque: inertia, load path, Coulomb + viscous friction; an unmodelled state rising from 0 at the
    # mission's start to a per-mission level; a torque periodic in the output angle (0.14 rev period)
    tau = (2e-4 * al_m + q / (N * 0.85) + 0.2 * np.tanh(om_m / 0.05) + 0.01 * om_m
           + level * (1 - np.exp(-t / 1.0)) + periodic * np.sin(2 * np.pi * thf / 0.88 + 0.5)
           + 0.01 * rng.normal(size=len(t)))
    return {"t": t, "theta_m": th_m, "theta_f": thf, "omega_m": om_m + 0.02 * rng.normal(size=len(t)),
            "alpha_m": al_m, "tau_m": tau, "Q_red": q, "Q_red_over_N": q / N}


def _dataset(missions: list[dict]) -> Dataset:
    n1 = len(missions[0]["t"])
    cols = {k: np.concatenate([m[k] for m in missions]) for k in missions[0] if k != "t"}
    bag = np.repeat(np.arange(len(missions)), n1)
    within = np.tile(np.minimum((np.arange(n1) * BLOCKS) // n1, BLOCKS - 1), len(missions))
    t = np.tile(missions[0]["t"], len(missions))
    return Dataset(cols, bag, bag * BLOCKS + within, t / DUR, t, bag.copy(), [f"m{i}" for i in range(len(missions))],
                   N, 0.1)


def _run(kinds, levels, periodic, seed):
    rng = np.random.default_rng(seed)
    ms = [_mission(k, x0, lv, periodic, rng) for (k, x0), lv in zip(kinds, levels)]
    ds = _dataset(ms)
    return discover_signal(ds, "tau_m", ds.bag == len(ms) - 1, opt=Options())


@pytest.fixture(scope="module")
def levels_case():
    # fit: parked at -0.2 (+0.15 N*m), parked at +0.2 (-0.15), sweeping (0); held out: parked at -0.2 (+0.15)
    return _run([("parked", -0.2), ("parked", 0.2), ("sweep", 0.0), ("parked", -0.2)], [0.15, -0.15, 0.0, 0.15],
                0.0, 1)


def test_per_mission_levels_are_not_a_function_of_the_parked_position(levels_case):
    r = levels_case
    assert r.identifiable
    # the levels are there and a position term does fit them between the blocks (the pooled CV gain is real) ...
    pos = [t for t in r.cv_trace if t.get("candidate", "").split("[")[-1].startswith(("theta_f", "theta_m"))
           and t.get("gain", 0) >= Options().min_gain and t.get("folds_better", 0) >= Options().fold_majority]
    assert pos, r.cv_trace
    # ... but with a level per block free it gains nothing where the position moves: rejected, nothing found
    assert all(t["step"] == "reject (between-block levels)" for t in pos), pos
    assert max([e["explained"] for e in r.effects] or [0.0]) < 0.05, r.effects


def test_a_real_short_stroke_periodic_torque_is_still_found():
    # the same design without levels and with a torque periodic in the output angle (0.1 N*m, 0.14 rev period);
    # the held-out mission sweeps
    r = _run([("parked", -0.2), ("parked", 0.2), ("sweep", 0.0), ("sweep", 0.0)], [0.0] * 4, 0.1, 2)
    assert r.effects, r.cv_trace
    top = r.effects[0]
    assert top["variable"] in ("theta_f", "theta_m") and top["explained"] > 0.5, r.effects
    assert r.error_after["rmse"] < 0.6 * r.error_before["rmse"], (r.error_before, r.error_after)
    assert not any(t["step"] == "reject (between-block levels)" and t["candidate"].startswith("unknown[theta_f")
                   for t in r.cv_trace)


def test_level_carrier_of_position_groups_and_none_for_the_target_itself():
    # every position group is tested with its factor's level, except the i_q ripple: i_q = tau_m / k_t is the target,
    # whose level per block would rescale the target (seen on harivin: the check then took the whole signal away and
    # rejected its order-1 and order-2 ripples, held-out 0.026 -> 0.035 N*m)
    from hd_ground.discovery.library import LibraryContext, build_candidates

    ctx = LibraryContext(target="tau_m", available={"omega_m", "theta_m", "theta_f", "i_q", "tau_m"}, omega_scale=10.0,
                         omega_low=1.0, sgn_eps=0.05, t_ref=25.0, orders={"theta_m": [1.0, 2.0]},
                         excluded={"theta_f", "temperature", "load"}, short_stroke={"theta_f": (0.0, 0.3)})
    pos = [c for c in build_candidates(ctx) if c.variable in ("theta_m", "theta_f")]
    iq = [c for c in pos if "i_q" in c.requires]  # the plain i_q ripple and its band-limited variant
    assert iq and all(c.level_carrier is None for c in iq)
    rest = [c for c in pos if c not in iq]
    assert rest and all(c.level_carrier is not None for c in rest)
    assert {"op": "const"} in [c.level_carrier for c in rest]
    assert any(isinstance(c.level_carrier, dict) and c.level_carrier.get("op") == "sgn" for c in rest)
    # the band-limited ripple: a plain level and a level of its share per block, free together
    band = [c for c in rest if isinstance(c.level_carrier, list)]
    assert band and all([x["op"] for x in c.level_carrier] == ["const", "lowpass"] for c in band)


# --- eighteenth pass: a true ripple whose within-block CV is dominated by one block (core.within_block_coefficients)


def _ripple_gram(seed: int, n: int = 400):
    """A Q_red-like design of 15 blocks: the target is a load column, a state the model has (its level per block is
    part of it, like a hysteresis state that sits at another level in every block) and a ripple of order 2 in the
    motor angle, which the logger sees one sample late. 5 blocks sweep theta_m slowly (3 rev per block), 9 dither it
    +-0.3 rad around a parked angle (there the ripple is a level), one is fast (0.45 pi rad per sample: the late
    sample turns the ripple's phase by 0.9 pi, so the harmonic identified elsewhere is out of phase there)."""
    rng = np.random.default_rng(seed)
    Xs, ys, blk = [], [], []
    for b, kind in enumerate(["sweep"] * 5 + ["fast"] + ["dither"] * 9):
        i = np.arange(n + 1)
        if kind == "sweep":
            th = rng.uniform(0, 6) + 2 * np.pi * 3 * i / n
        elif kind == "fast":
            th = rng.uniform(0, 6) + 0.45 * np.pi * i
        else:
            th = rng.uniform(-20, 20) + 0.3 * np.sin(2 * np.pi * 2 * i / n)
        load = np.sin(2 * np.pi * rng.uniform(0.5, 2) * i / n + rng.uniform(0, 6))
        state = np.tanh(3 * np.sin(2 * np.pi * i / n + rng.uniform(0, 6))) + rng.normal()
        ripple = 0.2 * np.sin(2 * th[:-1] + 0.7)  # the torque at the previous sample's angle
        th, load, state = th[1:], load[1:], state[1:]
        ys.append(load + 0.5 * state + ripple + 0.05 * rng.normal(size=n))
        Xs.append(np.column_stack([load, state, np.sin(2 * th), np.cos(2 * th)]))
        blk.append(np.full(n, b))
    return np.vstack(Xs), np.concatenate(ys), np.concatenate(blk)


def test_a_true_ripple_lost_in_one_fast_block_is_admitted_by_its_within_block_coefficients():
    # the fifteenth pass's CV rule alone rejected seed 700's kinematic error (hysteretic-robot): with a level per block
    # free, the CV sum was dominated by the fastest block, where the ripple is out of phase (in the pooled CV too). Here
    # the same structure on 10 draws: the CV rule rejects the true ripple in most of them; its within-block
    # coefficients are identified and equal to the pooled ones (Hausman) in most of those, which are now admitted
    from hd_ground.discovery.core import _BlockGram, select_groups
    from hd_ground.discovery.library import Candidate

    opt = Options()
    cv_rejects = admitted = 0
    for seed in range(1, 11):
        X, y, blk = _ripple_gram(seed)
        gram = _BlockGram(X, y, blk)
        groups = [(Candidate("position_periodic_torque", "theta_m:2", "theta_m", 2.0, [], "ripple"), [2, 3])]
        car = (np.ones(len(y)), np.zeros(len(y), bool))
        sel, trace = select_groups(gram, [0, 1], groups, opt, carrier=lambda gi: car)
        rec = trace[1]
        # the pooled rules admit it
        assert rec["gain"] >= opt.min_gain and rec["folds_better"] >= opt.fold_majority, rec
        if rec["within_gain"] < opt.min_gain or rec["within_t"] < 1.0:
            cv_rejects += 1
            assert "hausman" in rec, rec
            admitted += rec["step"] == "add"
            assert (rec["step"] == "add") == (rec["within_wald"] >= rec["within_threshold"] > rec["hausman"]), rec
        else:
            assert rec["step"] == "add" and "hausman" not in rec, rec
    assert cv_rejects >= 6, cv_rejects
    assert admitted >= cv_rejects / 2, (admitted, cv_rejects)
