"""The motor acceleration's derivative window is identified on the fit bags (``core.choose_alpha_window``), by default.

Synthetic plants written here (numpy only, no hd_sim): tau_m = J alpha + T_C tanh(omega/eps) + b omega + noise,
with alpha_m derived from the measured speed by the window under test. Fast transients (a 12 Hz motion: a
20 ms Savitzky-Golay derivative attenuates and smears its acceleration) need a shorter window; a slow motion
with a noisy speed would take the longest window tried, where the CV error is still falling: only bounded, so
the default stays. A torque logged later than the speed's instants gets the inertia torque's timing column,
J tau_a alpha_m', with tau_a recovered. Through ``run_discovery`` with its default options, the transient-rich
case's held-out error is far below that with the 20 ms window (a regression of the default fails here).
"""

import numpy as np
import pytest

from hd_bag.mission import Mission, MissionMeta
from hd_ground.discovery.core import Options, choose_alpha_window, discover_signal
from hd_ground.discovery.data import Dataset, _derivative
from hd_ground.discovery.pipeline import run_discovery

FS, T_BAG, N_BAGS, J, T_C, EPS, B = 1000.0, 4.0, 4, 0.01, 1.0, 0.5, 0.01


def _plant(f_motion: float, speed_noise: float, seed: int = 0, tau_a: float = 0.0, fs: float = FS):
    rng = np.random.default_rng(seed)
    n = int(fs * T_BAG)
    t = np.arange(n) / fs
    ws, taus = [], []
    for i in range(N_BAGS):
        a, f = 20.0 + 3 * i, f_motion * (1 + 0.1 * i)
        w = a * np.sin(2 * np.pi * f * t) + 0.3 * a * np.sin(2 * np.pi * 0.37 * f * t + i)
        ts = t + tau_a  # the torque's instants: the inertia torque tau_a later than the speed's
        al = a * 2 * np.pi * f * np.cos(2 * np.pi * f * ts) + 0.3 * a * 2 * np.pi * 0.37 * f * np.cos(2 * np.pi * 0.37 * f * ts + i)
        taus.append(J * al + T_C * np.tanh(w / EPS) + B * w + rng.normal(0, 0.02, n))
        ws.append(w + rng.normal(0, speed_noise, n))
    bag = np.repeat(np.arange(N_BAGS), n)
    frac = np.tile(t / t[-1], N_BAGS)
    block = bag * 5 + np.minimum((frac * 5).astype(int), 4)
    tt = np.tile(t, N_BAGS)
    omega = np.concatenate(ws)
    theta = np.concatenate([np.cumsum(w) / fs for w in ws])

    def make(win, timing=False):
        sig = {"theta_m": theta, "omega_m": omega, "tau_m": np.concatenate(taus),
               "alpha_m": _derivative(omega, tt, bag, win)}
        if timing:
            sig["alpha_m_dot"] = _derivative(sig["alpha_m"], tt, bag, win)
        return Dataset(sig, bag, block, frac, tt, bag.copy(), [f"bag{i}" for i in range(N_BAGS)], 100.0, 0.1)
    return make, bag == N_BAGS - 1


def test_fast_transients_get_a_shorter_acceleration_window():
    make, ho = _plant(12.0, 0.01)
    ds, note = choose_alpha_window(make, make(0.02), ho, Options())
    assert _chosen_ms(note) < 20.0, note
    assert not np.allclose(ds.signals["alpha_m"], make(0.02).signals["alpha_m"])  # the data use it


def test_a_slow_log_is_differentiated_at_its_own_resolution():
    # logged at 200 Hz, five samples are already 25 ms, beyond the 20 ms default: the central difference (three
    # samples, 15 ms) is the one shorter window the log allows, and an 8 Hz motion needs it (forty-first pass)
    make, ho = _plant(8.0, 0.01, fs=200.0)
    ds, note = choose_alpha_window(make, make(0.02), ho, Options())
    assert _chosen_ms(note) == pytest.approx(15.0), note
    assert "; tried 20 ms" in note and "15 ms:" in note, note
    # at 1 kHz five samples (5 ms) already bracket the default from below: no central difference is offered
    make1, ho1 = _plant(12.0, 0.01)
    note1 = choose_alpha_window(make1, make1(0.02), ho1, Options())[1]
    assert "; 5 ms:" in note1 and "; 3 ms:" not in note1, note1


