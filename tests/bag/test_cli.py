"""hdphm validate / inspect exit codes and output."""

from __future__ import annotations

from tests.bag.conftest import make_mission

from hd_bag import write_mission
from hdphm.cli import main as hdphm


def test_validate_exit_codes_and_lines(tmp_path, capsys):
    good = write_mission(tmp_path / "good.mcap", make_mission(n=500))
    m = make_mission(n=500)
    m.omega_m[[3, 4, 5]] = 1e7
    bad = write_mission(tmp_path / "bad.mcap", m)
    (tmp_path / "junk.mcap").write_bytes(b"hello")
    assert hdphm(["validate", good]) == 0
    assert "good.mcap: OK" in capsys.readouterr().out
    assert hdphm(["validate", good, bad, str(tmp_path / "junk.mcap")]) == 1
    out = capsys.readouterr().out
    assert "bad.mcap /hd/joint_states [3]: error: omega_m beyond physical limits" in out
    assert "bad.mcap /hd/joint_states [5]: error" in out
    assert "junk.mcap: error: not an MCAP file" in out
    assert "1/3 bags pass" in out
    assert hdphm(["validate", "--max-per-problem", "1", bad]) == 1
    out = capsys.readouterr().out
    assert "[4]" not in out and "... 2 more samples" in out
    assert hdphm(["validate", str(tmp_path)]) == 1  # a directory: every .mcap in it


def test_inspect(tmp_path, capsys):
    p = write_mission(tmp_path / "m.mcap", make_mission(n=1000))
    assert hdphm(["inspect", p]) == 0
    out = capsys.readouterr().out
    assert "/hd/joint_states" in out and "1000.00 Hz" in out and "gear_ratio = 100.0" in out
