"""Replay of a bag written by another tool (mcap-ros2-support: hd_mission metadata after the chunks)."""

import pytest

pytest.importorskip("rclpy")
from tests.robustness import foreign as FB  # noqa: E402

from hd_ros.replay import BagSource  # noqa: E402
from hdphm.stack import run_stack_on_bags  # noqa: E402

pytestmark = pytest.mark.ros


def test_foreign_bag_metadata_after_chunks_names_the_actuator(tmp_path, domain_id):
    bag = FB.write_variant(tmp_path, FB.VARIANTS["plain"], actuator_id="FX-0042", mission_index=3)
    src = BagSource(bag)
    next(iter(src.blocks()))
    assert src.meta is not None and src.meta["actuator_id"] == "FX-0042"  # known before the first message
    s = run_stack_on_bags([bag], domain_id=domain_id, progress=False)
    assert s["errors"] == []
    assert set(s["health"]) == {"FX-0042"}, s["health"]
    assert s["received_onboard"] == s["published"]
