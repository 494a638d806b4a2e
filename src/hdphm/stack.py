"""The in-process stack: the four nodes (twin, onboard, prognostic, ground) on one executor, and
:func:`run_stack_on_bags` (replay bags through them with a recorder; the demo's and the tests' API).

It sits above the node packages (it assembles them); the replay and record runtimes it drives live
in :mod:`hd_ros` (they need no node).
"""

from __future__ import annotations

import os
import sys
import time
from typing import Any, Iterable

import hd_ros as ru
from hd_ros.record import Recorder
from hd_ros.replay import Replayer

NODES = ("onboard", "prognostic", "ground", "twin")


def make_node(name: str, context=None, overrides: dict[str, Any] | None = None, param_services: bool = True,
              autostart: bool = True):
    """Instantiate one of the four stack nodes by name (``param_services=False``: no ``ros2 param`` services,
    fewer entities for the executor to wait on; used by the in-process replay job). The nodes are managed
    (lifecycle) nodes: ``autostart`` configures and activates them at once; ``autostart=False`` leaves them
    unconfigured for a lifecycle manager (``hd_ros.managed``)."""
    if name == "onboard":
        from hd_onboard.node import make_node as mk
    elif name == "twin":
        from hd_twin.node import make_node as mk
    elif name == "prognostic":
        from hd_prognostic.node import make_node as mk
    elif name == "ground":
        from hd_ground.node import make_node as mk
    else:
        raise ValueError(f"unknown node {name!r}; one of {', '.join(NODES)}")
    return mk(context=context, overrides=overrides, param_services=param_services, autostart=autostart)


class Stack:
    """All four nodes (+ optional replayer/recorder node) in one process, one executor."""

    def __init__(self, domain_id: int | None = None, overrides: dict[str, dict[str, Any]] | None = None,
                 nodes: Iterable[str] = NODES, record: str | None = None, args: list[str] | None = None,
                 split_per_mission: bool = False, tap_replay: bool = False, param_services: bool = True,
                 publication_mode: str | None = None):
        """``tap_replay``: the recorder files the contract topics and ``/hd/mission`` from an in-process
        :class:`Replayer` (``Replayer(..., tap=stack.recorder.tap)``) instead of subscribing to them.
        ``publication_mode``: Fast DDS publication mode of this stack's writers
        (:func:`hd_ros.context.publication_mode`; None: the middleware default, synchronous)."""
        from rclpy.node import Node

        self.param_services = bool(param_services)
        self.nodes: dict[str, Any] = {}
        overrides = overrides or {}
        with ru.publication_mode(publication_mode):  # read when the context's first node creates the participant
            self.ctx = ru.init_context(domain_id, args)
            self.ex = ru.make_executor(self.ctx)
            self.aux = Node("hdphm_stack_io", context=self.ctx, start_parameter_services=self.param_services)
        for name in nodes:
            self.add(name, overrides.get(name))
        self.ex.add_node(self.aux)
        self.recorder = (Recorder(self.aux, record, split_per_mission=split_per_mission,
                                  tapped=(ru.TOPIC_MISSION,) + ru.CONTRACT_TOPICS if tap_replay else ())
                         if record else None)

    def add(self, name: str, overrides: dict[str, Any] | None = None):
        node = make_node(name, self.ctx, overrides, self.param_services)
        self.nodes[name] = node
        self.ex.add_node(node)
        return node

    def remove(self, name: str) -> None:
        node = self.nodes.pop(name)
        self.ex.remove_node(node)
        node.destroy_node()

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=min(0.02, max(0.0, end - time.monotonic())))

    def pump(self, timeout: float = 0.0, force: bool = False) -> None:
        """Let every subscriber take what was published (lossless in-process replay)."""
        end = time.monotonic() + timeout
        n = 0
        while True:
            self.ex.spin_once(timeout_sec=0.0)
            n += 1
            if n >= (12 if force else 3) and time.monotonic() >= end:
                break
            if time.monotonic() < end:
                self.ex.spin_once(timeout_sec=min(0.005, max(0.0, end - time.monotonic())))

    def close(self) -> None:
        if self.recorder:
            self.pump(force=True)
            self.recorder.close()
        for n in list(self.nodes.values()) + [self.aux]:
            try:
                self.ex.remove_node(n)
                n.destroy_node()
            except Exception:  # noqa: BLE001
                pass
        self.ex.shutdown()
        try:
            import rclpy

            rclpy.shutdown(context=self.ctx)
        except Exception:  # noqa: BLE001
            pass


