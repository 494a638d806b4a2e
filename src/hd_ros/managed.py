"""Managed (lifecycle) node base of the four hdphm nodes (``rclpy.lifecycle``), and the node boilerplate
they share (parameter overrides, declaring a parameter table as ``self.p``).

Imports rclpy at module level: import it only where rclpy is wanted (the node modules).

A node subclass splits its set-up into ``__init__`` (declare parameters, nothing else) and
``configure()`` (read parameters, load the model, create publishers, subscriptions, timers and
services). The states mean what ROS 2 managed nodes mean:

| transition | what happens |
|---|---|
| configure  | parameters re-read, ``configure()``: model loaded, entities created (publishers are lifecycle publishers, still disabled) |
| activate   | publishers enabled, subscription and timer callbacks start running, ``activate()`` hook (e.g. publish the current state) |
| deactivate | callbacks stop (messages taken and dropped; on a latched topic the last one is kept and delivered on activation), publishers disabled |
| cleanup    | every entity ``configure()`` created is destroyed, ``release()`` hook (threads, pools, model) |
| shutdown   | as cleanup |

A failure inside ``configure()`` (a model that does not load, a bad parameter) is logged with its
reason and returns FAILURE: the node stays unconfigured, nothing half-built is left.

``bring_up(node, autostart)`` configures and activates at once (``hdphm stack``, in-process
replays and tests); ``hdphm node NAME --managed`` leaves the node unconfigured for an external
lifecycle manager (``/NAME/change_state``, ``/NAME/get_state`` services).
"""

from __future__ import annotations

from typing import Any

from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter


def declare(node, params: dict[str, Any]) -> dict[str, Any]:
    """Declare ``params`` (name -> default) on ``node`` and return their current values."""
    return {k: node.declare_parameter(k, v).value for k, v in params.items()}


