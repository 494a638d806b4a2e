"""``hdphm node | stack | replay | record``: the running ROS 2 stack from the shell (argument parsing only).

* ``hdphm node onboard|prognostic|ground|twin [--ros-args -p name:=value ...]``
  runs one node; its parameters come from ``ros2_ws/config/<node>.yaml``
  (a standard ROS 2 params file) and then from ``--ros-args``, parsed by
  rclpy itself.
* ``hdphm stack`` runs all four nodes **in one process** on one
  executor (:class:`hdphm.stack.Stack`; ``hd_ros.context.make_executor``: a SingleThreadedExecutor,
  rclpy's EventsExecutor with ``HDPHM_EXECUTOR=events``): Python nodes of this size share one core well,
  the latched twin state is delivered without discovery latency, and one
  process is simpler to supervise on an actuator computer. For isolation
  (a crashing ground analysis must not stop the onboard monitor) run
  ``hdphm node ...`` per process instead: the topics and QoS are the same.
* ``hdphm replay BAG... [--rate 1.0|max]`` publishes the contract topics
  with their original header stamps (:class:`hd_ros.replay.Replayer`).
* ``hdphm record --out FILE.mcap`` records every ``/hd/...``,
  ``/diagnostics`` and stack topic (:class:`hd_ros.record.Recorder`); chunks are flushed every
  ``--flush-s`` seconds, so a recorder killed mid-run leaves a readable
  file with everything before the last flush.

The runtimes live below: :mod:`hd_ros` (replay, record, contexts), :mod:`hdphm.stack` (the four
nodes in one process, :func:`~hdphm.stack.run_stack_on_bags`).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path

CONFIG_DIR = Path(__file__).resolve().parents[2] / "ros2_ws" / "config"


def ros_args_for(name: str, extra: list[str] | None) -> list[str]:
    """rclpy args: the node's YAML params file (if present) then the user's ``--ros-args`` tail."""
    args = ["hdphm"]
    cfg = CONFIG_DIR / f"{name}.yaml"
    if cfg.is_file():
        args += ["--ros-args", "--params-file", str(cfg)]
    if extra:
        if extra[0] != "--ros-args":
            extra = ["--ros-args"] + extra
        args += extra
    return args


# --------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------
def _split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    if "--ros-args" in argv:
        i = argv.index("--ros-args")
        return argv[:i], argv[i:]
    return argv, []


def _pop_domain(args) -> None:
    """argparse REMAINDER also takes options written after the node name: move ``--domain-id N`` (and, for
    ``hdphm node``, ``--rt-priority N``) out."""
    ra = list(args.ros_args or [])
    end = ra.index("--ros-args") if "--ros-args" in ra else len(ra)
    head, tail = ra[:end], ra[end:]
    if hasattr(args, "managed") and "--managed" in head:
        args.managed = True
        head.remove("--managed")
    opts = ("--domain-id", "--rt-priority") if hasattr(args, "rt_priority") else ("--domain-id",)
    for opt in opts:
        for k, tok in enumerate(head):
            if tok == opt or tok.startswith(opt + "="):
                val = tok.split("=", 1)[1] if "=" in tok else (head[k + 1] if k + 1 < len(head) else None)
                if val is None or not val.lstrip("-").isdigit():
                    raise SystemExit(f"hdphm: {opt} needs an integer, got {val!r}")
                if opt == "--rt-priority" and not 0 <= int(val) <= 99:
                    raise SystemExit(f"hdphm: --rt-priority {val} outside 0..99")
                setattr(args, opt[2:].replace("-", "_"), int(val))
                del head[k:k + (1 if "=" in tok else 2)]
                break
    if head:
        raise SystemExit(f"hdphm: unexpected arguments {head}; node parameters go after --ros-args")
    args.ros_args = tail


def _stop_on_signals() -> dict:
    """SIGINT and SIGTERM set ``stop["v"]`` (Python handlers, installed after rclpy's): the spin loops below
    poll it every 0.1 s, so a node, the stack or the recorder stops promptly on Ctrl-C or SIGTERM (rclpy's
    own handler left a node without timers, the twin, blocked in its wait set)."""
    stop = {"v": False, "sig": None}

    def on_sig(signum, _frame):
        stop["v"] = True
        stop["sig"] = signum

    signal.signal(signal.SIGINT, on_sig)
    signal.signal(signal.SIGTERM, on_sig)
    return stop


def _spin_until_stopped(ex, stop: dict, end: float | None = None) -> None:
    while not stop["v"] and (end is None or time.monotonic() < end):
        ex.spin_once(timeout_sec=0.1)


def cmd_node(args) -> int:
    import rclpy

    import hd_ros as ru
    from hdphm.stack import make_node

    _pop_domain(args)
    if args.rt_priority:
        # before the context: the middleware's receive threads inherit SCHED_FIFO (measured: the onboard
        # node's p99 arrival -> flag latency follows the receive threads' scheduling on a loaded machine)
        why = ru.set_thread_realtime(args.rt_priority)
        print(f"hdphm node: {'SCHED_FIFO priority %d' % args.rt_priority if not why else 'not real-time: ' + why}",
              file=sys.stderr)
    ctx = ru.init_context(args.domain_id, ros_args_for(args.name, args.ros_args))
    # handlers before the node exists: a signal that comes while it configures (it may already publish)
    # stops the loop below at once instead of raising KeyboardInterrupt
    stop = _stop_on_signals()
    node = make_node(args.name, ctx, autostart=not args.managed)
    if args.managed:
        print(f"hdphm node: {args.name} is unconfigured, waiting for a lifecycle manager "
              f"(services /{node.get_name()}/change_state, /{node.get_name()}/get_state)", file=sys.stderr)
    ex = ru.make_executor(ctx)
    ex.add_node(node)
    try:
        _spin_until_stopped(ex, stop)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    return 0


def cmd_stack(args) -> int:
    from hdphm.stack import NODES, Stack

    _pop_domain(args)
    argv = ["hdphm"]
    for n in NODES:
        cfg = CONFIG_DIR / f"{n}.yaml"
        if cfg.is_file():
            argv += ["--ros-args", "--params-file", str(cfg)]
    if args.ros_args:
        argv += args.ros_args if args.ros_args[0] == "--ros-args" else ["--ros-args"] + args.ros_args
    st = Stack(args.domain_id, record=args.record, args=argv)
    print(f"hdphm stack: nodes {', '.join(st.nodes)} in one process (domain {args.domain_id or os.environ.get('ROS_DOMAIN_ID', 0)}); Ctrl-C stops",
          file=sys.stderr)
    stop = _stop_on_signals()
    try:
        _spin_until_stopped(st.ex, stop)
    except KeyboardInterrupt:
        pass
    finally:
        st.close()
    return 0


def cmd_replay(args) -> int:
    from rclpy.node import Node

    import hd_ros as ru
    from hd_ros.replay import BagSource, Replayer

    rate = "max" if args.rate == "max" else float(args.rate)
    for b in args.bags:  # a bag that cannot be opened fails before any waiting or publishing: one line
        try:
            from hd_bag import read_metadata

            read_metadata(b)
            next(iter(BagSource(b).blocks()), None)
        except (ValueError, OSError) as e:
            line = str(e).splitlines()[0] if str(e) else type(e).__name__
            print(f"hdphm replay: {line if line.startswith(str(b)) else f'{b}: {line}'}", file=sys.stderr)
            return 2
    ctx = ru.init_context(args.domain_id)
    node = Node("hdphm_replay", context=ctx)
    rep = Replayer(node, rate)
    # every expected reader (e.g. the stack and a recorder: --wait-for 2) on every contract topic and on
    # /hd/mission before the first sample: starting when the first one matched cost a recorder 0.5 s
    want = max(int(args.wait_for), 1)
    pubs = list(rep.pubs.values()) + [rep.pub_mission]
    deadline = time.monotonic() + args.wait_s
    while time.monotonic() < deadline and min(p.get_subscription_count() for p in pubs) < want:
        time.sleep(0.05)
    have = min(p.get_subscription_count() for p in pubs)
    if have < want:
        print(f"hdphm replay: only {have} of {want} expected subscribers on every topic after {args.wait_s:g} s "
              f"({', '.join(f'{p.topic_name} {p.get_subscription_count()}' for p in pubs)})"
              + ("; not replaying (--wait-for)" if args.wait_for else "; replaying anyway"), file=sys.stderr)
        if args.wait_for:
            node.destroy_node()
            import rclpy

            rclpy.try_shutdown(context=ctx)
            return 2
    t0 = time.perf_counter()
    try:
        for b in args.bags:
            c = rep.play(b)
            print(f"{b}: " + ", ".join(f"{k} {v}" for k, v in c.items()), file=sys.stderr)
        for p in rep.pubs.values():
            p.wait_for_all_acked()
    except (ValueError, OSError) as e:  # a bad bag: one line naming the file, no traceback
        print(f"hdphm replay: {str(e).splitlines()[0] if str(e) else type(e).__name__}", file=sys.stderr)
        return 2
    finally:
        wall = time.perf_counter() - t0
        node.destroy_node()
        import rclpy

        rclpy.try_shutdown(context=ctx)
    print(f"replayed {rep.sample_seconds:.1f} s of data in {wall:.2f} s ({rep.sample_seconds / max(wall, 1e-9):.1f}x real time)",
          file=sys.stderr)
    return 0


def cmd_record(args) -> int:
    import rclpy
    from rclpy.node import Node

    import hd_ros as ru
    from hd_ros.record import Recorder, drain

    ctx = ru.init_context(args.domain_id)
    node = Node("hdphm_record", context=ctx)
    try:
        rec = Recorder(node, args.out, flush_s=args.flush_s, split_per_mission=args.split_per_mission)
    except ValueError as e:
        print(f"hdphm record: {e}", file=sys.stderr)
        return 2
    ex = ru.make_executor(ctx)
    ex.add_node(node)
    stop = _stop_on_signals()  # SIGINT too: rclpy's handler shut the context down before the drain
    end = time.monotonic() + args.duration if args.duration else None
    try:
        while not stop["v"] and (end is None or time.monotonic() < end):
            ex.spin_once(timeout_sec=0.05)
    except KeyboardInterrupt:
        pass
    finally:
        t_stop = time.monotonic()
        drain(ex, rec)
        rec.close()
        t_closed = time.monotonic()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    print(f"stopped: drained and closed in {t_closed - t_stop:.2f} s, shut down in {time.monotonic() - t_closed:.2f} s",
          file=sys.stderr)
    print(f"recorded {sum(rec.counts.values())} messages to {len(rec.files)} file(s) under {args.out}: "
          + ", ".join(f"{k} {v}" for k, v in rec.counts.items() if v), file=sys.stderr)
    return 0


def _cmd_onboard_eval(args) -> int:
    from hd_ground.references import calibrate_actuator
    from hd_onboard.evaluate import cmd_eval

    return cmd_eval(args, calibrate=calibrate_actuator)


def _cmd_onboard_study(args) -> int:
    from hdphm.onboard_study import run_study

    return run_study(args)


def register(sub) -> None:
    p = sub.add_parser("onboard", help="onboard detector tools (eval: false-alarm rate over healthy bags)")
    osub = p.add_subparsers(dest="onboard_command", metavar="ONBOARDCOMMAND")
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])
    pe = osub.add_parser("eval", help="false alarms of the onboard detector over healthy mission bags")
    pe.add_argument("paths", nargs="+", help="bags or directories of bags (all taken as healthy)")
    pe.add_argument("--ground", type=int, default=0,
                    help="calibrate lines on the first K missions per actuator and score the others (0: self-calibrated)")
    pe.add_argument("--model-dir", default="", help="trained twin (ONNX); default: physics-only stand-in")
    pe.add_argument("--out", default="", help="write onboard_eval.json and onboard_eval.png here")
    pe.add_argument("--quiet", action="store_true")
    pe.set_defaults(func=_cmd_onboard_eval)
    ps = osub.add_parser("study", help="detection delay per fault and severity on simulated faults + false alarms")
    from hd_onboard.study_args import add_study_args

    add_study_args(ps)
    ps.set_defaults(func=_cmd_onboard_study)

    p = sub.add_parser("node", help="run one stack node (onboard, prognostic, ground, twin)")
    from hdphm.stack import NODES

    p.add_argument("name", choices=NODES)
    p.add_argument("--domain-id", type=int, default=None, help="ROS domain id (default $ROS_DOMAIN_ID)")
    p.add_argument("--rt-priority", type=int, default=0, choices=range(0, 100), metavar="0-99",
                   help="run the process SCHED_FIFO at this priority (middleware receive threads included; "
                        "worker threads stay normal); needs CAP_SYS_NICE; 0: normal scheduling")
    p.add_argument("--managed", action="store_true",
                   help="leave the node unconfigured: a lifecycle manager configures and activates it through "
                        "/NODE/change_state (default: configure and activate at start)")
    p.add_argument("ros_args", nargs=argparse.REMAINDER, help="--ros-args -p name:=value ...")
    p.set_defaults(func=cmd_node, fast_exit=True)

    p = sub.add_parser("stack", help="run all four nodes in one process")
    p.add_argument("--domain-id", type=int, default=None)
    p.add_argument("--record", default=None, help="also record to this MCAP file")
    p.add_argument("ros_args", nargs=argparse.REMAINDER, help="--ros-args -p onboard.param:=value ...")
    p.set_defaults(func=cmd_stack, fast_exit=True)

    p = sub.add_parser("replay", help="publish bags on the contract topics with their original stamps")
    p.add_argument("bags", nargs="+")
    p.add_argument("--rate", default="1.0", help="1.0 = real time, 'max' = as fast as the subscribers take it")
    p.add_argument("--domain-id", type=int, default=None)
    p.add_argument("--wait-s", type=float, default=5.0, help="wait this long for the subscribers before starting")
    p.add_argument("--wait-for", type=int, default=0, metavar="N",
                   help="start only when N subscribers (e.g. 2: the stack and a recorder) match every contract "
                        "topic and /hd/mission; exit 2 if they do not within --wait-s (0: wait for one, then "
                        "start anyway)")
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("record", help="record /hd/..., /diagnostics and stack topics to MCAP")
    p.add_argument("--out", required=True)
    p.add_argument("--domain-id", type=int, default=None)
    p.add_argument("--flush-s", type=float, default=0.5, help="chunk flush period (data at risk on a kill)")
    p.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0: until Ctrl-C/SIGTERM)")
    p.add_argument("--split-per-mission", action="store_true",
                   help="--out is a directory; one contract bag per /hd/mission (default: one stack log file)")
    p.set_defaults(func=cmd_record, fast_exit=True)
