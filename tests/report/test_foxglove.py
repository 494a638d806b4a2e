"""The Foxglove layout check can fail: wrong column label, missing topic, index past the end.

(The check of the shipped layout against a real stack recording is in tests/ros/test_sim_stack.py.)"""

from __future__ import annotations

from mcap_ros2.writer import Writer as Ros2Writer

from hdphm.foxglove import check_layout, layout_paths, load_layout

F64MA = """std_msgs/MultiArrayLayout layout
float64[] data
================================================================================
MSG: std_msgs/MultiArrayLayout
MultiArrayDimension[] dim
uint32 data_offset
================================================================================
MSG: std_msgs/MultiArrayDimension
string label
uint32 size
uint32 stride"""


def _bag(path):
    with open(path, "wb") as f:
        w = Ros2Writer(f)
        s = w.register_msgdef("std_msgs/msg/Float64MultiArray", F64MA)
        msg = {"layout": {"dim": [{"label": "rows", "size": 1, "stride": 3},
                                  {"label": "stamp,Q_red,Q_red_hat", "size": 3, "stride": 3}], "data_offset": 0},
               "data": [1.0, 2.0, 3.0]}
        w.write_message("/hd/onboard/residuals", s, msg, log_time=1, publish_time=1)
        w.finish()
    return path


def _layout(*paths):
    return {"configById": {"Plot!x": {"paths": [{"value": v, "label": l} for v, l in paths]}}}


def test_check_accepts_right_and_names_wrong(tmp_path):
    bag = _bag(tmp_path / "a.mcap")
    assert check_layout(bag, _layout(("/hd/onboard/residuals.data[2]", "Q_red_hat"))) == []
    p = check_layout(bag, _layout(("/hd/onboard/residuals.data[1]", "Q_red_hat")))
    assert len(p) == 1 and "is column 'Q_red'" in p[0]
    p = check_layout(bag, _layout(("/hd/onboard/residuals.data[7]", "level")))
    assert len(p) == 1 and "does not resolve" in p[0]
    p = check_layout(bag, _layout(("/hd/prognostic/health.data[7]", "rul_p50")))
    assert len(p) == 1 and "has no message" in p[0]


def test_shipped_layout_names_the_panels_the_issue_asks_for():
    lay = load_layout()
    kinds = {k.split("!")[0] for k in lay["configById"]}
    assert {"DiagnosticSummary", "DiagnosticStatusPanel", "Plot", "RawMessages"} <= kinds
    topics = {t for t, _f, _l in layout_paths(lay)}
    assert {"/diagnostics", "/hd/joint_states", "/hd/onboard/residuals", "/hd/prognostic/health",
            "/hd/twin/state"} <= topics
