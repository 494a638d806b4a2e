"""Real-time options of the onboard node and `hdphm node` (no privileges assumed: both outcomes are checked)."""
import argparse
import os
import threading

import pytest

from hdphm import ros_cli as rc
import hd_ros as ru
from hd_ros.replay import Replayer


def test_set_thread_realtime_applies_or_says_why():
    with pytest.raises(ValueError, match="outside 0..99"):
        ru.set_thread_realtime(100)
    out = {}

    def worker():  # a thread of its own: the policy never leaks into the test process
        out["why"] = ru.set_thread_realtime(5)
        out["policy"] = os.sched_getscheduler(0) if hasattr(os, "sched_getscheduler") else None
        if not out["why"]:
            out["reset"] = ru.set_thread_realtime(0)
            out["after"] = os.sched_getscheduler(0)

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    if out["why"]:
        assert "SCHED_FIFO" in out["why"]
    else:
        assert out["policy"] == os.SCHED_FIFO and out["reset"] == "" and out["after"] == os.SCHED_OTHER


def test_node_cli_rt_priority_after_the_node_name():
    ap = argparse.ArgumentParser()
    rc.register(ap.add_subparsers())
    a = ap.parse_args(["node", "onboard", "--rt-priority", "40", "--domain-id=7", "--ros-args", "-p", "hold_s:=1.0"])
    rc._pop_domain(a)
    assert (a.rt_priority, a.domain_id, a.ros_args) == (40, 7, ["--ros-args", "-p", "hold_s:=1.0"])
    a = ap.parse_args(["node", "onboard", "--rt-priority", "120"])
    with pytest.raises(SystemExit, match="outside 0..99"):
        rc._pop_domain(a)
    with pytest.raises(ValueError, match="batch"):
        Replayer.__init__(object.__new__(Replayer), None, "max", batch=0)
