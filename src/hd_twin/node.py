"""Twin-core node: holds the current twin and publishes it latched.

State (JSON in ``std_msgs/msg/String`` on ``/hd/twin/state``, reliable +
transient_local, depth 1, so a node that starts late still gets it)::

    {"revision": int, "model_dir": str, "model_version": str,
     "params": {TwinParams, SI}, "effects": [declared effects],
     "degradation_law": {"name": "archard", ...prior},
     "thresholds": {actuator_id: {channel: {mu, sigma, h_warn, h_error, source}}},
     "references": {actuator_id: {"stiffness": {StiffnessReference}, "friction": {FrictionReference}}},
     "normalisation": {...}, "updated_by": str, "history": [last 20 update summaries]}

Updates arrive on ``/hd/twin/update`` (same JSON shape, any subset of the
keys; ``thresholds`` and ``references`` are merged per actuator; a state or
update without ``references`` is valid: older payloads load). Every update is
validated field by field first (:mod:`hd_twin.state`: types, finite numbers,
physical ranges, sizes, JSON depth, ``model_dir`` inside the configured
``model_roots``), then semantically (``TwinParams.from_dict`` bounds, threshold
and reference sanity: :mod:`hd_twin.records` ``from_dict``), and merged
(:func:`hd_twin.state.apply_update`; this module is the ROS shell only); a bad one is
refused with a /diagnostics WARN naming the field, the state is unchanged, and
a short summary goes to a bounded memory of refusals (:attr:`refusals`, the
last :data:`MAX_REFUSALS`). No exception of a callback stops the node
(``hd_ros.diagnostics.contain_callbacks``).
"""

from __future__ import annotations

import collections
import hashlib
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import String

import hd_ros as ru
from hd_ros.managed import ManagedNode, bring_up
from hd_twin import state as sv

NODE_NAME = "twin"
PARAMS: dict[str, Any] = {
    "model_dir": "",  # trained twin directory (config.json + twin.onnx); "" -> physics-only stand-in
    "params_file": "",  # YAML of TwinParams; "" -> hd_twin/default_params.yaml (or the model's config)
    # directories an update's model_dir may lie in (os.pathsep-separated); the parent of model_dir and
    # $HDPHM_MODEL_ROOTS are always included
    "model_roots": "",
}
#: refused updates remembered (short summaries), and update digests remembered against re-delivery
MAX_REFUSALS = 32
MAX_SEEN = 256


class TwinNode(ManagedNode):
    def __init__(self, context=None, overrides: dict[str, Any] | None = None, param_services: bool = True):
        super().__init__(NODE_NAME, PARAMS, overrides, context=context, param_services=param_services)

    def configure(self):
        self.model_roots = sv.model_roots(self.p["model_roots"], self.p["model_dir"])
        self.state = sv.initial_state(self.p["model_dir"], self.p["params_file"])
        self.pub = self.create_publisher(String, ru.TOPIC_TWIN_STATE, ru.qos("latched"))
        self.pub_diag = self.create_publisher(DiagnosticArray, ru.TOPIC_DIAGNOSTICS, ru.qos("diagnostics"))
        self.create_subscription(String, ru.TOPIC_TWIN_UPDATE, self._on_update, ru.qos("latched"))
        self.n_updates = self.n_refused = 0
        #: digests of the last MAX_SEEN updates (a latched update re-delivered after a restart is
        #: skipped); bounded, and never the message text itself
        self._seen: collections.OrderedDict[bytes, None] = collections.OrderedDict()
        #: short summaries of the last MAX_REFUSALS refused updates (field, problem, size, digest)
        self.refusals: collections.deque = collections.deque(maxlen=MAX_REFUSALS)
        ru.contain_callbacks(self, "hdphm/twin")

    def activate(self):
        self._publish()

    def _publish(self):
        self.pub.publish(ru.json_msg(self.state))
        self._diag(0, f"revision {self.state['revision']}",
                   {"model_version": self.state["model_version"], "updates": self.n_updates, "refused": self.n_refused,
                    "callback_errors": getattr(self, "n_callback_errors", 0)})

    def _diag(self, level: int, message: str, values: dict):
        self.pub_diag.publish(ru.diag_array(self, [ru.diag_status("hdphm/twin", level, message, "twin-core", values)]))

    def _on_update(self, msg):
        data = msg.data if isinstance(msg.data, str) else ""
        key = hashlib.sha256(data.encode("utf-8", "replace")).digest()
        if key in self._seen:  # a latched update re-delivered after a restart
            return
        self._seen[key] = None
        while len(self._seen) > MAX_SEEN:
            self._seen.popitem(last=False)
        try:
            upd = sv.parse_json(data, ru.TOPIC_TWIN_UPDATE, sv.MAX_UPDATE_BYTES)
            self.state = sv.apply_update(self.state, upd, ru.TOPIC_TWIN_UPDATE, self.model_roots)
        except ValueError as e:
            self.n_refused += 1
            self.refusals.append(sv.summary_of_refusal(e, data, time.time()))
            self.get_logger().warning(f"twin update refused: {str(e)[:300]}")
            self._diag(1, f"update refused: {str(e)[:180]}", {"refused": self.n_refused})
            return
        self.n_updates += 1
        self.get_logger().info(f"twin revision {self.state['revision']} by {self.state['updated_by']}")
        self._publish()


def make_node(context=None, overrides: dict[str, Any] | None = None, param_services: bool = True,
              autostart: bool = True) -> TwinNode:
    """The twin-core node (managed; configured and activated unless ``autostart`` is False)."""
    return bring_up(TwinNode(context, overrides, param_services), autostart)
