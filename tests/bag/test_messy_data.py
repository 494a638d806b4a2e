"""Dropouts, duplicates, out-of-order stamps, NaN, absurd samples, mixed layouts; streaming writer crash."""

from __future__ import annotations

import numpy as np
import pytest
from tests.bag.conftest import T0_NS, make_mission

from hd_bag import BagError, MissionWriter, read_mission, validate_bag
from hd_bag.mission import MAX_INTERP_GAP_SAMPLES


def _write(path, m, stamps_ns, rows=None, cmd=True, temp=True, **js_overrides):
    """Write joint states in the given (file) order with explicit stamps."""
    sig = {k: getattr(m, k) for k in ("theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red")}
    sig.update(js_overrides)
    idx = np.arange(m.n) if rows is None else rows
    with MissionWriter(path, m.meta) as w:
        w.add_joint_states(stamps_ns, *(np.asarray(sig[k])[idx] for k in sig), log_time_ns=np.arange(len(idx)) + T0_NS)
        if cmd:
            w.add_command(T0_NS + np.round(m.t_cmd * 1e9).astype(np.int64), m.theta_ref)
        if temp:
            w.add_temperature("gearbox", T0_NS + np.round(m.t[::100] * 1e9).astype(np.int64), 20 + 0 * m.t[::100])
    return path


def _stamps(m):
    return T0_NS + np.round(m.t * 1e9).astype(np.int64)


def test_dropouts_marked_segments_split_never_interpolated(tmp_path):
    m = make_mission(n=2000)
    keep = np.ones(m.n, bool)
    keep[100:105] = False  # 5 missing: gap, same segment
    keep[1000:1000 + MAX_INTERP_GAP_SAMPLES + 5] = False  # > 10 missing: new segment
    rows = np.nonzero(keep)[0]
    p = _write(tmp_path / "d.mcap", m, _stamps(m)[rows], rows=rows)
    r = read_mission(p)
    assert r.n == keep.sum()
    assert r.report.gaps == [(100, 5), (995, MAX_INTERP_GAP_SAMPLES + 5)]
    assert r.segment[99] == 0 and r.segment[100] == 0 and r.segment[995] == 1 and r.segment[-1] == 1
    np.testing.assert_array_equal(r.theta_f, m.theta_f[keep])  # nothing invented
    assert any("dropout" in s for s in r.report.notes)
    v = validate_bag(p)
    assert [x.severity for x in v if "dropout" in x.problem] == ["warning"]


def test_duplicates_and_slight_reordering_repaired_and_reported(tmp_path):
    m = make_mission(n=1000)
    rows = np.arange(m.n)
    rows[[10, 11]] = rows[[11, 10]]  # swapped pair
    rows[500:503] = rows[[502, 500, 501]]
    rows = np.concatenate([rows[:700], [699, 699], rows[700:]])  # 699 three times
    s = _stamps(m)[rows]
    p = _write(tmp_path / "o.mcap", m, s, rows=rows)
    r = read_mission(p)
    assert r.n == m.n
    np.testing.assert_array_equal(r.theta_m, m.theta_m)
    assert r.report.n_duplicates == 2
    assert r.report.n_reordered == 3  # 10 after 11, and 500, 501 after 502
    assert any("re-sorted" in s for s in r.report.notes) and any("duplicate" in s for s in r.report.notes)
    v = validate_bag(p)
    dup = [x for x in v if "duplicate" in x.problem]
    assert [x.index for x in dup] == [700, 701] and all(x.severity == "warning" for x in dup)
    assert not [x for x in v if x.severity == "error"]


def test_nan_kept_and_counted(tmp_path):
    m = make_mission(n=1000)
    tau = m.tau_m.copy()
    tau[200:260] = np.nan
    p = _write(tmp_path / "n.mcap", m, _stamps(m), tau_m=tau)
    r = read_mission(p)
    assert np.isnan(r.tau_m[200:260]).all() and np.isfinite(r.tau_m[:200]).all()
    assert r.report.n_nan["tau_m"] == 60 and r.report.n_nan["theta_m"] == 0
    assert not [x for x in validate_bag(p) if x.severity == "error"]


