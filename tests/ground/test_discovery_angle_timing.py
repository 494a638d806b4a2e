"""Position harmonics at the angle re-timed by the identified acquisition skew (issue 10, disc29).

A logger that latches the encoder at the start of its period and averages the speed and the current over it logs
the torque half a period after the angle: an order-k position ripple fitted on the logged angle is off in phase
by k omega s at speed (s the skew). Synthetic bags written here (numpy only, no hd_sim): a motor with inertia,
Coulomb + viscous friction and an order-2 position-periodic torque, simulated at 4 kHz and logged at 200 Hz the
way the bench's units are (angle: the period's first sub-sample; speed, torque: the mean of its 20), so the known
skew is 9.5 sub-samples = 2.375 ms. Checked: the skew identified from the speeds' lag is that value; with the
harmonics at the re-timed angle the ripple's phase is the true one in the slow and in the fast rows (as logged
it drifts with speed), the fit bags' CV chooses the re-timed angle, and the held-out error falls; a logger
that samples the torque at the angle's instant (no skew, though the averaged speeds still lag) keeps the logged
angle. The twin evaluates the written term with the same re-timing (the basis carries it).
"""

from types import SimpleNamespace

import numpy as np
import pytest

from hd_ground.discovery.core import (angle_skew_of, choose_angle_timing, discover_signal, uses_angle_harmonic)
from hd_ground.discovery.data import _derivative, speed_timing, with_angle_skew
from hd_twin.terms import evaluate_terms, required_signals

FS_SIM, DEC = 4000.0, 20  # simulated rate, sub-samples per logged row (200 Hz log)
SKEW = (DEC - 1) / 2 / FS_SIM  # the torque sample's centre after the angle's sample: 2.375 ms
A2, PSI = 0.3, 0.7  # the ripple's amplitude N*m and phase rad: A2 sin(2 theta_m + PSI)
AMPS = (12.0, 22.0, 30.0, 26.0)  # rad, per bag: speed peaks 2 pi 1.0 AMP = 75..190 rad/s


def _bags(torque_at_angle: bool, seed: int = 3):
    rng = np.random.default_rng(seed)
    n = int(8.0 * FS_SIM)
    t = np.arange(n) / FS_SIM
    out = []
    for i, a in enumerate(AMPS):
        th = a * np.sin(2 * np.pi * 1.0 * t + i) + 0.3 * a * np.sin(2 * np.pi * 0.37 * t)
        om = np.gradient(th, t)
        al = np.gradient(om, t)
        tau = 0.02 * al + 1.0 * np.tanh(om / 0.5) + 0.004 * om + A2 * np.sin(2 * th + PSI)
        rows = n // DEC
        first = np.arange(rows) * DEC
        mean = (lambda x: x[: rows * DEC].reshape(rows, DEC).mean(1))
        tau_log = tau[first] if torque_at_angle else mean(tau)
        out.append(SimpleNamespace(t=t[first], theta_m=th[first], omega_m=mean(om),
                                   tau_m=tau_log + rng.normal(0, 0.03, rows),
                                   theta_f=th[first] / 50, omega_f=mean(om) / 50,
                                   segment=np.zeros(rows, int), n=rows))
    return out


def _dataset(ms):
    from hd_ground.discovery.data import Dataset

    cols = {k: [] for k in ("theta_m", "omega_m", "alpha_m", "tau_m", "i_q")}
    for m in ms:
        for k, v in (("theta_m", m.theta_m), ("omega_m", m.omega_m), ("tau_m", m.tau_m), ("i_q", m.tau_m / 0.1),
                     ("alpha_m", _derivative(m.omega_m, m.t, m.segment, 0.02))):
            cols[k].append(v)
    n = ms[0].n
    bag = np.repeat(np.arange(len(ms)), n)
    frac = np.tile(np.arange(n) / (n - 1), len(ms))
    block = bag * 5 + np.minimum((frac * 5).astype(int), 4)
    ds = Dataset({k: np.concatenate(v) for k, v in cols.items()}, bag, block, frac, np.tile(ms[0].t, len(ms)),
                 bag.copy(), [f"bag{i}" for i in range(len(ms))], 50.0, 0.1)
    return ds, bag == len(ms) - 1


def _phase_by_speed(ds, skew: float):
    """The ripple's phase error (deg) fitted on the known rest of the torque at theta + skew omega, in the slow rows
    and in the fast rows of each direction (the skew's phase error 2 omega s is signed with the motion)."""
    s = ds.signals
    rest = s["tau_m"] - (0.02 * s["alpha_m"] + np.tanh(s["omega_m"] / 0.5) + 0.004 * s["omega_m"])
    x = 2 * (s["theta_m"] + skew * s["omega_m"])
    w = np.abs(s["omega_m"])
    out = []
    for rows in (w < 40, s["omega_m"] > 120, s["omega_m"] < -120):
        c = np.linalg.lstsq(np.column_stack([np.sin(x[rows]), np.cos(x[rows])]), rest[rows], rcond=None)[0]
        out.append(np.degrees(np.angle(np.exp(1j * (np.arctan2(c[1], c[0]) - PSI)))))
    return out


