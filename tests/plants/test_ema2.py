"""The independent plant (tests/plants/ema2.py): contract bags, base physics, one check per effect, fleets.

The checks per effect fit the plant's own laws by least squares on the *recorded* signals (what a
bag holds) and compare the fitted effect parameter with the truth, and with zero on the clean case:
they show that each effect is present, in the signal it should be, at the size it was set to.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.plants import ema2

PLANT = Path(ema2.__file__)
REPO = PLANT.parents[2]


def test_plant_imports_nothing_of_ours():
    allowed = set(sys.stdlib_module_names) | {"numpy", "scipy", "mcap", "mcap_ros2"}
    ours = {p.name for p in (REPO / "src").iterdir() if p.is_dir()} | {"tests"}
    found = set()
    for node in ast.walk(ast.parse(PLANT.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, "relative import in the independent plant"
            found.add(node.module.split(".")[0])
    assert found, "no imports parsed"
    assert not found & ours, f"the independent plant imports our code: {sorted(found & ours)}"
    assert found <= allowed, f"unexpected imports: {sorted(found - allowed)}"


def _check_bag(path, expect_effect_hidden=True):
    from hd_bag import read_mission, validate_bag

    vs = validate_bag(path)
    assert not vs, "\n".join(str(v) for v in vs[:10])
    m = read_mission(path, include_sim=True)
    assert not m.report.suspect, m.report.suspect
    assert not m.report.notes, m.report.notes
    assert not m.sim, "truth leaked into a bag"
    assert m.meta.source == "simulation" and m.meta.gear_ratio == ema2.BASE["N"]
    assert 990 < m.fs < 1010
    assert len(m.temperature_on_t()) == m.n
    if expect_effect_hidden:
        raw = Path(path).read_bytes()
        for name in ema2.EFFECTS:
            if name != "clean":
                assert name.encode() not in raw, f"effect name {name} written into {path}"
    return m


def test_case_bags_pass_validate_and_read_as_written(plant2_case_bags):
    case = plant2_case_bags("clean")
    assert len(case["bags"]) == ema2.CASE_MISSIONS and case["held_out"] == case["bags"][-1]
    for b, s in zip(case["bags"], case["signals"]):
        m = _check_bag(b)
        for k in ("theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red"):
            np.testing.assert_array_equal(m.signal(k), s[k])
        np.testing.assert_array_equal(m.theta_ref_on_t(), s["theta_ref"])
    case = plant2_case_bags("dead_zone")  # another effect: same contract
    _check_bag(case["held_out"])
    assert json.loads(case["truth_path"].read_text())["effect_params"]["dead_zone"] == 2e-4


def _fit(X, y):
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    return coef


def _motor_fit(s, extra=()):
    """tau_m = J_m omega_m' + Q_red / N + F_c tanh(omega_m / v_t) + b omega_m + extra, least squares."""
    return _fit(*_motor_rows(s, extra))


def _motor_rows(s, extra=()):
    p = ema2.BASE
    N, fs = p["N"], 1000.0
    wm = s["omega_m"]
    acc = np.gradient(wm, 1 / fs)
    ok = np.abs(acc) < 3000  # drop the few encoder-step spikes of the speed estimate
    cols = [acc, s["Q_red"] / N, np.tanh(wm / p["v_t"]), wm] + [c(s) for c in extra]
    # the same zero-phase low-pass on both sides: the 1 kHz central difference is biased for the
    # transmission resonance (~90 Hz) and the speed-loop content, which would leak into the other terms
    return _lp(np.stack(cols, 1))[ok], _lp(s["tau_m"])[ok]


def _lp(x, fc=20.0, fs=1000.0):
    from scipy.signal import butter, filtfilt

    b, a = butter(4, fc / (fs / 2))
    return filtfilt(b, a, x, axis=0)


def test_base_physics_tracking_and_torque_balance(plant2_case_bags):
    p = ema2.BASE
    for s in plant2_case_bags("clean")["signals"]:
        # the position loop follows the command (flap angle, rad)
        assert np.sqrt(np.mean((s["theta_f"] - s["theta_ref"]) ** 2)) < 2e-3
        assert np.ptp(s["theta_ref"]) > 0.3 and (s["omega_m"] > 20).any() and (s["omega_m"] < -20).any()
        # theta_m = N theta_f + twist, twist small and of the sign of Q_red
        twist = s["theta_m"] / p["N"] - s["theta_f"]
        assert np.max(np.abs(twist)) < 5e-3 and np.corrcoef(twist, s["Q_red"])[0, 1] > 0.95
        # motor balance: tau_m N - Q_red is friction (Coulomb + viscous) plus inertia
        J, a, Fc, b = _motor_fit(s)
        assert a == pytest.approx(1.0, abs=0.005)
        assert Fc == pytest.approx(p["F_c"], rel=0.05)
        assert b == pytest.approx(p["b_ref"], rel=0.06)
        assert J == pytest.approx(p["J_m"], rel=0.05)
        # near-constant speed: N tau_m - Q_red is the friction N (F_c sign(omega) + b omega), nothing else
        acc = np.gradient(_lp(s["omega_m"]), 1e-3)
        steady = (np.abs(s["omega_m"]) > 20) & (np.abs(acc) < 100)
        loss = s["tau_m"][steady] * p["N"] - s["Q_red"][steady]
        model = p["N"] * (p["F_c"] * np.sign(s["omega_m"][steady]) + p["b_ref"] * s["omega_m"][steady])
        assert steady.sum() > 200
        assert np.median(np.abs(loss - model)) < 0.25 * np.median(np.abs(model))