def test_grossly_non_monotonic_stamps_are_fatal(tmp_path):
    m = make_mission(n=1000)
    s = _stamps(m)
    s[600:] -= 2_000_000_000  # clock jumps back 2 s
    p = _write(tmp_path / "j.mcap", m, s)
    with pytest.raises(BagError, match=r"j\.mcap: .*not monotonic.*broken"):
        read_mission(p)
    assert any("not monotonic" in x.problem and x.severity == "error" for x in validate_bag(p))


def test_unset_stamps_are_fatal(tmp_path):
    m = make_mission(n=500)
    p = _write(tmp_path / "z.mcap", m, np.zeros(m.n, np.int64))
    with pytest.raises(BagError, match="distinct header.stamp"):
        read_mission(p)


def test_absurd_samples_nan_and_flagged_many_fatal(tmp_path):
    m = make_mission(n=1000)
    om = m.omega_m.copy()
    om[[5, 17]] = [1e9, -np.inf]
    p = _write(tmp_path / "a.mcap", m, _stamps(m), omega_m=om)
    r = read_mission(p)
    assert np.isnan(r.omega_m[[5, 17]]).all() and np.isfinite(np.delete(r.omega_m, [5, 17])).all()
    v = [x for x in validate_bag(p) if "omega_m" in x.problem]
    assert [x.index for x in v] == [5, 17] and all(x.severity == "error" for x in v)
    om[:100] = 5e4
    p2 = _write(tmp_path / "a2.mcap", m, _stamps(m), omega_m=om)
    with pytest.raises(BagError, match=r"a2\.mcap: .*omega_m beyond physical limits"):
        read_mission(p2)


def test_missing_optional_topics_are_warnings(tmp_path):
    m = make_mission(n=500)
    p = _write(tmp_path / "c.mcap", m, _stamps(m), cmd=False, temp=False)
    r = read_mission(p)
    assert len(r.theta_ref) == 0 and r.temperatures == {}
    assert np.isnan(r.temperature_on_t()).all()
    v = validate_bag(p)
    assert {x.topic for x in v} == {"/hd/command", "/hd/temperature"}
    assert all(x.severity == "warning" for x in v)


def test_names_in_any_order_and_mixed_layouts(tmp_path):
    """Joint order swapped in some messages, an extra joint in others: mapped by name."""
    from hd_bag import cdr

    m = make_mission(n=600)
    s = _stamps(m)
    pos = np.stack([m.theta_m, m.theta_f], 1)
    vel = np.stack([m.omega_m, m.omega_f], 1)
    eff = np.stack([m.tau_m, m.Q_red], 1)
    a = cdr.encode_jointstate(cdr.jointstate_layout(("motor", "output")), s[:200], pos[:200], vel[:200], eff[:200])
    b = cdr.encode_jointstate(cdr.jointstate_layout(("output", "motor")), s[200:400], pos[200:400, ::-1],
                              vel[200:400, ::-1], eff[200:400, ::-1])
    z = np.zeros((200, 1))
    c = cdr.encode_jointstate(cdr.jointstate_layout(("aux", "motor", "output"), "base"), s[400:],
                              np.hstack([z, pos[400:]]), np.hstack([z, vel[400:]]), np.hstack([z, eff[400:]]))
    with MissionWriter(tmp_path / "x.mcap", m.meta) as w:
        # interleave the three layouts inside chunks
        for k in range(0, 200, 50):
            for rows, off in ((a, 0), (b, 200), (c, 400)):
                w.add_rows("/hd/joint_states", rows[k:k + 50], s[off + k:off + k + 50])
        w.add_command(s[::10], m.theta_ref)
        w.add_temperature("gearbox", s[::100], 20 + 0 * s[::100])
    r = read_mission(tmp_path / "x.mcap")
    for k in ("theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red"):
        np.testing.assert_array_equal(getattr(r, k), getattr(m, k))


