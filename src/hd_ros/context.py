"""Contexts, domains, real-time scheduling, publication mode and executors (rclpy imported lazily)."""

from __future__ import annotations

import contextlib
import os

def init_context(domain_id: int | None = None, args: list[str] | None = None):
    """A fresh rclpy Context on ``domain_id`` (None: ``$ROS_DOMAIN_ID`` or 0).

    Discovery is limited to this host (``ROS_AUTOMATIC_DISCOVERY_RANGE``
    defaults to LOCALHOST here unless the user set it), so a test or a demo
    never talks to machines on the network.
    """
    import rclpy

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if domain_id is not None and not (0 <= int(domain_id) <= 232):
        raise ValueError(f"ROS domain id {domain_id} outside 0..232")
    ctx = rclpy.Context()
    rclpy.init(args=args, context=ctx, domain_id=None if domain_id is None else int(domain_id))
    return ctx


def set_thread_realtime(priority: int) -> str:
    """Put the calling thread under ``SCHED_FIFO`` at ``priority`` (1-99; 0: ``SCHED_OTHER``).

    Threads created afterwards by this thread inherit the policy (the
    middleware's receive threads, when called before the context's first
    node). Returns "" on success, else why it was not possible (no Linux, no
    CAP_SYS_NICE / RLIMIT_RTPRIO): the caller logs it and runs on, unprioritised.
    """
    priority = int(priority)
    if not 0 <= priority <= 99:
        raise ValueError(f"real-time priority {priority} outside 0..99")
    if not hasattr(os, "sched_setscheduler"):
        return "SCHED_FIFO is not available on this platform"
    try:
        if priority == 0:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        else:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as e:
        return f"SCHED_FIFO priority {priority} refused ({e.strerror}; needs CAP_SYS_NICE or an rtprio limit)"
    return ""


PUBLICATION_MODE_ENV = "RMW_FASTRTPS_PUBLICATION_MODE"


@contextlib.contextmanager
def publication_mode(mode: str | None):
    """Within the block, a context's first node is created with Fast DDS publication ``mode``.

    ``"ASYNCHRONOUS"``: a writer queues the sample and the middleware's own
    thread delivers it (GIL-free, beside the Python executor; the choice for
    max-rate replay); ``"SYNCHRONOUS"``: delivered in the publishing thread
    (lowest latency, rmw_fastrtps's default); None: leave as is. rmw_fastrtps
    reads ``$RMW_FASTRTPS_PUBLICATION_MODE`` when a context creates its
    participant (its first node), so create that node inside the block. A
    value the user exported wins.
    """
    if mode is not None and mode not in ("ASYNCHRONOUS", "SYNCHRONOUS", "AUTO"):
        raise ValueError(f"publication mode {mode!r}: one of ASYNCHRONOUS, SYNCHRONOUS, AUTO")
    if mode is None or PUBLICATION_MODE_ENV in os.environ:
        yield
        return
    os.environ[PUBLICATION_MODE_ENV] = mode
    try:
        yield
    finally:
        os.environ.pop(PUBLICATION_MODE_ENV, None)


#: executor kind of the stack: "single" (SingleThreadedExecutor, the default) or "events"
#: (rclpy's C++ EventsExecutor, experimental in Jazzy: no wait-set rebuild per wake; measured
#: 1.1-1.6x faster max-rate replay, but with it the prognostic node missed the last mission's
#: final window rows in a replay of two missions, so it is opt-in until that is understood).
#: $HDPHM_EXECUTOR overrides.
EXECUTOR = os.environ.get("HDPHM_EXECUTOR", "single")


def make_executor(context, kind: str | None = None):
    """An executor for ``context``: ``kind`` "events" (falls back to "single" when unavailable) or "single"."""
    kind = kind or EXECUTOR
    if kind not in ("events", "single"):
        raise ValueError(f"executor kind {kind!r}: one of 'events', 'single'")
    if kind == "events":
        try:
            from rclpy.experimental.events_executor import EventsExecutor

            return EventsExecutor(context=context)
        except ImportError:
            pass
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor(context=context)
