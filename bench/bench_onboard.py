"""Onboard throughput and latency (``hdphm bench onboard``).

1. Core throughput: samples/s through conditioning + expected response +
   residuals + detector + windows, in blocks of 1000 (target >= 10 kS/s on
   one core), for the physics-only stand-in and, with ``--model-dir``, the
   ONNX twin, the latter in both streaming modes (``OnboardConfig.twin_fixed_lag``: fixed lag, the
   default, and causal) in the same run.
2. Core per-sample latency at 1 kHz (one sample per call, as at real time):
   the baseline is the block path fed one-row blocks (what the node did
   before the short path), measured in the same run on the same samples;
   then the short path ``OnboardCore.push_one`` with windows closed inline
   and with windows deferred (as the node runs it).
3. Node latency message -> flag decision at 1 kHz: a publisher process sends
   JointStates at 1 kHz whose header stamp is the wall clock at publish; the
   onboard node (``latency_probe``) records wall clock - stamp after the
   level of each sample is decided (and its flag, if any, published). The
   baseline in the same run is a subscriber that only records the arrival
   (the DDS + rclpy floor of this machine).

Prints medians / p99 and the ratios; target p99 < 2 ms.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import textwrap
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))

PUBLISHER = textwrap.dedent('''
    import sys, time
    sys.path.insert(0, {synth!r})
    import numpy as np
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import JointState
    from synth import make_mission
    import hd_ros as ru
    ctx = ru.init_context({domain})
    node = Node("bench_pub", context=ctx)
    pub = node.create_publisher(JointState, ru.TOPIC_JOINT_STATES, ru.qos("sensor"))
    m = make_mission(duration={seconds}, seed=0)
    V = np.column_stack([m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red]).tolist()
    t_end = time.monotonic() + 10.0
    while pub.get_subscription_count() < {n_subs} and time.monotonic() < t_end:
        time.sleep(0.05)
    time.sleep(0.5)
    msg = JointState(); msg.name = ["motor", "output"]; msg.header.frame_id = "EMA-BENCH"
    t0 = time.perf_counter()
    for i, v in enumerate(V):
        due = t0 + i * 1e-3
        d = due - time.perf_counter()
        if d > 0:
            time.sleep(d)
        ns = time.time_ns()
        msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10**9, ns % 10**9
        msg.position, msg.velocity, msg.effort = v[0:2], v[2:4], v[4:6]
        pub.publish(msg)
    time.sleep(0.5)
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)
''')


def _pct(a, q) -> float:
    return float(np.percentile(np.asarray(a, float), q)) * 1e3 if len(a) else float("nan")


def core_bench(a) -> None:
    sys.path.insert(0, os.path.join(HERE, "..", "tests", "onboard"))
    from synth import make_mission

    from hd_onboard.batch import run_mission
    from hd_onboard.config import OnboardConfig
    from hd_onboard.core import OnboardCore
    from hd_onboard.windows import window_row
    from hd_onboard.expected import make_expected
    from hd_onboard.features import window_feature_fn
    from hd_twin import physics as ph

    m = make_mission(duration=a.seconds, seed=0, fault_at=a.seconds * 0.7)
    stamps = m.t0_ns + np.round(m.t * 1e9).astype(np.int64)
    V = np.column_stack([m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red])
    ff = window_feature_fn({}, m.meta.gear_ratio)
    kinds = [("standin", "", True)] + ([("onnx fixed-lag", a.model_dir, True), ("onnx causal", a.model_dir, False)]
                                       if a.model_dir else [])
    for kind, md, lag in kinds:
        p = ph.TwinParams.from_yaml().with_meta(gear_ratio=m.meta.gear_ratio)
        cfg = OnboardConfig(twin_fixed_lag=lag)
        ts = []
        for _ in range(a.repeat):
            core = OnboardCore(make_expected(md or None, p, fs_hz=1000.0), p, feature_fn=ff, config=cfg)
            t0 = time.perf_counter()
            run_mission(m, core, block=1000)
            ts.append(time.perf_counter() - t0)
        thr = m.n / np.median(ts)
        print(f"[core {kind}] throughput, blocks of 1000, features on: median {thr / 1e3:.1f} kS/s "
              f"(target >= 10 kS/s: {'PASS' if thr >= 1e4 else 'FAIL'})")
        n = min(m.n, int(a.latency_samples))
        sl, vl = stamps[:n].tolist(), V[:n].tolist()
        # baseline: the block path, one-row blocks, windows inline
        core = OnboardCore(make_expected(md or None, p, fs_hz=1000.0), p, feature_fn=ff, config=cfg)
        lb = np.empty(n)
        for i in range(n):
            t0 = time.perf_counter()
            core.push(stamps[i:i + 1], V[i:i + 1])
            lb[i] = time.perf_counter() - t0
        res = {}
        for defer in (False, True):
            core = OnboardCore(make_expected(md or None, p, fs_hz=1000.0), p, feature_fn=ff, config=cfg)
            core.defer_windows = defer
            ls = np.empty(n)
            for i in range(n):
                t0 = time.perf_counter()
                core.push_one(sl[i], vl[i])
                ls[i] = time.perf_counter() - t0
            if defer:
                [window_row(j, ff) for j in core.take_window_jobs()]
            res[defer] = ls
        print(f"[core {kind}] per-sample latency over {n} samples: baseline one-row block p50 {_pct(lb, 50):.3f} ms, "
              f"p99 {_pct(lb, 99):.3f} ms | short path, windows inline: p50 {_pct(res[False], 50):.3f} ms, "
              f"p99 {_pct(res[False], 99):.3f} ms, max {res[False].max() * 1e3:.1f} ms | short path, windows deferred: "
              f"p50 {_pct(res[True], 50):.3f} ms, p99 {_pct(res[True], 99):.3f} ms, max {res[True].max() * 1e3:.1f} ms | "
              f"p50 ratio baseline/short {np.median(lb) / np.median(res[True]):.0f}x")


def node_bench(a) -> None:
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from hd_onboard.node import make_node
    import hd_ros as ru

    synth = os.path.join(HERE, "..", "tests", "onboard")
    out = {}
    modes = ("baseline", "onboard", "onboard_rt", "baseline_fifo", "onboard_rt_fifo", "onboard_rt_inline_fifo")
    fifo_ok = ""
    for k, mode in enumerate(modes):
        dom = a.domain_id + k
        fifo = mode.endswith("_fifo")
        inline = "_inline" in mode
        if fifo:  # as `hdphm node onboard --rt-priority`: the middleware's threads inherit SCHED_FIFO
            fifo_ok = ru.set_thread_realtime(a.rt_priority)
            if fifo_ok:
                print(f"[node] {mode} skipped: {fifo_ok}")
                continue
        ctx = ru.init_context(dom)
        ex = ru.make_executor(ctx)
        lat: list[int] = []
        if mode.startswith("baseline"):
            node = Node("bench_counter", context=ctx)
            holder = {}

            def cb(first):
                for b in ru.take_all(holder["s"], first):
                    s = ru.decode_joint_state(b)[0]
                    lat.append(time.time_ns() - s)

            holder["s"] = node.create_subscription(JointState, ru.TOPIC_JOINT_STATES, cb, ru.qos("sensor"), raw=True)
        else:
            node = make_node(context=ctx, overrides={"latency_probe": True, "actuator_id": "EMA-BENCH",
                                                     "rt_thread": mode.startswith("onboard_rt"),
                                                     "rt_priority": a.rt_priority if fifo else 0,
                                                     "feature_thread": not inline})
            lat = node.latency_ns
        ex.add_node(node)
        if fifo:
            ru.set_thread_realtime(0)  # the main thread (timers, twin state) back to normal; the node's threads keep it
        env = dict(os.environ)
        proc = subprocess.Popen([sys.executable, "-c", PUBLISHER.format(synth=synth, domain=dom, seconds=a.node_seconds,
                                                                        n_subs=1)], env=env)
        try:
            while proc.poll() is None:
                ex.spin_once(timeout_sec=0.05)
            for _ in range(20):
                ex.spin_once(timeout_sec=0.01)
        finally:
            if proc.poll() is None:
                proc.kill()
            node.destroy_node()
            ex.shutdown()
            import rclpy

            rclpy.try_shutdown(context=ctx)
        out[mode] = np.asarray(lat, float) * 1e-9
        if os.environ.get("HDPHM_BENCH_DUMP"):
            np.save(os.path.join(os.environ["HDPHM_BENCH_DUMP"], f"lat_{mode}.npy"), out[mode])
        if not mode.startswith("baseline"):
            out[mode + "_windows"] = node.n_published[ru.TOPIC_FEATURES]
    for bm in ("baseline", "baseline_fifo"):
        if bm in out:
            b = out[bm]
            print(f"[node] 1 kHz publisher process -> subscriber: {bm} (receive only{', SCHED_FIFO' if 'fifo' in bm else ''}) "
                  f"n={len(b)} p50 {_pct(b, 50):.3f} ms, p99 {_pct(b, 99):.3f} ms")
    for mode, what in (("onboard", "one executor"), ("onboard_rt", "rt_thread: joint states on their own executor thread"),
                       ("onboard_rt_fifo", f"rt_thread + SCHED_FIFO {a.rt_priority} for it and the middleware threads"),
                       ("onboard_rt_inline_fifo", "the same, window features on the joint-state thread after the flag "
                                                  "(feature_thread false: no other Python thread holds the GIL)")):
        if mode not in out:
            continue
        b = out["baseline_fifo" if mode.endswith("fifo") else "baseline"]
        o = out[mode]
        p99 = _pct(o, 99)
        print(f"[node] onboard node ({what}; decode + short path + flag publish) n={len(o)} p50 {_pct(o, 50):.3f} ms, "
              f"p99 {p99:.3f} ms, max {o.max() * 1e3 if len(o) else float('nan'):.1f} ms (target p99 < 2 ms: "
              f"{'PASS' if p99 < 2.0 else 'FAIL'}); p99 ratio to baseline {p99 / max(_pct(b, 99), 1e-9):.2f}; "
              f"feature messages {out[mode + '_windows']}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench onboard")
    ap.add_argument("--seconds", type=float, default=20.0, help="mission length [s] at 1 kHz (core benchmarks)")
    ap.add_argument("--latency-samples", type=int, default=20000)
    ap.add_argument("--node-seconds", type=float, default=10.0, help="length of the 1 kHz node stream [s]")
    ap.add_argument("--model-dir", default="", help="trained twin (ONNX) to time as well")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--domain-id", type=int, default=211)
    ap.add_argument("--skip-node", action="store_true")
    ap.add_argument("--rt-priority", type=int, default=40, help="SCHED_FIFO priority of the *_fifo runs")
    a = ap.parse_args(argv)
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass
    core_bench(a)
    if not a.skip_node:
        node_bench(a)
    return 0


if __name__ == "__main__":
    sys.exit(main())