def test_streaming_writer_killed_mid_run_leaves_readable_file(tmp_path):
    m = make_mission(n=5000)
    s = _stamps(m)
    w = MissionWriter(tmp_path / "k.mcap", m.meta, chunk_seconds=0.5)
    for i in range(0, 3500, 100):  # a recorder adding 100-sample batches
        sl = slice(i, i + 100)
        w.add_joint_states(s[sl], m.theta_m[sl], m.theta_f[sl], m.omega_m[sl], m.omega_f[sl], m.tau_m[sl],
                           m.Q_red[sl])
    w._w._f.flush()
    # process dies: no close(), no summary, and a half-written record at the end
    with open(tmp_path / "k.mcap", "ab") as f:
        f.write(b"\x06" + (10_000).to_bytes(8, "little") + b"\x00" * 100)
    r = read_mission(tmp_path / "k.mcap")
    assert 3000 <= r.n <= 3500  # every complete chunk, nothing after the cut
    np.testing.assert_array_equal(r.theta_m, m.theta_m[:r.n])
    assert any("truncated" in s for s in r.report.notes)
    v = validate_bag(tmp_path / "k.mcap")
    assert any("truncated" in x.problem and x.severity == "error" for x in v)


def _parked(n=8000, rate=1000.0, seed=3):
    """A parked output (held against a load): the 16-bit output encoder toggles between two counts, the motor
    encoder (14 bit) dithers a few counts; the logged speeds are ~0 with their own noise."""
    rng = np.random.default_rng(seed)
    m = make_mission(n=n, rate=rate, seed=seed)
    q_f, q_m = 2 * np.pi / 2**16, 2 * np.pi / 2**14
    th_f = -0.0293 + 0.6 * q_f * np.sin(2 * np.pi * 0.7 * m.t) + 0.3 * q_f * rng.normal(size=n)
    th_m = 100 * -0.0293 + 8 * q_m * np.sin(2 * np.pi * 3 * m.t)
    m.theta_f, m.theta_m = np.round(th_f / q_f) * q_f, np.round(th_m / q_m) * q_m
    m.omega_f = 2e-4 * rng.normal(size=n)
    m.omega_m = 100 * m.omega_f + 2 * np.pi * 3 * 8 * q_m * np.cos(2 * np.pi * 3 * m.t)
    return m


def test_a_parked_axis_toggling_between_encoder_counts_is_not_read_as_a_unit_error(tmp_path):
    """The speed-unit cross-check compares a speed with its angle's difference quotient on moving samples. On a
    parked output the quotient is the encoder's count toggling (+-q / 10 ms) against a speed of ~0: their ratio
    (0.018 on a hysteretic-robot bag of the discovery bench, seed 8500) said nothing about units but was reported
    as suspect data. Below three counts per difference interval an axis is not moving; the same axis logged in
    rpm while it moves is still flagged."""
    m = _parked()
    p = _write(tmp_path / "parked.mcap", m, _stamps(m))
    rep = read_mission(p).report
    assert not [s for s in rep.suspect if "time derivative" in s], rep.suspect
    # the same mission moving, its output speed logged in rpm: flagged with the unit hint
    mv = make_mission(n=8000, seed=3)
    q_f = 2 * np.pi / 2**16
    mv.theta_f = np.round(mv.theta_f / q_f) * q_f
    p2 = _write(tmp_path / "rpm.mcap", mv, _stamps(mv), omega_f=mv.omega_f * 60 / (2 * np.pi))
    rep2 = read_mission(p2).report
    assert any("omega_f" in s and "in rpm?" in s for s in rep2.suspect), rep2.suspect


def _wrap(x):
    return np.mod(x + np.pi, 2 * np.pi) - np.pi


