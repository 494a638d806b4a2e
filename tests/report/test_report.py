"""``hdphm report``: content of the page (no browser needed)."""

from __future__ import annotations

import re

import pytest

from hdphm.cli import main
from hdphm.report import load_run, render, write_report


def test_page_is_self_contained_and_has_every_section(demo_like_run, tmp_path):
    out = write_report(demo_like_run, tmp_path / "r.html")
    page = out.read_text()
    # no network: no external script or stylesheet reference
    assert not re.search(r"<script[^>]+src=['\"]https?:", page)
    assert not re.search(r"<link[^>]+href=['\"]https?:", page)
    assert "Plotly" in page  # plotly.js embedded
    for needle in ("Fleet", "EMA-A", "EMA-B", "held out", "Twin fit", "data:image/png;base64,",
                   "Discovery", "stribeck_friction", "Settings and versions", "alpha = 0.2 cone"):
        assert needle in page, needle
    # three figures for EMA-B (life, flags) + one discovery bar chart
    assert len(re.findall(r'id="hdphm-fig-\d+"', page)) == 3


def test_fleet_table_values(demo_like_run):
    view = load_run(demo_like_run)
    b = view.actuators["EMA-B"]
    assert b.role == "held out" and b.eol_mission == 40 and len(b.flags) == 2
    assert b.suspected_fault == "lubrication loss?"
    assert view.actuators["EMA-A"].role == "training"
    page = render(view)
    row = re.search(r"<tr><td><a href='#act-EMA-B'>EMA-B</a></td>(.*?)</tr>", page).group(1)
    assert "<td>4.0</td>" in row and "<td>0.30</td>" in row  # RUL P50 and risk from the node's last health


def test_bad_inputs_are_named(tmp_path, capsys):
    assert main(["report", str(tmp_path / "nope")]) == 1
    assert "no such run folder" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["report", str(tmp_path / "empty")]) == 1
    assert "nothing to report" in capsys.readouterr().err
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "report.json").write_text("{not json")
    assert main(["report", str(bad)]) == 1
    assert "not valid JSON" in capsys.readouterr().err


def test_cli_json_output(demo_like_run, tmp_path, capsys):
    import json

    assert main(["report", str(demo_like_run), "--out", str(tmp_path / "x.html"), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["report"].endswith("x.html") and d["bytes"] > 1_000_000  # plotly.js inside


def test_report_of_a_fleet_store(small_fleet_dir, tmp_path):
    """The page is made from a fleet store (hdphm ground fleet) through its DuckDB views."""
    pytest.importorskip("duckdb")
    from hd_ground.fleet.tasks import FleetOptions, calibrate_task, mission_task

    bags = sorted(str(p) for p in small_fleet_dir.rglob("*.mcap") if "EMA-0002" in str(p))
    opts = FleetOptions(healthy_missions=1, onboard={"warmup_s": 1.0})
    cal = calibrate_task(bags[:1], opts)
    store = tmp_path / "store"
    for b in bags:
        mission_task(b, str(store), cal, opts)
    view = load_run(store)
    assert view.kind == "fleet store" and view.actuators["EMA-0002"].missions == len(bags)
    page = write_report(store, tmp_path / "fleet.html").read_text()
    assert "<a href='#act-EMA-0002'>EMA-0002</a>" in page


def test_recalibration_history_from_recorded_ground_reports(demo_like_run, tmp_path):
    """The ground node's reports (recalibration at report level, as hd_ground.analysis.analyse_archive writes
    it) are read from a recorded stack MCAP and shown per analysed actuator."""
    import json
    import shutil

    from mcap_ros2.writer import Writer as Ros2Writer

    run = tmp_path / "run"
    shutil.copytree(demo_like_run, run)
    sd = run / "stack_EMA-B"
    sd.mkdir()
    reports = [{"archive_dir": "a", "actuators": {"EMA-A": {"missions": [0, 1]}, "EMA-B": {"missions": [0, 1, 2]}},
                "recalibration": {"estimates": {"T_C": 0.10 + 0.01 * k, "b_visc": 2e-4}, "rows": 3000,
                                  "rms_before": 0.3, "rms_after": 0.2}} for k in range(2)]
    reports.append({"actuators": {"EMA-B": {"missions": [0]}}, "recalibration": {"skipped": "too few rows"}})
    with open(sd / "EMA-B_m0000.mcap", "wb") as f:
        w = Ros2Writer(f)
        s = w.register_msgdef("std_msgs/msg/String", "string data")
        for k, r in enumerate(reports):
            w.write_message("/hd/ground/report", s, {"data": json.dumps(r)}, log_time=k + 1, publish_time=k + 1)
        w.finish()
    view = load_run(run)
    for aid, n in (("EMA-A", 2), ("EMA-B", 3)):
        rows = view.actuators[aid].recalibrations
        assert [r["analysis"] for r in rows] == [0, 1], aid  # the skipped analysis adds no row
        assert [r["T_C"] for r in rows] == [0.10, 0.11] and rows[0]["rms_after"] == 0.2 and rows[0]["missions"] == n
    assert "recalibration history" in render(view)
