"""Whole-stack replay speed (``hdphm bench replay``): ``--rate max`` through twin + onboard + prognostic
+ ground + recorder in one process, as a multiple of real time (target >= 20x).

Every variant is run ``--repeat`` times, interleaved (A B C A B C ...), so the
shared machine's load falls on all of them alike; medians are printed with
their ratios:

- ``baseline``: replay alone into one subscriber that only counts (the DDS +
  rclpy floor of this machine);
- ``stack``: the whole stack as ``run_stack_on_bags`` runs it by default
  (raw payloads to the publisher handles, a pump every 500 messages until the
  onboard node took them all, synchronous publication);
- ``stack, batch 2000`` / ``stack, async publication``: the same with 2000
  messages between pumps / with Fast DDS asynchronous publication (both
  measured slower or no faster here, so not the defaults).

Each stack run is :func:`hdphm.stack.run_stack_on_bags` as the demo uses it:
every contract message goes through DDS to the onboard node (counts checked
on every run), the recorder files the replayed contract messages from the
replayer (same bytes, per block) and records the stack's own topics through
its subscriptions. ``HDPHM_EXECUTOR=events`` times rclpy's EventsExecutor
instead of the SingleThreadedExecutor.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time


def _baseline(bag: str, domain_id: int) -> float:
    from sensor_msgs.msg import JointState

    import hd_ros as ru
    from hd_ros.replay import Replayer
    from hdphm.stack import Stack

    st = Stack(domain_id, nodes=())
    try:
        n = {"v": 0}
        sub = {}

        def cb(first):
            n["v"] += len(ru.take_all(sub["s"], first))

        sub["s"] = st.aux.create_subscription(JointState, ru.TOPIC_JOINT_STATES, cb, ru.qos("sensor"), raw=True)
        rep = Replayer(st.aux, "max", pump=st.pump, batch=2000,
                       drained=lambda: n["v"] >= rep.counts[ru.TOPIC_JOINT_STATES])
        end = time.monotonic() + 15.0
        while time.monotonic() < end and rep.pubs[ru.TOPIC_JOINT_STATES].get_subscription_count() == 0:
            st.ex.spin_once(timeout_sec=0.02)
        t0 = time.perf_counter()
        rep.play(bag)
        st.pump(force=True)
        wb = time.perf_counter() - t0
        if n["v"] != rep.counts[ru.TOPIC_JOINT_STATES]:
            raise RuntimeError(f"baseline subscriber got {n['v']} of {rep.counts[ru.TOPIC_JOINT_STATES]} joint states")
        return rep.sample_seconds / wb
    finally:
        st.close()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench replay")
    ap.add_argument("--seconds", type=float, default=20.0, help="mission length [s] at 1 kHz")
    ap.add_argument("--repeat", type=int, default=3, help="runs of every variant (interleaved)")
    ap.add_argument("--domain-id", type=int, default=201)
    a = ap.parse_args(argv)
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "onboard"))
    from synth import make_mission

    from hd_bag import write_mission
    import hd_ros as ru
    from hdphm.stack import run_stack_on_bags

    d = tempfile.mkdtemp()
    bag = os.path.join(d, "m.mcap")
    write_mission(bag, make_mission(duration=a.seconds, seed=0))
    variants = {
        "baseline": lambda dom: _baseline(bag, dom),
        "stack": lambda dom: _stack(bag, d, dom),
        "stack, batch 2000": lambda dom: _stack(bag, d, dom, replay_batch=2000),
        "stack, async publication": lambda dom: _stack(bag, d, dom, async_publish=True),
    }
    res: dict[str, list[float]] = {k: [] for k in variants}
    dom = a.domain_id
    for r in range(a.repeat):
        for name, fn in variants.items():
            res[name].append(fn(dom))
            dom = 1 + (dom % 230)
            print(f"  run {r + 1}/{a.repeat} {name}: {res[name][-1]:.1f}x real time", file=sys.stderr, flush=True)
    med = {k: statistics.median(v) for k, v in res.items()}
    base = med["baseline"]
    print(f"replay of {a.seconds:.0f} s at 1 kHz, medians of {a.repeat} interleaved runs (executor {ru.EXECUTOR}):")
    for k, v in med.items():
        runs = ", ".join(f"{x:.1f}" for x in res[k])
        extra = "" if k == "baseline" else f"; baseline / this {base / v:.2f}"
        print(f"  {k:<24s} {v:6.1f}x real time (runs {runs}){extra}")
    s = med["stack"]
    print(f"whole stack + recorder (default settings): {s:.1f}x real time (target >= 20x: "
          f"{'PASS' if s >= 20 else 'FAIL'}); {s / base:.2f} of the bare replay in the same run")
    return 0


def _stack(bag: str, d: str, dom: int, **kw) -> float:
    from hdphm.stack import run_stack_on_bags

    s = run_stack_on_bags([bag], out_mcap=os.path.join(d, f"rec{dom}.mcap"), domain_id=dom, progress=False, **kw)
    if s["received_onboard"] != s["published"] or any(s["recorded"][t] != n for t, n in s["published"].items()):
        raise RuntimeError(f"stack run lost messages: published {s['published']}, onboard {s['received_onboard']}, "
                           f"recorded {s['recorded']}")
    os.remove(os.path.join(d, f"rec{dom}.mcap"))
    return s["speedup"]


if __name__ == "__main__":
    sys.exit(main())
