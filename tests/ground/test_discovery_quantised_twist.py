"""Quantisation-aware twist for the twist-side hysteresis state (hd_ground.discovery.data).

A twist formed from whole encoder counts toggles by one count and back at rest and at every slow
crossing of a count; a Dahl / Bouc-Wen state driven by it counts each toggle as a reversal of the load.
``angle_resolution`` finds the count step from the data, ``play`` of one step removes the toggles.
"""

import numpy as np

from hd_ground.discovery.data import angle_resolution, play
from hd_twin.identify import presliding_state


def test_angle_resolution_finds_the_count_step_and_rejects_continuous_angles():
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 4.0, 4000)
    x = 0.3 * np.sin(2 * np.pi * 0.5 * t) + 1e-4 * rng.standard_normal(t.size)
    q = 2 * np.pi / 2**16
    assert abs(angle_resolution(np.round(x / q) * q) / q - 1.0) < 1e-6
    assert angle_resolution(x) == 0.0  # continuous (noisy) angle: not quantised
    assert angle_resolution(np.full(100, 0.2)) == 0.0  # no increments: nothing to tell


def test_play_ignores_count_toggles_follows_motion_and_restarts_per_segment():
    q = 1e-4
    toggling = np.tile([0.0, q, 0.0, -q], 50)
    assert np.ptp(play(toggling, 1.001 * q)) == 0.0
    ramp = np.arange(100) * q
    out = play(ramp, 1.001 * q)
    assert np.allclose(np.diff(out[5:]), q)  # moves with the ramp once past the play
    seg = np.r_[np.zeros(50, int), np.ones(50, int)]
    assert play(ramp, 1.001 * q, seg)[50] == ramp[50]  # a new segment starts on its own first sample
    assert np.array_equal(play(ramp, 0.0), ramp)


def test_hysteresis_amplitude_recovered_from_a_twist_quantised_at_the_loop_width():
    # a load cycling slowly, transmitted through K w + T_h s(w; d): the twist measured in counts of
    # about half the loop width; least squares on [w, s(.)] with the state of the measured twist vs of its play
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 8.0, 1e-3)
    K, T_h, d = 1.0e6, 100.0, 1.5e-4
    w = 6e-4 * np.sin(2 * np.pi * 0.4 * t) + 2e-4 * np.sin(2 * np.pi * 1.3 * t)
    q = 1e-4
    w_meas = np.round((w + 3e-6 * rng.standard_normal(t.size)) / q) * q
    Q = K * w + T_h * presliding_state(w, d) + 5.0 * rng.standard_normal(t.size)
    r = angle_resolution(w_meas)
    assert abs(r / q - 1.0) < 1e-6

    def fit(x):
        A = np.c_[w_meas, presliding_state(x, d)]
        p = np.linalg.lstsq(A, Q, rcond=None)[0]
        return p[1], float(np.sqrt(np.mean((Q - A @ p) ** 2)))

    th_raw, e_raw = fit(w_meas)
    th_q, e_q = fit(play(w_meas, 1.001 * r))
    assert abs(th_q / T_h - 1.0) < 0.35
    assert e_q < e_raw
    assert abs(th_raw / T_h - 1.0) > abs(th_q / T_h - 1.0)