@pytest.fixture(scope="module")
def skewed():
    ms = _bags(torque_at_angle=False)
    ds, ho = _dataset(ms)
    lags, _ = speed_timing(ms)
    return ds, ho, angle_skew_of(lags)


def test_skew_identified_from_the_speeds_and_phase_recovered_at_all_speeds(skewed):
    ds, ho, skew = skewed
    assert skew == pytest.approx(SKEW, rel=0.1)
    slow0, up0, down0 = _phase_by_speed(ds, 0.0)
    slow1, up1, down1 = _phase_by_speed(ds, skew)
    # as logged the phase error grows with speed (2 omega s: > 2 x 120 rad/s x 2.375 ms = 33 deg above 120 rad/s),
    # signed with the direction; at the re-timed angle it is gone at every speed
    assert up0 > 25 and down0 < -25 and abs(slow0) < 15, (slow0, up0, down0)
    assert abs(slow1) < 8 and abs(up1) < 8 and abs(down1) < 8, (slow1, up1, down1)


def test_retimed_harmonics_chosen_and_heldout_error_falls(skewed):
    ds, ho, skew = skewed
    r0 = discover_signal(ds, "tau_m", ho)
    assert uses_angle_harmonic(r0.terms)
    r1 = discover_signal(with_angle_skew(ds, skew), "tau_m", ho)
    keep, st = choose_angle_timing(r0, r1, skew)
    assert keep and "; used" in st, st
    assert r1.error_after["rmse"] < 0.97 * r0.error_after["rmse"], (r0.error_after, r1.error_after)
    ke = [t for t in r1.terms if t["name"] == "position_periodic_torque" and t["order"] == 2]
    assert ke, [t["name"] for t in r1.terms]
    b = ke[0]["basis"][0]
    b = b if b["op"] in ("sin", "cos") else b["factors"][0]
    assert b["skew_s"] == pytest.approx(skew) and b["rate"] == "omega_m"
    # the twin evaluates the written term with the same re-timing (the basis carries it)
    s = ds.signals
    v = evaluate_terms(ke, {k: s[k] for k in required_signals(ke)})
    x = 2 * (s["theta_m"] + skew * s["omega_m"])
    c = ke[0]["coef"]
    if ke[0]["basis"][0]["op"] in ("sin", "cos"):
        assert np.allclose(v, c[0] * np.sin(x) + c[1] * np.cos(x))
    assert {"theta_m", "omega_m"} <= required_signals(ke)


def test_torque_at_the_angle_instant_keeps_the_logged_angle():
    ms = _bags(torque_at_angle=True)
    ds, ho = _dataset(ms)
    lags, _ = speed_timing(ms)
    skew = angle_skew_of(lags)
    assert skew == pytest.approx(SKEW, rel=0.1)  # the averaged speeds still lead the angle ...
    r0 = discover_signal(ds, "tau_m", ho)
    r1 = discover_signal(with_angle_skew(ds, skew), "tau_m", ho)
    keep, st = choose_angle_timing(r0, r1, skew)
    assert not keep and "as logged" in st, st  # ... but the torque is at the angle's instant: no re-timing


def test_a_skewed_harmonic_needs_its_rate_and_a_finite_skew():
    from hd_twin.terms import make_term, sin_cos_pair

    with pytest.raises(ValueError, match="rate"):
        make_term("position_periodic_torque", "tau_m", [{"op": "sin", "var": "theta_m", "k": 2, "skew_s": 0.002}],
                  [1.0])
    with pytest.raises(ValueError, match="skew_s"):
        make_term("position_periodic_torque", "tau_m",
                  [{"op": "cos", "var": "theta_m", "k": 2, "skew_s": float("nan"), "rate": "omega_m"}], [1.0])
    with pytest.raises(ValueError, match="rate"):
        sin_cos_pair("theta_m", 2.0, skew_s=0.002)
    # no skew: the plain pair, as every term written before
    assert sin_cos_pair("theta_m", 2.0, skew_s=0.0) == [{"op": "sin", "var": "theta_m", "k": 2.0},
                                                         {"op": "cos", "var": "theta_m", "k": 2.0}]


def test_a_lagging_speed_gives_no_angle_skew():
    # an averaging logger's speed leads the angle's rate (tau < 0): the torque sample's skew is -tau; a speed that
    # lags it is a filtered estimate, whose lag says nothing about the torque's instant (harivin: 2.72 ms)
    assert angle_skew_of({"omega_m": -0.002375}) == pytest.approx(0.002375)
    assert angle_skew_of({"omega_m": 0.00272}) is None
    assert angle_skew_of({"omega_m": 0.0}) is None and angle_skew_of({}) is None
    assert angle_skew_of({"omega_m": float("nan")}) is None
