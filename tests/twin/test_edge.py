"""Edge samples: the twin's derived signals are not defined within half a derivative window of a segment edge.

A mission that starts with a step in acceleration (the logger starts as the motion does; the sweep missions)
gave the twin's largest error on its first samples: the Savitzky-Golay derivative of the physics path
extrapolates its edge fit across the kink. Those samples are marked and left out of the losses and the metrics
(counted); the streaming twin flags its window fill after a reset. Synthetic data, numpy only.
"""

import numpy as np
import pytest

from hd_bag.mission import Mission, MissionMeta
from hd_twin import data as D
from hd_twin.identify import derivative, sg_window

N, J = 100.0, 5e-3  # gear ratio, motor-side inertia [kg m^2]


def _step_start_mission(fs=1000.0, T=3.0, seed=0):
    """Motion from rest that starts at the first logged sample with a speed step response (time constant 8 ms,
    so the acceleration jumps to 6000 rad/s^2 at t = 0), then a slow sine; tau_m = J alpha_m + Q_red / N."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(T * fs)) / fs
    W, tc = 50.0, 8e-3
    om = W * (1 - np.exp(-t / tc)) + 10 * np.sin(2 * np.pi * 1.3 * t)
    al = W / tc * np.exp(-t / tc) + 10 * 2 * np.pi * 1.3 * np.cos(2 * np.pi * 1.3 * t)
    th = W * (t + tc * (np.exp(-t / tc) - 1)) + 10 / (2 * np.pi * 1.3) * (1 - np.cos(2 * np.pi * 1.3 * t))
    Q = 200 * np.sin(2 * np.pi * 0.4 * t) - 300.0
    tau = J * al + Q / N
    meta = MissionMeta(actuator_id="EMA-E", mission_index=0, operating_hours=0.0, gear_ratio=N, torque_constant=0.1)
    m = Mission(meta=meta, t=t, theta_m=th, theta_f=th / N, omega_m=om + rng.normal(0, 1e-3, len(t)),
                omega_f=om / N, tau_m=tau, Q_red=Q, t_cmd=t.copy(), theta_ref=th / N,
                temperatures={"gearbox": (t[::1000].copy(), np.full(len(t[::1000]), 25.0))})
    m.report.path = "synthetic/step_start"
    return m


@pytest.mark.parametrize("fs_model", [250.0, 1000.0])
def test_the_edge_spike_is_on_the_masked_edge_samples(fs_model):
    m = _step_start_mission()
    (seg,) = D.preprocess(m, fs_model)
    half = sg_window(1.0 / seg.dt) // 2
    assert D.edge_half_window(seg.dt) == half >= 2
    assert seg.edge[:half].all() and seg.edge[-half:].all() and seg.edge.sum() == 2 * half
    assert not (seg.mask & seg.edge).any() and seg.mask[half:-half].all()  # edges out of every loss and metric
    # the physics path's torque balance with the exact inertia: its only error is the derivative's
    t = np.arange(seg.n) * seg.dt
    Q_hat = N * (seg.X[:, 2] - J * derivative(seg.X[:, 1], t))
    err = np.abs(Q_hat - seg.Q_red)
    worst = int(np.argmax(err))
    assert worst < half, (worst, half)  # the spike: on the first samples, where the edge fit extrapolates
    assert err[seg.mask].max() < 0.5 * err.max(), (err[seg.mask].max(), err.max())


def test_metrics_count_the_edge_samples_and_streaming_flags_its_window_fill(tmp_path):
    from hd_twin.runtime import StreamingTwin
    from hd_twin.train import TrainConfig, eval_model, train_twin
    from tests.twin.synth import synth_fleet

    train_twin(synth_fleet(2, 2, duration=2.0), tmp_path, TrainConfig.from_preset(
        "tiny", epochs=1, plots=False, fs_target=None), progress=False)
    m = _step_start_mission(fs=200.0, T=2.0)
    met = eval_model(tmp_path, [m])
    (seg,) = D.preprocess(m, 200.0)
    half = D.edge_half_window(seg.dt)
    assert met["edge_excluded"] == 2 * half and met["n"] == seg.n - 2 * half
    tw = StreamingTwin(tmp_path, fs_in=200.0)
    assert tw.edge_s == pytest.approx(2 * half / 200.0)
    flags = np.concatenate([tw.step(x)["edge"] for x in np.array_split(D.mission_inputs(m), 7)])
    assert flags[:2 * half].all() and not flags[2 * half:].any()  # the window fill after the reset only
