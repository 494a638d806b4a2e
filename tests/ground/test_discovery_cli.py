"""`hdphm discover` end to end on contract bags written to disk, and a clear error on a bad path."""

import json

from hd_bag import write_mission
from hdphm.cli import main


def test_cli_on_bags_writes_report_plots_and_new_twin(tmp_path, make_mission):
    eff = {"cogging_torque": (0.04, 12, 0.3)}
    for i in range(2):
        write_mission(tmp_path / f"m{i}.mcap", make_mission(i, effects=eff, T=8.0, index=i))
    out = tmp_path / "out"
    assert main(["discover", str(tmp_path / "m0.mcap"), str(tmp_path / "m1.mcap"), "--out", str(out)]) == 0
    rep = json.loads((out / "report.json").read_text())
    for k in ("signal", "error_before", "error_after", "effects", "declared_before", "declared_after"):
        assert k in rep
    assert rep["effects"][0]["name"] == "cogging_torque" and rep["effects"][0]["order"] == 12
    assert rep["error_after"]["rmse"] < 0.5 * rep["error_before"]["rmse"]
    assert (out / "tau_m_order_spectrum.png").stat().st_size > 0
    assert "cogging_torque" in json.loads((out / "twin" / "config.json").read_text())["declared_effects"]


def test_cli_names_a_missing_bag(tmp_path, capsys):
    assert main(["discover", str(tmp_path / "nope.mcap"), "--out", str(tmp_path / "o")]) == 1
    assert "nope.mcap" in capsys.readouterr().err
