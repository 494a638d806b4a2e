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
and reference sanity: ``hd_onboard.detector`` ``from_dict``); a bad one is
refused with a /diagnostics WARN naming the field, the state is unchanged, and
a short summary goes to a bounded memory of refusals (:attr:`refusals`, the
last :data:`MAX_REFUSALS`). No exception of a callback stops the node
(``hd_ros.diagnostics.contain_callbacks``).
"""

from __future__ import annotations

import collections
import hashlib
import json
import time
from typing import Any

import hd_ros as ru

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


def initial_state(model_dir: str = "", params_file: str = "") -> dict:
    """The twin state at start: parameters from the model's config.json, a params file, or the defaults."""
    from hd_twin import physics as ph

    state: dict[str, Any] = {"revision": 0, "model_dir": model_dir, "model_version": "physics-standin",
                             "effects": list(ph.DEFAULT_EFFECTS), "degradation_law": {"name": "archard"},
                             "thresholds": {}, "references": {}, "normalisation": {}, "updated_by": "init", "history": []}
    params = ph.TwinParams.from_yaml(params_file or None)
    if model_dir:
        from pathlib import Path

        from hd_twin.modeldir import CONFIG_NAME, read_config

        cfgp = Path(model_dir) / CONFIG_NAME
        cfg = read_config(model_dir)
        if isinstance(cfg.get("params"), dict) and not params_file:
            params = ph.TwinParams.from_dict({k: v for k, v in cfg["params"].items() if k in ph.TwinParams.__dataclass_fields__ or k in ("mu_g", "K_out")}, str(cfgp))
        state["model_version"] = str(cfg.get("version") or cfg.get("model_version") or Path(model_dir).name)
        state["effects"] = list(cfg.get("effects", state["effects"]))
        state["normalisation"] = cfg.get("normalization", {})
    state["params"] = params.to_dict()
    return state


def apply_update(state: dict, upd: dict, source: str = "update", model_roots: list[str] | None = None) -> dict:
    """New state = ``state`` with ``upd`` merged, validated; raises ValueError naming the bad field.

    ``model_roots``: directories a new ``model_dir`` may lie in (None: those of
    :func:`hd_twin.state.model_roots` for the state's current ``model_dir``)."""
    from hd_onboard.detector import ChannelThreshold
    from hd_twin import physics as ph
    from hd_twin import state as sv

    if model_roots is None:
        model_roots = sv.model_roots("", state.get("model_dir", ""))
    try:
        upd = sv.check_update(upd, model_roots, source)
    except sv.UpdateError as e:
        raise sv.refusal(source, e) from None
    new = json.loads(json.dumps(state))
    if "params" in upd:
        if not isinstance(upd["params"], dict):
            raise ValueError(f"{source}: params must be a mapping")
        merged = {k: v for k, v in new["params"].items() if k not in ("mu_g", "K_out")}
        merged.update({k: v for k, v in upd["params"].items() if k not in ("mu_g", "K_out")})
        new["params"] = ph.TwinParams.from_dict(merged, where=f"{source} params").to_dict()
        try:
            sv.check_merged_params(new["params"])
        except sv.UpdateError as e:
            raise sv.refusal(source, e) from None
    if "thresholds" in upd:
        if not isinstance(upd["thresholds"], dict):
            raise ValueError(f"{source}: thresholds must be a mapping actuator -> channel -> values")
        for act, chans in upd["thresholds"].items():
            if not isinstance(chans, dict):
                raise ValueError(f"{source}: thresholds[{act}] must be a mapping channel -> values")
            ok = {c: ChannelThreshold.from_dict(v, f"{source} thresholds[{act}][{c}]").to_dict() for c, v in chans.items()}
            new["thresholds"].setdefault(act, {}).update(ok)
    if "references" in upd:
        new.setdefault("references", {})
        for act, refs in validate_references(upd["references"], source).items():
            new["references"].setdefault(act, {}).update(refs)
    if "effects" in upd:
        new["effects"] = ph.check_effects(upd["effects"])
    for k in ("normalisation", "degradation_law"):
        if k in upd:
            if not isinstance(upd[k], dict):
                raise ValueError(f"{source}: {k} must be a mapping")
            new[k] = upd[k]
    for k in ("model_dir", "model_version"):
        if k in upd:
            new[k] = str(upd[k])
    new["revision"] = int(state.get("revision", 0)) + 1
    new["updated_by"] = str(upd.get("updated_by", source))[:sv.MAX_TEXT]
    size = len(json.dumps(new))
    if size > sv.MAX_STATE_BYTES // 2:  # merged thresholds/references grow per actuator: bound the whole state
        raise ValueError(f"{source}: the state would grow to {size} bytes, above the cap of {sv.MAX_STATE_BYTES // 2} "
                         "(hd_twin.state.MAX_STATE_BYTES / 2)")
    new["history"] = (state.get("history", []) + [{"revision": new["revision"], "by": new["updated_by"], "keys": sorted(upd),
                                                     "wall_time": time.time()}])[-20:]
    return new


