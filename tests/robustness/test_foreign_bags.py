"""Bags written by other tools, with effects our simulator never made: read, validate, inspect.

Each variant of ``foreign.VARIANTS`` gives either the right data or a clear
error naming the file and the problem (exit status 1), never a traceback.
"""

from __future__ import annotations

import numpy as np
import pytest

from hd_bag import BagError, read_metadata, read_mission, validate_bag
from hdphm.cli import main
from tests.robustness.foreign import VARIANTS

OK = [n for n, v in VARIANTS.items() if v.expect == "ok"]
BAD = [n for n, v in VARIANTS.items() if v.expect == "error"]
FLAGGED = [n for n, v in VARIANTS.items() if v.expect == "flagged"]
#: variants that carry exactly the plain mission (seed 0, 1 kHz, 2 s) in another file form
SAME_AS_PLAIN = ["rosbags", "rosbags_nocomp", "lz4", "uncompressed", "unchunked", "extra_topics", "names_reversed",
                 "meta_sloppy"]


@pytest.mark.parametrize("name", OK)
def test_validate_and_inspect_pass(foreign_bags, name, capsys):
    p = str(foreign_bags[name])
    assert main(["validate", p]) == 0
    out = capsys.readouterr().out
    assert f"{p}: OK" in out
    assert main(["inspect", p]) == 0
    out = capsys.readouterr().out
    assert "/hd/joint_states" in out and "actuator_id = FX-0001" in out


@pytest.mark.parametrize("name", BAD)
def test_broken_bags_give_one_clear_error(foreign_bags, name, capsys):
    p = str(foreign_bags[name])
    assert main(["validate", p]) == 1
    out = capsys.readouterr().out
    assert p in out and VARIANTS[name].match in out
    with pytest.raises(BagError, match=VARIANTS[name].match) as ei:
        read_mission(p)
    assert str(ei.value).startswith(p)
    # every bag-reading command: exit 1 with the file and the problem, no traceback
    assert main(["twin", "eval", "no-such-model-dir", p]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and p in err and VARIANTS[name].match in err


@pytest.mark.parametrize("name", SAME_AS_PLAIN)
def test_other_writers_layouts_and_extra_topics_read_identically(foreign_bags, name):
    a = read_mission(foreign_bags["plain"])
    b = read_mission(foreign_bags[name])
    for k in ("t", "theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red", "t_cmd", "theta_ref"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k), err_msg=f"{name}: {k}")
    assert a.t0_ns == b.t0_ns and a.meta.gear_ratio == b.meta.gear_ratio == 101.0
    assert set(b.temperatures) == set(a.temperatures)


def test_a_single_turn_motor_angle_reads_as_the_unwrapped_log(foreign_bags):
    """theta_m logged modulo 2 pi by another tool reads as the plain bag's angle 40 turns on (unwrapped with
    omega_m, put on the output encoder's turn with N), with a note and nothing suspect; read as it was, the
    gear-ratio and speed checks blamed the metadata and the units."""
    a = read_mission(foreign_bags["plain"])
    b = read_mission(foreign_bags["theta_wrapped"])
    np.testing.assert_allclose(b.theta_m, a.theta_m + 80 * np.pi, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.theta_f, a.theta_f + 80 * np.pi / 101.0, rtol=0, atol=1e-12)
    assert any("theta_m is logged within one turn" in x for x in b.report.notes), b.report.notes
    assert not b.report.suspect, b.report.suspect
    assert abs(b.report.twist_offset - a.report.twist_offset) < 1e-9


def test_extra_topics_are_counted_but_ignored(foreign_bags):
    m = read_mission(foreign_bags["extra_topics"])
    assert m.report.n_messages["/tf"] == 100 and m.report.n_messages["/rosout"] == 8
    assert m.n == 2000 and not m.report.gaps


def test_metadata_written_after_the_chunks_is_found_without_decoding(foreign_bags):
    """mcap-ros2-support and rosbags write metadata records after the messages (read_metadata finds them)."""
    for name in ("plain", "rosbags", "unchunked"):
        md = read_metadata(foreign_bags[name])
        assert md["hd_mission"]["actuator_id"] == "FX-0001"
    assert "rosbag2" in read_metadata(foreign_bags["rosbags"])  # rosbags' own record is there too


def test_sloppy_metadata_values_parse(foreign_bags):
    m = read_mission(foreign_bags["meta_sloppy"])
    assert m.meta.gear_ratio == 101.0 and m.meta.operating_hours == 0.0 and m.meta.extra["rig_serial"] == "B-17"


def test_sample_rates_100hz_and_10khz(foreign_bags):
    m1 = read_mission(foreign_bags["fs100"])
    m2 = read_mission(foreign_bags["fs10k"])
    assert abs(m1.fs - 100.0) < 1e-6 and m1.n == 400 and not m1.report.gaps
    assert abs(m2.fs - 10_000.0) < 1e-3 and m2.n == 6000 and not m2.report.gaps


def test_heavy_jitter_is_not_mistaken_for_dropouts(foreign_bags):
    m = read_mission(foreign_bags["jitter"])
    assert m.n == 2000 and m.report.gaps == [] and int(m.segment.max()) == 0
    assert any("jitter" in s for s in m.report.notes)
    assert np.all(np.diff(m.t) > 0) and abs(m.fs - 1000.0) < 10.0