class ManagedNode(LifecycleNode):
    """Base of the stack's nodes. ``params`` (name -> default) are declared and their values kept in
    ``self.p`` (re-read on every configure); ``overrides`` (name -> value) win over a params file;
    ``param_services=False`` creates no ``ros2 param`` services (fewer entities to wait on)."""

    def __init__(self, node_name: str, params: dict[str, Any] | None = None,
                 overrides: dict[str, Any] | None = None, *, context=None, param_services: bool = True, **kwargs):
        self._hd_configuring = False
        self._hd_active = False
        self._hd_owned: list = []
        self._hd_pending: dict = {}  # latched messages received while inactive, delivered on activation
        self.configure_error: Exception | None = None
        if overrides:
            kwargs["parameter_overrides"] = [Parameter(k, value=v) for k, v in overrides.items()]
        super().__init__(node_name, context=context, start_parameter_services=param_services, **kwargs)
        if params is not None:
            self.p = declare(self, params)

    # ---- hooks for subclasses -------------------------------------------------------------------
    def configure(self) -> None:  # pragma: no cover - every node overrides it
        raise NotImplementedError

    def activate(self) -> None:
        """Called after publishers are enabled."""

    def release(self) -> None:
        """Release what ``configure()`` started besides ROS entities (threads, pools)."""

    @property
    def is_active(self) -> bool:
        return self._hd_active

    # ---- entity creation: track what configure() makes, gate callbacks on the active state --------
    def create_publisher(self, *args, **kwargs):
        if not getattr(self, "_hd_configuring", False):
            return Node.create_publisher(self, *args, **kwargs)
        pub = self.create_lifecycle_publisher(*args, **kwargs)
        self._hd_owned.append(pub)
        return pub

    def _gated(self, callback, keep_last: bool = False):
        """Run ``callback`` only while active; a latched (transient-local) topic keeps its last message
        while inactive and delivers it on activation (its publisher sends it only once)."""
        def run(*a):
            if self._hd_active:
                return callback(*a)
            if keep_last:
                self._hd_pending[id(run)] = (callback, a)
            return None

        return run

    def create_subscription(self, msg_type, topic, callback, qos_profile, **kwargs):
        if not getattr(self, "_hd_configuring", False):
            return Node.create_subscription(self, msg_type, topic, callback, qos_profile, **kwargs)
        from rclpy.qos import DurabilityPolicy

        latched = getattr(qos_profile, "durability", None) == DurabilityPolicy.TRANSIENT_LOCAL
        sub = Node.create_subscription(self, msg_type, topic, self._gated(callback, latched), qos_profile, **kwargs)
        self._hd_owned.append(sub)
        return sub

    def create_timer(self, timer_period_sec, callback, *args, **kwargs):
        if not getattr(self, "_hd_configuring", False):
            return Node.create_timer(self, timer_period_sec, callback, *args, **kwargs)
        t = Node.create_timer(self, timer_period_sec, self._gated(callback), *args, **kwargs)
        self._hd_owned.append(t)
        return t

    def create_service(self, srv_type, srv_name, callback, **kwargs):
        if not getattr(self, "_hd_configuring", False):
            return Node.create_service(self, srv_type, srv_name, callback, **kwargs)
        s = Node.create_service(self, srv_type, srv_name, callback, **kwargs)
        self._hd_owned.append(s)
        return s

    def _destroy_owned(self) -> None:
        from rclpy.lifecycle.publisher import LifecyclePublisher
        from rclpy.service import Service
        from rclpy.subscription import Subscription
        from rclpy.timer import Timer

        for e in reversed(self._hd_owned):
            if isinstance(e, LifecyclePublisher):
                self.destroy_lifecycle_publisher(e)
            elif isinstance(e, Subscription):
                self.destroy_subscription(e)
            elif isinstance(e, Timer):
                self.destroy_timer(e)
            elif isinstance(e, Service):
                self.destroy_service(e)
        self._hd_owned.clear()

    # ---- transitions ------------------------------------------------------------------------------
    def on_configure(self, state) -> TransitionCallbackReturn:
        if hasattr(self, "p") and isinstance(self.p, dict):
            self.p = {k: self.get_parameter(k).value for k in self.p}
        self._hd_configuring = True
        self.configure_error = None
        try:
            self.configure()
        except Exception as e:  # noqa: BLE001 - a failed configure is a lifecycle FAILURE, not a crash
            self.get_logger().error(f"configure failed: {type(e).__name__}: {e}")
            self.configure_error = e
            self._hd_configuring = False
            self._destroy_owned()
            try:
                self.release()
            except Exception:  # noqa: BLE001
                pass
            return TransitionCallbackReturn.FAILURE
        finally:
            self._hd_configuring = False
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        ret = super().on_activate(state)
        if ret != TransitionCallbackReturn.SUCCESS:
            return ret
        self._hd_active = True
        pending, self._hd_pending = self._hd_pending, {}
        for callback, a in pending.values():
            callback(*a)
        self.activate()
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self._hd_active = False
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        self._hd_active = False
        self._hd_pending = {}
        self._destroy_owned()
        self.release()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state) -> TransitionCallbackReturn:
        return self.on_cleanup(state)

    def destroy_node(self):
        if self._hd_owned:
            self._hd_active = False
            try:
                self.release()
            except Exception:  # noqa: BLE001 - destroying anyway
                pass
            self._hd_owned.clear()
        return super().destroy_node()


def bring_up(node: ManagedNode, autostart: bool = True) -> ManagedNode:
    """Configure and activate ``node`` now when ``autostart``. A failed configure re-raises its own
    exception (a bad model folder stays the ValueError naming it, as before nodes were managed)."""
    if autostart:
        for name, trig in (("configure", node.trigger_configure), ("activate", node.trigger_activate)):
            ret = trig()
            if ret != TransitionCallbackReturn.SUCCESS:
                err = node.configure_error
                node.destroy_node()
                if err is not None:
                    raise err
                raise RuntimeError(f"node {node.get_name()}: {name} failed ({ret.name}); see its log")
    return node
