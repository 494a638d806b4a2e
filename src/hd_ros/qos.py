"""QoS profiles of the stack's topic classes (``sensor``, ``stream``, ``latched``, ``diagnostics``)
and the ``offered_qos_profiles`` YAML ``ros2 bag`` writes. rclpy is imported inside the functions."""

from __future__ import annotations

from typing import Any, Iterable

from hd_ros.topics import STACK_TOPICS

#: History depth of sensor topics. Reliable + KEEP_ALL on both sides gives
#: flow control: a full reader history withholds acknowledgements, so
#: ``replay --rate max`` is throttled by the slowest subscriber instead of
#: losing samples.
SENSOR_DEPTH = 5000


def qos(kind: str):
    """The QoS profile of a topic class: ``sensor``, ``stream``, ``latched``, ``diagnostics``.

    - sensor: reliable, keep-all (bounded by the middleware's resource limits),
      volatile: contract topics; no sample lost at any replay rate.
    - stream: reliable, keep-last 1000, volatile: residual/feature/health blocks.
    - latched: reliable, keep-last 1, transient-local: twin state, updates, mission metadata.
    - diagnostics: reliable, keep-last 100, volatile (as diagnostic_updater).
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    if kind == "sensor":
        return QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=SENSOR_DEPTH,
                          reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    if kind == "stream":
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                          reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    if kind == "latched":
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                          reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    if kind == "diagnostics":
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                          reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    raise ValueError(f"unknown QoS class {kind!r}; one of sensor, stream, latched, diagnostics")


def mission_sub_qos():
    """Subscription QoS of ``/hd/mission``: latched (compatible with the publisher's keep-last 1) but
    keep-last 16, so missions announced faster than a busy subscriber takes them are all delivered."""
    q = qos("latched")
    q.depth = 16
    return q


def topic_qos(topic: str):
    """QoS profile of a stack topic (unknown topics get ``stream``)."""
    return qos(STACK_TOPICS.get(topic, ("", "stream"))[1])


def offered_qos_yaml(profiles: Iterable[Any]) -> str:
    """``offered_qos_profiles`` channel metadata in the YAML form ``ros2 bag`` writes.

    ``profiles`` are rclpy ``QoSProfile`` objects (one per publisher). Enum
    values are the rmw integers (history 1 keep_last / 2 keep_all,
    reliability 1 reliable / 2 best_effort, durability 1 transient_local /
    2 volatile), durations as sec/nsec with the "infinite" sentinel.
    """
    out = []
    for p in profiles:
        def dur(d) -> str:
            ns = int(getattr(d, "nanoseconds", 0))
            if ns <= 0 or ns >= 2**63 - 1:
                return "    sec: 9223372036\n    nsec: 854775807"
            return f"    sec: {ns // 10**9}\n    nsec: {ns % 10**9}"

        out.append(
            f"- history: {int(p.history)}\n  depth: {int(p.depth)}\n  reliability: {int(p.reliability)}\n"
            f"  durability: {int(p.durability)}\n  deadline:\n{dur(p.deadline)}\n  lifespan:\n{dur(p.lifespan)}\n"
            f"  liveliness: {int(p.liveliness)}\n  liveliness_lease_duration:\n{dur(p.liveliness_lease_duration)}\n"
            f"  avoid_ros_namespace_conventions: false"
        )
    return "\n".join(out)