def _ripple(s):
    return np.cos(2 * s["theta_m"])


def _rippls(s):
    return np.sin(2 * s["theta_m"])


def _amp(c):
    return float(np.hypot(c[0], c[1]))


def test_each_effect_shows_in_its_signal_at_its_size(plant2_case_bags):
    P, E = ema2.BASE, ema2.EFFECTS
    N = P["N"]

    def sigs(e):
        # the signals are simulated for every effect at once; bags of these are written only when asked for
        return plant2_case_bags.signals(e)

    def motor_coef(e, extra):
        return np.array([_motor_fit(s, extra)[4:] for s in sigs(e)])

    # (1) 2/rev motor torque ripple: tau_m carries -A cos(2 theta_m + phase) (the motor fights it)
    for e in ("ripple", "ripple_weak", "ripple_temp_viscosity", "clean"):
        amp = np.mean([_amp(c) for c in motor_coef(e, (_ripple, _rippls))])
        want = E[e].get("ripple_amp", 0.0)
        assert amp == pytest.approx(want, abs=0.08 * want + 0.0015), e
    # (2) temperature-dependent viscosity b(T) = b_ref exp(-c (T - T_ref)): c by profile least squares over
    #     the four missions pooled (they start at different temperatures and warm up)
    grid = np.linspace(-0.02, 0.06, 17)
    for e in ("temp_viscosity", "ripple_temp_viscosity", "clean"):
        base, ys, wT = [], [], []
        for s in sigs(e):
            Xs, y = _motor_rows(s, (_ripple, _rippls))
            ok = np.abs(np.gradient(s["omega_m"], 1e-3)) < 3000  # the rows _motor_rows keeps
            T = np.interp(s["t"], s["t_temp"], s["temperature"])
            base.append(np.delete(Xs, 3, 1))  # the plain viscous column is replaced by b(T) omega
            ys.append(y)
            wT.append((s["omega_m"], T - P["T_ref"], ok))
        X0, y = np.concatenate(base), np.concatenate(ys)
        sse = []
        for c in grid:
            col = np.concatenate([_lp(w * np.exp(-c * dT))[ok] for w, dT, ok in wT])
            X = np.column_stack([X0, col])
            sse.append(np.sum((y - X @ _fit(X, y)) ** 2))
        c_hat = grid[int(np.argmin(sse))]
        want = E[e].get("visc_temp_coeff", 0.0)
        assert c_hat == pytest.approx(want, abs=0.006), (e, c_hat)
    # (3) Stribeck rise at low motor speed
    strib = (lambda s: np.exp(-(s["omega_m"] / 5.0) ** 2) * np.tanh(s["omega_m"] / P["v_t"]),)
    for e, want in (("stribeck", E["stribeck"]["stribeck_rise"]), ("clean", 0.0)):
        c = np.median(motor_coef(e, strib)[:, 0])
        assert c == pytest.approx(want, abs=0.1 * want + 0.004), e
    # (4) load-dependent friction
    load = (lambda s: np.abs(s["Q_red"]) / N * np.tanh(s["omega_m"] / P["v_t"]),)
    for e, want in (("load_friction", E["load_friction"]["load_friction"]), ("clean", 0.0)):
        c = np.median(motor_coef(e, load)[:, 0])
        assert c == pytest.approx(want, abs=0.08 * want + 0.003), e
    # (5) torque periodic in the output angle (3/rev over a 0.14-rev stroke), reflected to the motor
    outp = (lambda s: np.sin(3 * s["theta_f"] + 0.9) / N,)
    for e, want in (("output_periodic", E["output_periodic"]["out_amp"]), ("clean", 0.0)):
        c = np.median(motor_coef(e, outp)[:, 0])
        assert c == pytest.approx(want, abs=0.05 * want + 0.4), e
        assert max(np.ptp(s["theta_f"]) for s in sigs(e)) / (2 * np.pi) < 0.15  # stroke: no full period
    # (6) dead zone in the twist -> Q_red relation: twist = Q/k1 - k3 Q^3/k1^4 + b sign(Q)
    for e, want in (("dead_zone", E["dead_zone"]["dead_zone"]), ("clean", 0.0)):
        bs = []
        for s in sigs(e):
            Q = s["Q_red"]
            ok = np.abs(Q) > 10
            w = s["theta_m"] / N - s["theta_f"]
            bs.append(_fit(np.stack([Q, Q ** 3, np.sign(Q)], 1)[ok], w[ok])[2])
        assert np.median(bs) == pytest.approx(want, abs=0.12 * want + 2e-5), e
    # (7) stiffness periodic in the wave-generator angle (2/rev): Q = k1 (1 + eps cos(2 theta_m + psi)) w + k3 w^3
    for e, want in (("position_stiffness", E["position_stiffness"]["stiff_mod"]), ("clean", 0.0)):
        eps = []
        for s in sigs(e):
            w = s["theta_m"] / N - s["theta_f"]
            X = np.stack([w, w ** 3, w * np.cos(2 * s["theta_m"]), w * np.sin(2 * s["theta_m"]),
                          np.gradient(w, 1e-3)], 1)
            c = _fit(X, s["Q_red"])
            eps.append(np.hypot(c[2], c[3]) / c[0])
        assert np.median(eps) == pytest.approx(want, abs=0.05 * want + 0.005), e
    # the Q_red-side effects leave the motor side alone and vice versa (the signal map is right)
    assert ema2.EFFECT_SIGNAL["dead_zone"] == "Q_red" and ema2.EFFECT_SIGNAL["ripple"] == "tau_m"


