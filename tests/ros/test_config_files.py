"""ros2_ws/config/<node>.yaml: every key is a parameter the node declares, every value its default
(the YAML documents the defaults; a drift means the file and the code disagree). Nodes may set
deployment-only values in the YAML: those are listed here on purpose."""

import importlib
from pathlib import Path

import pytest
import yaml

CONFIG = Path(__file__).resolve().parents[2] / "ros2_ws" / "config"
# deliberate deployment values that differ from the in-process defaults
DEPLOYMENT = {("onboard", "rt_thread")}


@pytest.mark.parametrize("node", ["onboard", "twin", "prognostic", "ground"])
def test_yaml_matches_declared_defaults(node):
    mod = importlib.import_module({"onboard": "hd_onboard.node", "twin": "hd_twin.node",
                                   "prognostic": "hd_prognostic.node", "ground": "hd_ground.node"}[node])
    doc = yaml.safe_load((CONFIG / f"{node}.yaml").read_text())
    params = doc[mod.NODE_NAME]["ros__parameters"]
    unknown = sorted(set(params) - set(mod.PARAMS))
    assert not unknown, f"{node}.yaml names parameters the node does not declare: {unknown}"
    differ = {k: (v, mod.PARAMS[k]) for k, v in params.items()
              if (node, k) not in DEPLOYMENT and v != mod.PARAMS[k]}
    assert not differ, f"{node}.yaml values differ from the node's defaults (yaml, code): {differ}"
