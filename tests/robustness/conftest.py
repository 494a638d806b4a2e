"""Fixtures: foreign-style bags (see ``foreign.py``), generated once per test session and worker."""

from __future__ import annotations

import pytest

from tests.robustness import foreign as FB


@pytest.fixture(scope="session")
def foreign_bags(tmp_path_factory) -> dict:
    """Every variant of :data:`foreign.VARIANTS`, written once: name -> .mcap path."""
    return FB.write_all(tmp_path_factory.mktemp("foreign"))


@pytest.fixture(scope="session")
def foreign_actuator(tmp_path_factory):
    """One actuator as ``ros2 bag`` directories: mission_index 0, 1, 3, 4, 7, 8; names not in mission order."""
    d = tmp_path_factory.mktemp("actuator") / "FX-0100"
    paths = FB.write_actuator(d, writer="rosbags", duration=1.5)
    return d, paths


@pytest.fixture(scope="session")
def foreign_twin(tmp_path_factory):
    """A tiny twin trained (2 epochs) on three foreign bags of distinct seeds and writers, through the CLI."""
    from hdphm.cli import main

    d = tmp_path_factory.mktemp("twin_train")
    FB.write_variant(d / "bags", FB.replace(FB.VARIANTS["rosbags"], name="a"), seed=1, mission_index=0)
    FB.write_variant(d / "bags", FB.replace(FB.VARIANTS["lz4"], name="b"), seed=2, mission_index=1)
    FB.write_variant(d / "bags", FB.replace(FB.VARIANTS["unchunked"], name="c"), seed=3, mission_index=2)
    out = d / "model"
    rc = main(["train", "--preset", "tiny", "--bags", str(d / "bags"), "--epochs", "2", "--threads", "1",
               "--out", str(out)])
    assert rc == 0 and (out / "config.json").is_file() and (out / "twin.onnx").is_file()
    return out
