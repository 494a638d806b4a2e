"""Issue 13, findings 3 and 4 without ROS: every hostile update is refused by the schema, naming the field,
and the state is unchanged; good updates still apply."""

from __future__ import annotations

import json
import os

import pytest

from hd_twin import state as sv
from hd_twin.state import apply_update, initial_state

from .hostile_updates import HOSTILE_UPDATES


@pytest.fixture(scope="module")
def state0():
    return initial_state()


@pytest.mark.parametrize("name,text,match", HOSTILE_UPDATES, ids=[h[0] for h in HOSTILE_UPDATES])
def test_hostile_update_refused_naming_the_field(state0, name, text, match, tmp_path):
    before = json.dumps(state0, sort_keys=True)
    with pytest.raises(ValueError) as ei:
        upd = sv.parse_json(text, "/hd/twin/update")
        apply_update(state0, upd, "/hd/twin/update", sv.model_roots(str(tmp_path)))
    assert match in str(ei.value), str(ei.value)[:300]
    assert len(str(ei.value)) < 2000  # a refusal never echoes a huge field
    assert json.dumps(state0, sort_keys=True) == before


def test_good_updates_still_apply(state0, tmp_path):
    model = tmp_path / "models" / "twin_v2"
    model.mkdir(parents=True)
    roots = sv.model_roots(str(tmp_path / "models"))
    upd = sv.parse_json(json.dumps({"params": {"N": 50, "notes": {"why": "recalibrated"}}, "effects": ["coulomb_friction"],
                                    "normalisation": {"mean": [1.0, 2.0]}, "degradation_law": {"name": "archard", "k": 1e-9},
                                    "model_dir": str(model), "updated_by": "ground"}), "u")
    new = apply_update(state0, upd, "u", roots)
    assert new["params"]["N"] == 50.0 and new["model_dir"] == str(model) and new["revision"] == 1
    # a symbolic link inside the root that points outside is not inside
    os.symlink("/etc", tmp_path / "models" / "link")
    with pytest.raises(ValueError, match="model_dir"):
        apply_update(state0, {"model_dir": str(tmp_path / "models" / "link")}, "u", roots)
    assert apply_update(state0, {"model_dir": ""}, "u", roots)["model_dir"] == ""


def test_depth_check_runs_on_the_text_before_json_recursion():
    deep = "[" * 1_000_000 + "]" * 1_000_000
    assert sv.json_depth(deep) == 1_000_000
    with pytest.raises(ValueError, match="cap"):
        sv.parse_json('{"a": ' + deep + "}", "u", max_bytes=4 << 20)
    assert sv.json_depth('{"a": "[[[[[[[[[[[["}') == 1  # brackets inside strings do not count


def test_parse_json_msg_of_the_nodes_has_the_same_caps():
    from types import SimpleNamespace

    import hd_ros as ru

    with pytest.raises(ValueError, match="nested"):
        ru.parse_json_msg(SimpleNamespace(data='{"a": ' + "[" * 100 + "]" * 100 + "}"), "/hd/mission")
    with pytest.raises(ValueError, match="cap"):
        ru.parse_json_msg(SimpleNamespace(data='{"a": "' + "x" * (2 << 20) + '"}'), "/hd/mission")
    assert ru.parse_json_msg(SimpleNamespace(data='{"gear_ratio": "101"}'), "/hd/mission") == {"gear_ratio": "101"}


def test_message_class_imports_only_from_the_fixed_package_table(tmp_path, monkeypatch):
    import hd_ros as ru

    (tmp_path / "evilpkg").mkdir()
    marker = tmp_path / "PWNED"
    (tmp_path / "evilpkg" / "__init__.py").write_text("")
    (tmp_path / "evilpkg" / "msg.py").write_text(f"open({str(marker)!r}, 'w')\nclass X: pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for bad in ("evilpkg/msg/X", "evilpkg/X", "os/msg/system", "std_msgs/msg/__class__", "std_msgs/../os/X"):
        with pytest.raises(ValueError):
            ru.message_class(bad)
    assert not marker.exists()
    assert ru.message_class("std_msgs/msg/String").__name__ == "String"


def test_state_growth_by_many_updates_is_bounded(state0):
    """Merged per-actuator entries grow the state update after update: the merged state is capped."""
    big = dict(state0, normalisation={"x": ["y" * 2000] * 4500})  # 9 MB already merged
    with pytest.raises(ValueError, match="state would grow"):
        apply_update(big, {"updated_by": "u"}, "u", [])
    assert apply_update(state0, {"updated_by": "u"}, "u", [])["revision"] == 1


@pytest.mark.parametrize("meta,match", [({"gear_ratio": True}, "gear_ratio"), ({"gear_ratio": "nan"}, "gear_ratio"),
                                        ({"actuator_id": "../../x"}, "actuator_id"), ({"operating_hours": "1e300"}, "hours"),
                                        ({"mission_index": [1]}, "mission_index"), ({"gear_ratio": "0"}, "> 0")])
def test_mission_documents_are_checked(meta, match):
    with pytest.raises(ValueError, match=match):
        sv.check_mission(meta)


def test_replayed_mission_documents_pass(tmp_path):
    from hd_bag import read_metadata, write_mission

    from tests.bag.conftest import make_mission

    p = write_mission(tmp_path / "m.mcap", make_mission())
    meta = dict(read_metadata(p)["hd_mission"], bag=str(p))
    assert sv.check_mission(meta) is meta
