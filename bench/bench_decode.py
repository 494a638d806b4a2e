"""Benchmark: decode /hd/joint_states of one contract bag into arrays.

Compares, in one run on the same file:
  (a) mcap-ros2-support: ``make_reader(...).iter_decoded_messages`` (the baseline),
  (b) rosbags: ``AnyReader.messages`` + ``deserialize`` (if installed),
  (c) ours, decode only: hd_bag's chunk scan + vectorised CDR (arrays of stamps and values),
  (d) ours, full ``read_mission`` (decode + sort, duplicates, gaps, limits, report).
Every path produces the same (n, 6) float64 matrix (checked) and prints the
median of ``--repeats`` runs and the speed-up over (a).

    python bench/bench_decode.py [--seconds 60] [--rate 1000] [--repeats 5]
    hdphm bench decode
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

TOPIC = "/hd/joint_states"


def make_bag(path: str, seconds: float, rate: float) -> int:
    from hd_bag import Mission, MissionMeta, write_mission

    n = int(seconds * rate)
    rng = np.random.default_rng(0)
    t = np.arange(n) / rate
    m = Mission(meta=MissionMeta("BENCH-1", 0, 0.0, 100.0, 0.12), t=t, theta_m=100 * np.sin(t),
                theta_f=np.sin(t), omega_m=100 * np.cos(t), omega_f=np.cos(t), tau_m=rng.normal(size=n),
                Q_red=rng.normal(size=n), t_cmd=t[::10], theta_ref=np.sin(t[::10]),
                temperatures={"gearbox": (t[::int(rate)], 20 + 0 * t[::int(rate)])}, t0_ns=1_700_000_000 * 10**9)
    write_mission(path, m)
    return n


def decode_mcap_ros2(path: str) -> np.ndarray:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    rows = []
    with open(path, "rb") as f:
        r = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, _, _, msg in r.iter_decoded_messages(topics=[TOPIC]):
            rows.append((*msg.position, *msg.velocity, *msg.effort))
    return np.array(rows)


def decode_rosbags(path: str) -> np.ndarray:
    from rosbags.highlevel import AnyReader

    rows = []
    with AnyReader([Path(path)]) as ar:
        conns = [c for c in ar.connections if c.topic == TOPIC]
        for c, _, raw in ar.messages(connections=conns):
            msg = ar.deserialize(raw, c.msgtype)
            rows.append((*msg.position, *msg.velocity, *msg.effort))
    return np.array(rows)


def decode_ours(path: str) -> np.ndarray:
    from hd_bag.reader import _scan

    raw = _scan(path, include_sim=False)
    acc = raw.js[TOPIC]
    order = np.argsort(np.concatenate(acc.index), kind="stable")
    M = np.concatenate([np.concatenate([p, v, e], 1) for p, v, e in zip(acc.pos, acc.vel, acc.eff)])
    return M[order][:, [0, 1, 2, 3, 4, 5]]


def read_mission_ours(path: str) -> np.ndarray:
    from hd_bag import read_mission

    m = read_mission(path)
    return np.stack([m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red], 1)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="bench_decode", description=__doc__.splitlines()[1])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--bag", help="use this contract bag instead of a generated one")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        path = a.bag or os.path.join(d, "bench.mcap")
        if not a.bag:
            n = make_bag(path, a.seconds, a.rate)
            print(f"bag: {n} JointState messages ({a.seconds:g} s at {a.rate:g} Hz), "
                  f"{os.path.getsize(path) / 1e6:.2f} MB zstd")
        cands = [("mcap-ros2-support", decode_mcap_ros2)]
        try:
            import rosbags  # noqa: F401

            cands.append(("rosbags", decode_rosbags))
        except ImportError:
            print("rosbags not installed: skipped")
        cands += [("hd_bag decode", decode_ours), ("hd_bag read_mission", read_mission_ours)]
        ref = None
        res = {}
        for name, fn in cands:
            times = []
            for _ in range(a.repeats if name.startswith("hd_bag") else max(1, min(a.repeats, 3))):
                t0 = time.perf_counter()
                out = fn(path)
                times.append(time.perf_counter() - t0)
            if ref is None:
                ref = out
            elif out.shape != ref.shape or not np.allclose(out, ref, equal_nan=True):
                print(f"{name}: output differs from the baseline!", file=sys.stderr)
                return 1
            res[name] = statistics.median(times)
        base = res["mcap-ros2-support"]
        n = len(ref)
        print(f"{'method':22s} {'median s':>10s} {'us/msg':>8s} {'speed-up vs (a)':>16s}")
        for name, t in res.items():
            print(f"{name:22s} {t:10.4f} {1e6 * t / n:8.2f} {base / t:15.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