def validate_references(refs, source: str = "update") -> dict:
    """``{actuator: {"stiffness": {...}, "friction": {...}}}`` checked entry by entry (either monitor may be
    absent); returns the normalised mapping; ValueError naming ``source``, the actuator and the monitor."""
    from hd_onboard.detector import FrictionReference, StiffnessReference

    if not isinstance(refs, dict):
        raise ValueError(f"{source}: references must be a mapping actuator -> monitor -> values")
    out = {}
    for act, mons in refs.items():
        if not isinstance(mons, dict):
            raise ValueError(f"{source}: references[{act}] must be a mapping monitor -> values")
        bad = set(mons) - {"stiffness", "friction"}
        if bad:
            raise ValueError(f"{source}: references[{act}]: unknown monitor(s) {sorted(bad)}; known: friction, stiffness")
        o = {}
        if "stiffness" in mons:
            o["stiffness"] = StiffnessReference.from_dict(mons["stiffness"], f"{source} references[{act}][stiffness]").to_dict()
        if "friction" in mons:
            o["friction"] = FrictionReference.from_dict(mons["friction"], f"{source} references[{act}][friction]").to_dict()
        out[str(act)] = o
    return out


def make_node(context=None, overrides: dict[str, Any] | None = None, param_services: bool = True,
              autostart: bool = True):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import String

    from hd_ros.diagnostics import diag_status

    from hd_ros.managed import ManagedNode, bring_up

    class TwinNode(ManagedNode):
        def __init__(self):
            super().__init__(NODE_NAME, PARAMS, overrides, context=context, param_services=param_services)

        def configure(self):
            from hd_twin import state as sv

            self.model_roots = sv.model_roots(self.p["model_roots"], self.p["model_dir"])
            self.state = initial_state(self.p["model_dir"], self.p["params_file"])
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
            a = DiagnosticArray()
            a.header.stamp = self.get_clock().now().to_msg()
            a.status = [diag_status("hdphm/twin", 0, f"revision {self.state['revision']}", "twin-core",
                                    {"model_version": self.state["model_version"], "updates": self.n_updates,
                                     "refused": self.n_refused,
                                     "callback_errors": getattr(self, "n_callback_errors", 0)})]
            self.pub_diag.publish(a)

        def _on_update(self, msg):
            from hd_twin import state as sv

            data = msg.data if isinstance(msg.data, str) else ""
            key = hashlib.sha256(data.encode("utf-8", "replace")).digest()
            if key in self._seen:  # a latched update re-delivered after a restart
                return
            self._seen[key] = None
            while len(self._seen) > MAX_SEEN:
                self._seen.popitem(last=False)
            try:
                upd = sv.parse_json(data, ru.TOPIC_TWIN_UPDATE, sv.MAX_UPDATE_BYTES)
                self.state = apply_update(self.state, upd, ru.TOPIC_TWIN_UPDATE, self.model_roots)
            except ValueError as e:
                self.n_refused += 1
                self.refusals.append(sv.summary_of_refusal(e, data, time.time()))
                self.get_logger().warning(f"twin update refused: {str(e)[:300]}")
                a = DiagnosticArray()
                a.header.stamp = self.get_clock().now().to_msg()
                a.status = [diag_status("hdphm/twin", 1, f"update refused: {str(e)[:180]}", "twin-core",
                                        {"refused": self.n_refused})]
                self.pub_diag.publish(a)
                return
            self.n_updates += 1
            self.get_logger().info(f"twin revision {self.state['revision']} by {self.state['updated_by']}")
            self._publish()

    return bring_up(TwinNode(), autostart)
