"""Scoring harness of the onboard detection study: the simulated missions it scores.

``hd_onboard.evaluate`` holds the study (:func:`~hd_onboard.evaluate.detection_study`); it takes the
mission maker as an argument because estimator packages never import the plant (``hd_sim``;
tests/test_layering.py). This module, above both, joins them: ``hdphm onboard study`` and
``python -m hdphm.onboard_study study ...``.
"""

from __future__ import annotations


def sim_mission(actuator: int, pop_seed: int, seed: int, duration: float, mission_index: int, fault=None):
    """One simulated mission of the study (t0 set); ``fault`` None: healthy."""
    import dataclasses

    from hd_sim import EffectSet, sample_population, simulate_mission

    p = sample_population(actuator + 1, seed=pop_seed)[actuator]
    m, _ = simulate_mission(p, EffectSet.default(), "inspection", seed, duration=duration, mission_index=mission_index,
                            fault=fault)
    return dataclasses.replace(m, t0_ns=1_700_000_000_000_000_000)


def run_study(args) -> int:
    """``hdphm onboard study``: the study of :mod:`hd_onboard.evaluate` on simulated missions."""
    from hd_ground.references import calibrate_actuator
    from hd_onboard.evaluate import run_study as run

    return run(args, simulate=sim_mission, calibrate=calibrate_actuator)


def main(argv=None) -> int:
    """``python -m hdphm.onboard_study study --healthy DIR [--n 6] [--actuator 2] [--seed0 40] --out DIR``."""
    import argparse

    from hd_onboard.study_args import add_study_args

    ap = argparse.ArgumentParser(prog="python -m hdphm.onboard_study",
                                 description="onboard detection study: delay per fault and severity + false alarms")
    ap.add_argument("what", choices=("study",))
    add_study_args(ap)
    return run_study(ap.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
