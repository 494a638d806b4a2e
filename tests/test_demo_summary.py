"""The demo's figures are about the replayed actuator: traffic of another ROS 2 graph on the same domain
(seen when tests ran beside a demo on domain 0) is named, not counted."""

from hdphm.demo_cli import _own_actuator


def test_foreign_actuators_are_named_not_counted(capsys):
    summary = {
        "flags": [{"actuator": "EMA-0004", "stamp_s": 6.7, "level": 1, "reason": "twist"},
                  {"actuator": "EMA-T1", "stamp_s": 1.7e9, "level": 1, "reason": "twist"},
                  {"actuator": "EMA-T1", "stamp_s": 1.7e9, "level": 2, "reason": "twist"}],
        "health": {"EMA-0004": {"rul_p50": 3}, "unknown": {"rul_p50": 468}},
        "n_warn": 2, "n_error": 1,
    }
    _own_actuator(summary, "EMA-0004")
    assert summary["n_warn"] == 1 and summary["n_error"] == 0
    assert [f["actuator"] for f in summary["flags"]] == ["EMA-0004"]
    assert summary["foreign_actuators"] == ["EMA-T1", "unknown"]
    assert "another ROS 2 graph" in capsys.readouterr().err


def test_no_note_without_foreign_traffic(capsys):
    summary = {"flags": [{"actuator": "A", "stamp_s": 1.0, "level": 2, "reason": "Q_red"}], "health": {"A": {}}}
    _own_actuator(summary, "A")
    assert summary["n_error"] == 1 and summary["foreign_actuators"] == []
    assert capsys.readouterr().err == ""
