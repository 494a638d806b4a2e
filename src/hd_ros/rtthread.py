"""A subscription served on its own thread: own node + executor, optionally ``SCHED_FIFO`` (rclpy lazily).

Why: one executor serving all of a node's entities pays its wait-set rebuild per wake; at 1 kHz that
cost, not the work, dominates the arrival -> callback latency. :class:`RtSubscription` puts one
topic alone in a wait set, spun by a dedicated thread that can run under ``SCHED_FIFO``
(:func:`hd_ros.context.set_thread_realtime`). Any node may use it (the onboard node does for
``/hd/joint_states`` when ``rt_thread`` is set); not for in-process replays that spin every node in
one executor (its node is not in theirs).

The callback runs only while ``gate()`` is true (the owner's lifecycle: this node is not managed) and
under ``lock`` (the owner's state is shared with its other callbacks).
"""

from __future__ import annotations

import threading
from typing import Any, Callable


class RtSubscription:
    """``msg_type`` on ``topic`` with ``qos_profile`` to ``callback``, on node ``node_name`` of ``context``
    spun by thread ``thread_name`` (``label`` in log lines; ``priority`` 1-99: SCHED_FIFO, 0: normal). ``log(level, text)``
    reports ("warning": not real-time; "error": the thread ended on an exception). Create, then
    :meth:`contain` (optional), :meth:`start`; :meth:`stop` joins and destroys."""

    def __init__(self, context, node_name: str, msg_type, topic: str, callback: Callable[[Any], None], qos_profile, *,
                 priority: int = 0, gate: Callable[[], bool] | None = None, lock=None, raw: bool = False,
                 thread_name: str = "rt-subscription", label: str = "subscription",
                 log: Callable[[str, str], None] | None = None, executor_kind: str | None = None):
        from rclpy.node import Node

        from hd_ros.context import make_executor

        self.context = context
        self.priority = int(priority)
        self.label = label  # names the thread in log lines: "<label> thread not real-time: ..."
        self._log = log or (lambda level, text: None)
        self._callback, self._gate, self._lock = callback, gate, lock
        self.node = Node(node_name, context=context, start_parameter_services=False)
        self.sub = self.node.create_subscription(msg_type, topic, self._run, qos_profile, raw=raw)
        self.executor = make_executor(context, executor_kind)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name=thread_name, daemon=True)

    def _run(self, msg):
        if self._gate is not None and not self._gate():
            return
        if self._lock is None:
            self._callback(msg)
            return
        with self._lock:
            self._callback(msg)

    def contain(self, diag_name: str) -> None:
        """No exception of the callback ends the thread (:func:`hd_ros.diagnostics.contain_callbacks`)."""
        from hd_ros.diagnostics import contain_callbacks

        contain_callbacks(self.node, diag_name)

    def start(self) -> None:
        self._thread.start()

    def _spin(self):
        if self.priority:
            from hd_ros.context import set_thread_realtime

            why = set_thread_realtime(self.priority)
            if why:
                self._log("warning", f"{self.label} thread not real-time: {why}")
        while not self._stop.is_set() and self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.1)
            except Exception as e:  # noqa: BLE001 - shutdown races end the thread quietly
                if not self._stop.is_set() and self.context.ok():
                    self._log("error", f"{self.label} thread: {type(e).__name__}: {e}")
                return

    def stop(self, timeout: float = 2.0) -> None:
        """End the thread (joined up to ``timeout`` s), then the executor and the node."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=timeout)
        self.executor.shutdown()
        self.node.destroy_node()