def test_a_single_turn_motor_angle_is_unwrapped_with_its_speed_and_put_back_on_the_output_encoders_turn(tmp_path):
    """A foreign logger that writes the motor angle within one turn (modulo 2 pi; the contract says unwrapped):
    read as it is, the gear-ratio check blamed the metadata (theta_m / theta_f = 6.6) and the speed check the units
    (omega_m 0.005 x the derivative). Each step of a whole turn that omega_m does not show is removed, the angle is
    moved to the output encoder's turn with N, and the mission reads as the unwrapped log did, with a note."""
    m = make_mission(n=4000, seed=5)
    m.theta_m = m.theta_m + 2 * np.pi * 3 * 100  # both encoders three output turns from zero, co-referenced
    m.theta_f = m.theta_f + 2 * np.pi * 3
    ref = read_mission(_write(tmp_path / "unwrapped.mcap", m, _stamps(m)))
    got = read_mission(_write(tmp_path / "wrapped.mcap", m, _stamps(m), theta_m=_wrap(m.theta_m)))
    np.testing.assert_allclose(got.theta_m, ref.theta_m, rtol=0, atol=1e-9)
    assert any("theta_m is logged within one turn" in s for s in got.report.notes), got.report.notes
    assert not got.report.suspect, got.report.suspect
    assert abs(got.report.gear_ratio_encoders - 100) < 1
    assert not [v for v in validate_bag(tmp_path / "wrapped.mcap") if v.severity == "error"]


def test_a_single_turn_output_angle_of_a_multi_turn_joint_is_unwrapped_too(tmp_path):
    """A robot joint turning several output revolutions, its output encoder logged within one turn."""
    m = make_mission(n=4000, seed=6)
    m.theta_f = 3.0 * m.t + 0.2 * np.sin(2 * np.pi * m.t)  # ~2 output turns in 4 s
    m.omega_f = np.gradient(m.theta_f, m.t)
    m.theta_m, m.omega_m = 100 * m.theta_f, 100 * m.omega_f
    ref = read_mission(_write(tmp_path / "u.mcap", m, _stamps(m)))
    got = read_mission(_write(tmp_path / "w.mcap", m, _stamps(m), theta_f=_wrap(m.theta_f)))
    np.testing.assert_allclose(got.theta_f, ref.theta_f, rtol=0, atol=1e-9)
    assert any("theta_f is logged within one turn" in s for s in got.report.notes)


def test_a_jump_the_speed_does_not_explain_as_whole_turns_is_reported_and_left_as_read(tmp_path):
    """A wrapped log with one step that is not a whole turn (a re-homed encoder, a lost count burst) is not a plain
    single-turn log: nothing is changed, the mission is marked suspect with the reason."""
    m = make_mission(n=4000, seed=7)
    w = _wrap(m.theta_m)
    w[2500:] = _wrap(w[2500:] + 2.0)  # the encoder re-zeroed by 2 rad mid-mission
    got = read_mission(_write(tmp_path / "j.mcap", m, _stamps(m), theta_m=w))
    np.testing.assert_array_equal(got.theta_m, w)
    assert any("not a plain single-turn log" in s for s in got.report.suspect), got.report.suspect


@pytest.mark.parametrize("scale, speed_scale, hint", [
    (4.0, 4.0, "electrical radians of a motor with 4 pole pairs"),  # a drive's electrical angle and speed
    (180 / np.pi, 1.0, "theta_m in degrees"),  # angle in degrees, speed in rad/s
    (1.0, 1.0 / 100, None),  # sanity: only the speed off, no angle hint
])
def test_a_motor_angle_in_other_units_is_named_in_the_gear_ratio_error(tmp_path, scale, speed_scale, hint):
    """Another tool's motor angle in electrical radians (pole pairs x mechanical) or in degrees shows as an encoder
    ratio of a fixed multiple of N; the error says which, instead of only blaming the metadata."""
    m = make_mission(n=4000, seed=8)
    p = _write(tmp_path / "u.mcap", m, _stamps(m), theta_m=m.theta_m * scale, omega_m=m.omega_m * speed_scale)
    rep = read_mission(p).report
    ratio = [x for x in rep.suspect if "gear_ratio" in x]
    if hint is None:
        assert not ratio and not any("electrical" in x or "degrees" in x for x in rep.suspect), rep.suspect
    else:
        assert ratio and hint in ratio[0], rep.suspect


