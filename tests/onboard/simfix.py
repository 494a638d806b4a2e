"""Missions from the real plant simulator (hd_sim) for the onboard and ROS tests.

A fault **injected mid-mission** comes from hd_sim's own hook
(``simulate_mission(..., fault={"name", "severity", "t_onset", "t_ramp"})``):
the kernel ramps the faulted parameters over ``t_ramp`` (default
``hd_sim.plant.FAULT_RAMP_S`` = 50 ms) from ``t_fault`` on, so the plant state
stays continuous and the samples before the onset are bit-identical to the
healthy mission with the same seeds (no splice, no jump for a detector to
flag instead of the fault).
"""
from __future__ import annotations

import dataclasses


def sim_mission(actuator: int = 0, seed: int = 0, duration: float = 20.0, pop_seed: int = 7, effects=None,
                mission_index: int = 0, profile: str = "inspection", t0_ns: int = 1_700_000_000_000_000_000):
    """One simulated mission (default realistic effects) of unit ``actuator`` of a population; t0_ns set."""
    from hd_sim import EffectSet, sample_population, simulate_mission

    p = sample_population(actuator + 1, seed=pop_seed)[actuator]
    m, _ = simulate_mission(p, effects if effects is not None else EffectSet.default(), profile, seed,
                            duration=duration, mission_index=mission_index)
    return dataclasses.replace(m, t0_ns=t0_ns)


def faulted_mission(t_fault: float, effect: str = "lubrication_loss", severity: float = 3.0,
                    actuator: int = 0, seed: int = 0, duration: float = 20.0, t_ramp: float | None = None,
                    pop_seed: int = 7, mission_index: int = 0, profile: str = "inspection",
                    t0_ns: int = 1_700_000_000_000_000_000):
    """``sim_mission`` with ``effect`` at ``severity`` starting at ``t_fault`` [s] (ramp ``t_ramp`` [s])."""
    from hd_sim import EffectSet, sample_population, simulate_mission

    fault = {"name": effect, "severity": float(severity), "t_onset": float(t_fault)}
    if t_ramp is not None:
        fault["t_ramp"] = float(t_ramp)
    p = sample_population(actuator + 1, seed=pop_seed)[actuator]
    m, _ = simulate_mission(p, EffectSet.default(), profile, seed, duration=duration,
                            mission_index=mission_index, fault=fault)
    return dataclasses.replace(m, t0_ns=t0_ns)


def spliced_mission(t_fault: float, effect: str = "lubrication_loss", severity: float = 3.0, actuator: int = 0,
                    seed: int = 0, duration: float = 20.0, **kw):
    """The former construction (for comparison only): healthy run before ``t_fault``, a run faulted from the
    start after it, same seeds; the plant state jumps at the splice."""
    import numpy as np

    from hd_sim import EffectSet

    key = "severity" if effect == "lubrication_loss" else "loss"
    a = sim_mission(actuator, seed, duration, **kw)
    b = sim_mission(actuator, seed, duration, effects=EffectSet.default().apply_cli(
        [f"{effect}=on"], [f"{effect}.{key}={severity}"]), **kw)
    ka, kb = a.t < t_fault, b.t >= t_fault
    names = ("t", "theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red")
    return dataclasses.replace(a, **{nm: np.concatenate([getattr(a, nm)[ka], getattr(b, nm)[kb]]) for nm in names})


def measure_delays(n: int = 8, severity: float = 3.0, actuator: int = 1, duration: float = 16.0,
                   effect: str = "lubrication_loss", splice: bool = False) -> list[tuple]:
    """Detection delay of the onboard core (physics stand-in twin) on ``n`` missions, onset 8 + 0.5 k s,
    seed 20 + k: [(seed, t_onset, first flag time [s] or None, delay [s] or None, channels)]."""
    from hd_onboard.batch import run_mission

    rows = []
    for k in range(n):
        t_on, seed = 8.0 + 0.5 * k, 20 + k
        mk = spliced_mission if splice else faulted_mission
        m = mk(t_on, effect, severity, actuator=actuator, seed=seed, duration=duration)
        r = run_mission(m)
        on = r["onset_s"]
        ch = r["events"][0][2] if r["events"] else ""
        rows.append((seed, t_on, on, None if on is None else on - t_on, ch))
    return rows


if __name__ == "__main__":  # python -m tests.onboard.simfix [--severity 3] [--effect NAME] [--splice]
    import argparse

    ap = argparse.ArgumentParser(description="onboard detection delay on sim missions with a mid-mission fault")
    ap.add_argument("--severity", type=float, default=3.0)
    ap.add_argument("--effect", default="lubrication_loss", choices=("lubrication_loss", "flexspline_stiffness_loss"))
    ap.add_argument("--splice", action="store_true", help="the former spliced construction, for comparison")
    ap.add_argument("-n", type=int, default=8, help="missions (onset 8 + 0.5 k s, seed 20 + k)")
    a = ap.parse_args()
    for row in measure_delays(n=a.n, severity=a.severity, effect=a.effect, splice=a.splice):
        d = "missed" if row[3] is None else f"{row[3]:+.2f} s"
        print(f"seed {row[0]} onset {row[1]:.1f} s: flag at {row[2]} -> delay {d} {str(row[4])[:60]}", flush=True)