def run_stack_on_bags(bags: list[str | os.PathLike], model_dir: str | None = None, out_mcap: str | None = None,
                      rate: float | str = "max", domain_id: int | None = None,
                      overrides: dict[str, dict[str, Any]] | None = None, settle_s: float = 0.5,
                      progress: bool = True, obs_model: str | None = None, split_per_mission: bool = False,
                      archive_dir: str | None = None, replay_batch: int = 500, async_publish: bool = False) -> dict:
    """Replay ``bags`` (in the given order) through twin, onboard, prognostic and ground nodes in one process.

    ``model_dir``: trained twin (ONNX) for the twin core and the onboard node
    (None: physics-only stand-in); ``obs_model``: the prognostic node's
    observation model JSON; ``archive_dir``: mission archive the ground node
    analyses at start (its thresholds/parameters reach the onboard node
    through the twin core before the replay starts);
    ``split_per_mission``: ``out_mcap`` is a directory with one contract
    bag per mission (see :class:`Recorder`); ``replay_batch``: contract
    messages published between two executor pumps at ``rate="max"`` (the
    replay then pumps until the onboard node has taken all of them, so it
    must stay well below the reader history, ``hd_ros.qos.SENSOR_DEPTH``);
    ``async_publish``: the stack's writers use Fast DDS asynchronous
    publication (delivery in the middleware's thread; order per topic and
    reliability unchanged; the replay waits at every mission boundary until
    the onboard node has taken the mission message and every sample before
    it). Off by default: ``hdphm bench replay`` measured it slower on 2 cores
    (the delivery thread competes with the executor for the same cores).

    Returns a summary: per-topic counts published and recorded, flags
    (actuator, stamp, level, reason), per-actuator last health / RUL and the
    final row of every mission, the wall time and the replay speed-up over
    real time.
    """
    overrides = {k: dict(v) for k, v in (overrides or {}).items()}
    if model_dir:
        overrides.setdefault("twin", {})["model_dir"] = str(model_dir)
        overrides.setdefault("onboard", {})["model_dir"] = str(model_dir)
    if obs_model:
        overrides.setdefault("prognostic", {})["obs_model"] = str(obs_model)
    if archive_dir:
        overrides.setdefault("ground", {})["archive_dir"] = str(archive_dir)
    st = Stack(domain_id, overrides, record=out_mcap, split_per_mission=split_per_mission, tap_replay=True,
               param_services=False, publication_mode="ASYNCHRONOUS" if async_publish else None)
    try:
        st.spin_for(settle_s)  # latched twin state reaches the onboard node
        if archive_dir:  # the ground analysis runs in a worker thread; wait for its update to be applied
            gr, tw = st.nodes["ground"], st.nodes["twin"]
            end = time.monotonic() + 300.0
            while time.monotonic() < end and gr.n_runs == 0 and gr.error is None:
                st.spin_for(0.1)
            if gr.error:
                raise ValueError(f"ground analysis of {archive_dir} failed: {gr.error}")
            st.spin_for(0.3)
        def drained() -> bool:  # the onboard node took every contract message published so far
            onb_ = st.nodes.get("onboard")
            taken = getattr(onb_, "n_taken", None)
            return taken is None or (all(taken.get(t, 0) >= n for t, n in rep.counts.items())
                                     and onb_.n_mission_msgs >= rep.n_mission)

        rep = Replayer(st.aux, rate, pump=st.pump, tap=st.recorder.tap if st.recorder else None, batch=replay_batch,
                       drained=drained)
        # the replay's publishers are new: wait until DDS discovery has matched the onboard
        # subscription, or a max-speed replay on a loaded machine loses its first samples
        end = time.monotonic() + 15.0
        while time.monotonic() < end and rep.pubs[ru.TOPIC_JOINT_STATES].get_subscription_count() == 0:
            st.ex.spin_once(timeout_sec=0.02)
        t0 = time.perf_counter()
        it = bags
        if progress:
            from tqdm import tqdm

            it = tqdm(bags, desc="replay", unit="bag", file=sys.stderr)
        for b in it:
            rep.play(b)
        st.pump(force=True)
        onb = st.nodes["onboard"]
        onb.close_mission()  # end of the replay ends the last mission (live: the stale timeout does it)
        st.pump(force=True)
        wall = time.perf_counter() - t0
        st.spin_for(0.3)
        prog = st.nodes.get("prognostic")
        summary = {
            "bags": [str(b) for b in bags],
            "published": dict(rep.counts),
            "received_onboard": dict(onb.n_msgs),
            "onboard_published": dict(onb.n_published),
            "flags": [{"actuator": a, "stamp_s": s * 1e-9, "level": int(lv), "reason": why} for a, s, lv, why in onb.flags],
            "n_warn": sum(1 for f in onb.flags if f[2] == 1),
            "n_error": sum(1 for f in onb.flags if f[2] == 2),
            "errors": list(onb.errors),
            "health": dict(getattr(prog, "last", {}) or {}),
            "health_history": {a: list(v) for a, v in (getattr(prog, "history", {}) or {}).items()},
            "ground_runs": getattr(st.nodes.get("ground"), "n_runs", 0),
            "wall_s": wall,
            "sample_s": rep.sample_seconds,
            "speedup": rep.sample_seconds / wall if wall > 0 else float("nan"),
            "twin": onb.core.expected.kind,
        }
        if st.recorder:
            st.pump(force=True)
            st.recorder.flush()
            summary["recorded"] = dict(st.recorder.counts)
            summary["out_mcap"] = st.recorder.out
            summary["recorded_files"] = list(st.recorder.files)
        return summary
    finally:
        st.close()