def test_an_output_angle_in_degrees_is_named_by_both_cross_checks(tmp_path):
    m = make_mission(n=4000, seed=9)
    p = _write(tmp_path / "deg.mcap", m, _stamps(m), theta_f=np.degrees(m.theta_f))
    sus = read_mission(p).report.suspect
    assert any("gear_ratio" in x and "theta_f in degrees" in x for x in sus), sus
    assert any(x.startswith("omega_f is") and "theta_f in degrees?" in x for x in sus), sus


def test_a_temperature_logged_in_kelvin_is_named(tmp_path):
    """sensor_msgs/Temperature is degrees Celsius; a gearbox at 20 degC logged as 293.15 is inside the reader's
    absurd-value limits but beyond any insulation class: reported as kelvin, suspect, left as read."""
    m = make_mission(n=2000, seed=10)
    p = tmp_path / "k.mcap"
    with MissionWriter(p, m.meta) as w:
        w.add_joint_states(_stamps(m), m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red)
        w.add_temperature("gearbox", T0_NS + np.round(m.t[::100] * 1e9).astype(np.int64), 293.15 + 0 * m.t[::100])
    got = read_mission(p)
    assert any("logged in kelvin?" in x and "20 degC" in x for x in got.report.suspect), got.report.suspect
    np.testing.assert_allclose(got.temperatures["gearbox"][1], 293.15)
    # a hot but plausible winding (150 degC) says nothing
    p2 = tmp_path / "hot.mcap"
    with MissionWriter(p2, m.meta) as w:
        w.add_joint_states(_stamps(m), m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red)
        w.add_temperature("motor_winding", T0_NS + np.round(m.t[::100] * 1e9).astype(np.int64), 150 + 0 * m.t[::100])
    assert not read_mission(p2).report.suspect


def test_a_turn_made_during_a_dropout_of_an_unwrapped_log_says_nothing(tmp_path):
    """An unwrapped log whose motor made an extra turn during a 1 s dropout that the speeds at its ends do not show:
    across a dropout the motion is unknown, so that whole-turn step is no evidence of a single-turn log (it had
    marked the mission suspect); the angle is read as logged."""
    m = make_mission(n=4000, seed=11)
    m.theta_m = m.theta_m + np.where(np.arange(m.n) >= 3000, 2 * np.pi + 0.1, 0.0)
    keep = (np.arange(m.n) < 2000) | (np.arange(m.n) >= 3000)
    rows = np.flatnonzero(keep)
    got = read_mission(_write(tmp_path / "gap.mcap", m, _stamps(m)[rows], rows=rows))
    assert not any("turn" in x for x in got.report.notes + got.report.suspect), got.report.notes
    np.testing.assert_array_equal(got.theta_m, m.theta_m[rows])


@pytest.mark.parametrize("factor, flagged", [(3.0, True), (7.0, True), (1.0, False), (0.7, False)])
def test_a_drives_electrical_speed_beside_the_mechanical_angle_is_named(tmp_path, factor, flagged):
    """Drives often log the electrical speed (pole pairs x mechanical): 3 x the angle's derivative lies inside the
    speed band that a filtered estimate's lag needs (0.25-4) and passed silently; an integer ratio to 2 % is named.
    A speed estimate that reads 0.7 of the derivative (lag) is not."""
    m = make_mission(n=4000, seed=12)
    p = _write(tmp_path / "e.mcap", m, _stamps(m), omega_m=m.omega_m * factor)
    sus = [x for x in read_mission(p).report.suspect if x.startswith("omega_m is")]
    if flagged:
        assert sus and f"motor with {int(factor)} pole pairs?" in sus[0], sus
    else:
        assert not sus, sus
