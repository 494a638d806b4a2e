"""Whole-stack replay speed (``hdphm bench replay``): ``--rate max`` through twin + onboard + prognostic
+ ground + recorder in one process, as a multiple of real time (target >= 20x).

Baseline in the same run: replay alone into a single subscriber that only
counts (the DDS + rclpy floor on this machine), so the ratio shows what the
stack itself costs. The stack run is :func:`hdphm.ros_cli.run_stack_on_bags`
as the demo uses it: every contract message goes through DDS to the onboard
node (counts checked), the recorder files the replayed contract messages
from the replayer (same bytes, per block) and records the stack's own topics
through its subscriptions. ``HDPHM_EXECUTOR=events`` times rclpy's
EventsExecutor instead of the SingleThreadedExecutor.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench replay")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--domain-id", type=int, default=201)
    a = ap.parse_args(argv)
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "onboard"))
    from synth import make_mission

    from hd_bag import write_mission
    from hdphm import rosutil as ru
    from hdphm.ros_cli import Replayer, Stack, run_stack_on_bags

    d = tempfile.mkdtemp()
    bag = os.path.join(d, "m.mcap")
    write_mission(bag, make_mission(duration=a.seconds, seed=0))
    # baseline: replay -> one counting subscriber
    from sensor_msgs.msg import JointState

    st = Stack(a.domain_id, nodes=())
    n = {"v": 0}
    sub = {}

    def cb(first):
        n["v"] += len(ru.take_all(sub["s"], first))

    sub["s"] = st.aux.create_subscription(JointState, ru.TOPIC_JOINT_STATES, cb, ru.qos("sensor"), raw=True)
    rep = Replayer(st.aux, "max", pump=st.pump)
    t0 = time.perf_counter()
    rep.play(bag)
    st.pump(force=True)
    wb = time.perf_counter() - t0
    st.close()
    base = rep.sample_seconds / wb
    s = run_stack_on_bags([bag], out_mcap=os.path.join(d, "rec.mcap"), domain_id=a.domain_id + 1, progress=False)
    print(f"baseline replay->counter: {base:.1f}x real time ({n['v']} msgs)")
    ok = s["received_onboard"] == s["published"]
    print(f"whole stack + recorder: {s['speedup']:.1f}x real time (target >= 20x: {'PASS' if s['speedup'] >= 20 else 'FAIL'}); "
          f"ratio to baseline {base / s['speedup']:.2f}; onboard received every message: {ok}; executor {ru.EXECUTOR}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
