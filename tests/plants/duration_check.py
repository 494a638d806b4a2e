"""How short may a case mission be? Runs the effect checks of test_ema2 at several durations.

    PYTHONPATH=src:. python -m tests.plants.duration_check 6 8 12

Prints, per duration, PASS/FAIL of the base-physics and per-effect checks and the per-mission estimates
of the motor-side effect parameters (truth: ripple 0.04, ripple_weak 0.012, stribeck 0.05, load 0.06,
outp 6.0).
"""

from __future__ import annotations

import sys

import numpy as np

from tests.plants import ema2
from tests.plants import test_ema2 as T


def main(argv=None) -> int:
    N = ema2.BASE["N"]
    for dur in map(float, (argv if argv is not None else sys.argv[1:]) or ["8"]):
        sig = ema2.simulate_cases(duration=dur)

        class F:
            def signals(self, e, duration=None):
                return sig[e]

            def __call__(self, e, duration=None):
                return {"signals": sig[e]}

        ok = []
        for fn in (T.test_base_physics_tracking_and_torque_balance, T.test_each_effect_shows_in_its_signal_at_its_size):
            try:
                fn(F())
                ok.append("PASS")
            except AssertionError as ex:
                ok.append("FAIL " + str(ex).splitlines()[0][:100])
        est = {
            "ripple": [T._amp(T._motor_fit(s, (T._ripple, T._rippls))[4:]) for s in sig["ripple"]],
            "ripple_weak": [T._amp(T._motor_fit(s, (T._ripple, T._rippls))[4:]) for s in sig["ripple_weak"]],
            "stribeck": [T._motor_fit(s, (lambda s: np.exp(-(s["omega_m"] / 5) ** 2) * np.tanh(s["omega_m"]),))[4]
                         for s in sig["stribeck"]],
            "load": [T._motor_fit(s, (lambda s: np.abs(s["Q_red"]) / N * np.tanh(s["omega_m"]),))[4]
                     for s in sig["load_friction"]],
            "outp": [T._motor_fit(s, (lambda s: np.sin(3 * s["theta_f"] + 0.9) / N,))[4]
                     for s in sig["output_periodic"]],
        }
        print(f"{dur:g} s: {ok}", {k: np.round(v, 4).tolist() for k, v in est.items()}, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
