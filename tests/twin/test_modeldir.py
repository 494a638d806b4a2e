"""The one config.json reader of a twin model directory, and the train/export/plots circle gone."""

import ast
from pathlib import Path

import pytest

from hd_twin.modeldir import MODEL_FORMAT, read_config

SRC = Path(__file__).resolve().parents[2] / "src" / "hd_twin"


def test_read_config_errors_name_the_source(tmp_path):
    with pytest.raises(ValueError, match=r"not a twin model directory \(no config.json\)"):
        read_config(tmp_path)
    (tmp_path / "config.json").write_text("{not json")
    with pytest.raises(ValueError, match="config.json: corrupt JSON"):
        read_config(tmp_path)
    (tmp_path / "config.json").write_text("[1, 2]")
    with pytest.raises(ValueError, match="expected a JSON object, got list"):
        read_config(tmp_path)
    (tmp_path / "config.json").write_text('{"format": "other/9", "model_version": "v"}')
    assert read_config(tmp_path)["model_version"] == "v"
    with pytest.raises(ValueError, match="model format 'other/9'"):
        read_config(tmp_path, check_format=True)
    (tmp_path / "config.json").write_text(f'{{"format": "{MODEL_FORMAT}"}}')
    assert read_config(tmp_path, check_format=True)["format"] == MODEL_FORMAT


def test_every_reader_goes_through_read_config(tmp_path):
    """The twin node and the ground discovery give the reader's error for a directory without config.json."""
    from hd_ground.discovery.pipeline import DiscoveryError, load_twin
    from hd_twin.state import initial_state

    for call, exc in ((lambda: initial_state(str(tmp_path)), ValueError), (lambda: load_twin(tmp_path), DiscoveryError)):
        with pytest.raises(exc, match=r"not a twin model directory \(no config.json\)"):
            call()
    for f in SRC.rglob("*.py"):
        if f.name != "modeldir.py":
            assert "json.loads((" not in f.read_text() or "config.json" not in f.read_text().split("json.loads((", 1)[1][:60], f


def _imports(name: str) -> set[str]:
    tree = ast.parse((SRC / name).read_text())
    out = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom):
            out.add(("." * n.level) + (n.module or ""))
        elif isinstance(n, ast.Import):
            out.update(a.name for a in n.names)
    return out


def test_no_train_export_plots_circle():
    for name in ("modeldir.py", "export.py", "plots.py"):
        imp = _imports(name)
        assert ".train" not in imp and "hd_twin.train" not in imp, name
    assert not {".export", ".plots", "hd_twin.export", "hd_twin.plots"} & _imports("modeldir.py")