def test_window_on_the_longest_candidate_is_only_bounded_and_the_default_stays():
    # slow motion, noisy speed: the CV error falls to the longest window tried (33 ms) and would fall further
    make, ho = _plant(0.3, 0.2)
    ds0 = make(0.02)
    ds, note = choose_alpha_window(make, ds0, ho, Options())
    assert ds is ds0 and "only bounded, not identified" in note, note
    assert "best alternative 33 ms" in note, note


def test_default_window_kept_when_no_window_gains_min_gain():
    make, ho = _plant(0.3, 0.2)
    ds0 = make(0.02)
    ds, note = choose_alpha_window(make, ds0, ho, Options(min_gain=0.9))
    assert ds is ds0 and "kept" in note, note


def test_inertia_torque_timing_is_identified():
    tau_a = 2e-3  # the logged torque 2 ms after the speed's instants
    make, ho = _plant(12.0, 0.01, tau_a=tau_a)
    ds, note = choose_alpha_window(make, make(0.02), ho, Options())
    assert "timing" in note and "alpha_m_dot" in ds.signals, note
    bp = discover_signal(ds, "tau_m", ho).baseline_params
    assert bp["J_eq"] == pytest.approx(J, rel=0.05)
    assert bp["J_tau_a"] / bp["J_eq"] == pytest.approx(tau_a, rel=0.2), bp
    # without the offset the timing column does not pay for itself
    make0, ho0 = _plant(12.0, 0.01)
    assert "timing" not in choose_alpha_window(make0, make0(0.02), ho0, Options())[1].split("; tried")[0]


def _missions(f_motion: float = 12.0, tau_a: float = 1e-3, seed: int = 3) -> list[Mission]:
    """Contract missions of the fast-transient plant: the inertia torque is most of tau_m and a 20 ms derivative
    window attenuates its acceleration; the logged torque is ``tau_a`` later than the speed's instants."""
    rng = np.random.default_rng(seed)
    n = int(FS * T_BAG)
    t = np.arange(n) / FS
    out = []
    for i in range(N_BAGS):
        a, f = 20.0 + 3 * i, f_motion * (1 + 0.1 * i)

        def w_of(tt):
            return a * np.sin(2 * np.pi * f * tt) + 0.3 * a * np.sin(2 * np.pi * 0.37 * f * tt + i)

        def al_of(tt):
            return (a * 2 * np.pi * f * np.cos(2 * np.pi * f * tt)
                    + 0.3 * a * 2 * np.pi * 0.37 * f * np.cos(2 * np.pi * 0.37 * f * tt + i))
        w = w_of(t)
        tau = J * al_of(t + tau_a) + T_C * np.tanh(w / EPS) + B * w + rng.normal(0, 0.02, n)
        theta = np.cumsum(w) / FS
        out.append(Mission(MissionMeta("SYN", i, 0.0, 50.0, 0.1), t, theta, theta / 50.0,
                           w + rng.normal(0, 0.01, n), w / 50.0, tau, np.full(n, np.nan), t[:1], theta[:1] / 50.0))
    return out


def test_default_pipeline_identifies_the_window_and_lowers_the_heldout_error(tmp_path):
    ms = _missions()
    names = [f"syn{i}.mcap" for i in range(N_BAGS)]
    err = {}
    for mode in ("identify", "default"):
        opt = Options() if mode == "identify" else Options(alpha_window="default")
        rep = run_discovery(names, tmp_path / mode, missions=ms, signals=["tau_m"], within_bag_check=False,
                            plots=False, opt=opt, log=lambda s: None)
        err[mode] = rep["error_before"]["rmse"]
        if mode == "identify":
            assert any(n.startswith("acceleration: identified") for n in rep["data_notes"]), rep["data_notes"]
            assert rep["acceleration"]["window_s"] < 0.02 and rep["acceleration"]["timing"], rep["acceleration"]
    assert Options().alpha_window == "identify"  # the default
    # the held-out baseline error with the default options: the 20 ms window's acceleration bias is gone
    assert err["identify"] < 0.5 * err["default"], err


def _chosen_ms(note: str) -> float:
    assert "identified on the fit bags, " in note, note
    return float(note.split("identified on the fit bags, ")[1].split(" ms")[0])