def test_jitter_does_not_hide_a_real_dropout(foreign_bags, tmp_path):
    from tests.robustness import foreign as FB

    s = FB.v_jitter(FB.make_streams(FB.VARIANTS["plain"]), seed=3)
    keep = np.ones(len(s.js_stamp), bool)
    keep[1000:1005] = False  # 5 samples lost
    p = FB.write_mcap_ros2(tmp_path / "jd.mcap", FB.replace(s, js_stamp=s.js_stamp[keep], js=s.js[keep]))
    m = read_mission(p)
    assert len(m.report.gaps) == 1 and m.report.gaps[0] == (1000, 5)


def test_no_torque_sensor_keeps_nan_and_counts_it(foreign_bags):
    m = read_mission(foreign_bags["no_torque"])
    assert np.isnan(m.Q_red).all() and m.report.n_nan["Q_red"] == m.n
    assert np.isfinite(m.tau_m).all()


def test_temperature_missing_or_1hz_gearbox(foreign_bags, capsys):
    m = read_mission(foreign_bags["no_temp"])
    assert m.temperatures == {} and np.isnan(m.temperature_on_t()).all()
    assert any("/hd/temperature" in v.problem for v in validate_bag(foreign_bags["no_temp"]))
    m = read_mission(foreign_bags["temp_1hz"])
    assert list(m.temperatures) == ["gearbox"] and len(m.temperatures["gearbox"][0]) == 3
    w = m.temperature_on_t("motor_winding")  # falls back to the gearbox sensor, finite everywhere
    assert np.isfinite(w).all()


def test_other_gear_ratios_and_torque_constants(foreign_bags):
    for name, N, kt in (("n50", 50.0, 0.35), ("n160", 160.0, 2.0)):
        m = read_mission(foreign_bags[name])
        assert m.meta.gear_ratio == N and m.meta.torque_constant == kt
        # the transmission relation holds with the bag's N (theta_m = N theta_f + twist)
        assert abs(np.median(m.theta_f - m.theta_m / N)) < 1e-3
        np.testing.assert_allclose(m.i_q, m.tau_m / kt)


def test_motion_profiles(foreign_bags):
    neg = read_mission(foreign_bags["negative"])
    assert neg.theta_f[-1] < -0.2 and np.nanmax(neg.omega_f) < 0.05
    cs = read_mission(foreign_bags["const_speed"])
    assert np.median(cs.omega_f) == pytest.approx(np.radians(15.0), rel=0.1)
    st = read_mission(foreign_bags["standstill"])
    assert np.ptp(st.theta_f) < 0.01


def test_short_mission(foreign_bags):
    m = read_mission(foreign_bags["short"])
    assert m.n == 500 and m.duration == pytest.approx(0.499)


def test_two_second_dropout_splits_segments(foreign_bags):
    m = read_mission(foreign_bags["dropout"])
    assert m.n == 3000 and int(m.segment.max()) == 1
    assert len(m.report.gaps) == 1 and 1990 <= m.report.gaps[0][1] <= 2001
    assert np.diff(m.t).max() == pytest.approx(2.0, abs=0.002)


def test_duplicates_and_disorder_repaired(foreign_bags):
    m = read_mission(foreign_bags["dup_disorder"])
    ref = read_mission(foreign_bags["plain"])
    assert m.report.n_duplicates == 40 and m.report.n_reordered > 0
    np.testing.assert_array_equal(m.t, ref.t)
    np.testing.assert_array_equal(m.theta_m, ref.theta_m)


def test_large_co_referenced_angles_read_exactly(foreign_bags):
    m = read_mission(foreign_bags["theta_large"])
    ref = read_mission(foreign_bags["plain"])
    np.testing.assert_allclose(m.theta_m - 1e4, ref.theta_m, atol=1e-9)
    assert abs(m.report.twist_offset) < 1e-3
    assert [v for v in validate_bag(foreign_bags["theta_large"]) if v.severity == "error"] == []


@pytest.mark.parametrize("name", FLAGGED)
def test_unit_sign_and_reference_errors_are_flagged(foreign_bags, name, capsys):
    """Readable, but the signals contradict each other: validate error (exit 1), report.suspect says why."""
    p = str(foreign_bags[name])
    m = read_mission(p)
    assert any(VARIANTS[name].match in x for x in m.report.suspect), m.report.suspect
    # the Q_red sign against the wind-up is physics, not written on the contract page: a warning
    assert main(["validate", p]) == (0 if name == "torque_sign" else 1)
    out = capsys.readouterr().out
    assert VARIANTS[name].match in out and p in out


def test_consistency_checks_stay_quiet_on_good_bags(foreign_bags):
    for name in OK:
        assert read_mission(foreign_bags[name]).report.suspect == [], name


def test_encoders_without_common_zero_are_flagged(foreign_bags, capsys):
    p = str(foreign_bags["theta_offset"])
    m = read_mission(p)  # readable: the signals themselves are fine
    assert m.report.twist_offset == pytest.approx(-(1e4 + 0.1234) / 101.0, abs=1e-3)
    assert any("common zero" in s for s in m.report.notes)
    assert main(["validate", p]) == 1
    assert "common zero" in capsys.readouterr().out