def test_fleet_fails_at_truth_threshold_and_events_match(plant2_fleet):
    from hd_bag import read_mission

    d, events, truth = plant2_fleet["dir"], plant2_fleet["events"], plant2_fleet["truth"]
    fail = {r["actuator_id"]: int(r["mission_index"]) for r in events if r["event"] == "failure"}
    removal = {r["actuator_id"]: int(r["mission_index"]) for r in events if r["event"] == "removal"}
    assert len(fail) >= 2, "the small fleet should see failures"
    assert set(r["event"] for r in events) <= {"failure", "removal", "inspection"}
    for u in truth["units"]:
        uid, ms = u["actuator_id"], u["missions"]
        bags = sorted((d / uid).glob("mission_*.mcap"))
        assert len(bags) == len(ms)
        wear_start = [m["wear_start"] for m in ms]
        assert all(np.diff(wear_start) > 0)
        if u["failure_mission"] is None:
            assert uid not in fail and ms[-1]["wear_end"] < u["threshold"]
            if u["removal_mission"] is not None:  # removed healthy at the start of that mission: censored
                assert removal[uid] == u["removal_mission"] == len(bags)
            continue
        assert uid not in removal
        f = u["failure_mission"]
        assert fail[uid] == f == len(bags)  # found failed at the start of mission f: flew 0..f-1
        assert ms[-1]["wear_end"] >= u["threshold"] > ms[-1]["wear_start"]
        # wear is visible: lost motion grows, stiffness falls, friction rises
        assert ms[-1]["lost_motion"] > ms[0]["lost_motion"] and ms[-1]["k1"] < ms[0]["k1"]
        assert ms[-1]["F_c"] > ms[0]["F_c"]
        for r in events:
            if r["actuator_id"] == uid and r["event"] == "inspection":
                m = ms[int(r["mission_index"])]
                want = m["lost_motion"] if r["quantity"] == "lost_motion" else m["k1"]
                assert float(r["value"]) == pytest.approx(want, rel=0.1, abs=3e-5)
        # observable from the bags alone: the lost motion fitted on the twist grows from first to last mission
        b = []
        for path in (bags[0], bags[-1]):
            m = _check_bag(path)
            Q = m.signal("Q_red")
            ok = np.abs(Q) > 10
            w = m.signal("theta_m") / m.meta.gear_ratio - m.signal("theta_f")
            b.append(_fit(np.stack([Q, Q ** 3, np.sign(Q)], 1)[ok], w[ok])[2])
        assert b[1] > b[0] + 2e-5, (uid, b)


def test_cli_mission_writes_a_valid_bag(tmp_path):
    out = tmp_path / "x.mcap"
    r = subprocess.run([sys.executable, "-m", "tests.plants.ema2", "mission", "--effect", "ripple", "--duration",
                        "1.5", "--seed", "5", "--out", str(out), "--truth", str(tmp_path / "t.json")],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    m = _check_bag(out)
    assert json.loads((tmp_path / "t.json").read_text())["effect"]["ripple_amp"] == 0.04
    # an independent decoder (mcap-ros2-support's own reader) agrees with ours on every joint-state message
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(out, "rb") as f:
        rd = make_reader(f, decoder_factories=[DecoderFactory()])
        js = [msg for _, _, _, msg in rd.iter_decoded_messages(topics=["/hd/joint_states"])]
    assert len(js) == m.n and list(js[0].name) == ["motor", "output"]
    np.testing.assert_array_equal([x.position[0] for x in js], m.signal("theta_m"))
    np.testing.assert_array_equal([x.effort[1] for x in js], m.signal("Q_red"))
    assert js[7].header.stamp.nanosec == 7_000_000
