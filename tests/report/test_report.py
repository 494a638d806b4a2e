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
