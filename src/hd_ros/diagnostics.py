"""Diagnostics helpers of the node shells: ``DiagnosticStatus`` construction and callback containment."""

from __future__ import annotations

import math
from typing import Any


def diag_status(name: str, level: int, message: str, hardware_id: str, values: dict[str, Any]):
    """A ``diagnostic_msgs/DiagnosticStatus`` with ``values`` as key/value strings (non-finite floats: "nan")."""
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

    s = DiagnosticStatus()
    s.name, s.level, s.message, s.hardware_id = name, bytes([int(level)]), message, hardware_id
    s.values = [KeyValue(key=str(k), value=_fmt(v)) for k, v in values.items()]
    return s


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else "nan"
    return str(v)


def diag_array(node, statuses):
    """A ``DiagnosticArray`` of ``statuses`` stamped with ``node``'s clock."""
    from diagnostic_msgs.msg import DiagnosticArray

    a = DiagnosticArray()
    a.header.stamp = node.get_clock().now().to_msg()
    a.status = list(statuses)
    return a


def contain_callbacks(node, diag_name: str | None = None) -> None:
    """Wrap every subscription and timer callback of ``node`` (call at the end of its ``__init__``, before
    it is added to an executor): an exception is logged, counted in ``node.n_callback_errors`` and
    reported on ``/diagnostics`` (ERROR, at most once a second), and the node goes on; one message can
    no longer take a node, or a whole ``hdphm stack``, down."""
    import time as _time
    import traceback

    node.n_callback_errors = 0
    node.last_callback_error = ""
    last = {"t": -1e9}
    name = diag_name or f"hdphm/{node.get_name()}"

    def wrap(fn, what):
        if getattr(fn, "_hdphm_contained", False):
            return fn

        def contained(*a, **k):
            try:
                return fn(*a, **k)
            except Exception as e:  # noqa: BLE001 - containment is the point
                node.n_callback_errors += 1
                text = f"{what} callback failed ({type(e).__name__}: {str(e)[:200]}); node continues"
                node.last_callback_error = text
                now = _time.monotonic()
                if now - last["t"] >= 1.0:
                    last["t"] = now
                    tb = traceback.extract_tb(e.__traceback__)
                    where = f" at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
                    node.get_logger().error(text + where + f" [{node.n_callback_errors} so far]")
                    pub = getattr(node, "pub_diag", None)
                    if pub is not None:
                        try:
                            from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

                            st = DiagnosticStatus(name=f"{name}/callbacks", level=DiagnosticStatus.ERROR,
                                                  message=text[:250], hardware_id=node.get_name())
                            st.values = [KeyValue(key="callback_errors", value=str(node.n_callback_errors))]
                            arr = DiagnosticArray(status=[st])
                            arr.header.stamp = node.get_clock().now().to_msg()
                            pub.publish(arr)
                        except Exception:  # noqa: BLE001 - reporting must not fail the containment
                            pass
                return None

        contained._hdphm_contained = True
        contained.__wrapped__ = fn
        return contained

    for sub in list(getattr(node, "subscriptions", [])):
        sub.callback = wrap(sub.callback, sub.topic_name)
    for tmr in list(getattr(node, "timers", [])):
        tmr.callback = wrap(tmr.callback, "timer")

