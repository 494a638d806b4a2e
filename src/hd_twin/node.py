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
validated (``TwinParams.from_dict`` bounds, threshold and reference sanity:
``hd_onboard.detector`` ``from_dict``); a bad one is refused
with a /diagnostics WARN naming the problem and the state is unchanged.
"""

from __future__ import annotations

import json
import time
from typing import Any

from hdphm import rosutil as ru

NODE_NAME = "twin"
PARAMS: dict[str, Any] = {
    "model_dir": "",  # trained twin directory (config.json + twin.onnx); "" -> physics-only stand-in
    "params_file": "",  # YAML of TwinParams; "" -> hd_twin/default_params.yaml (or the model's config)
}


def initial_state(model_dir: str = "", params_file: str = "") -> dict:
    """The twin state at start: parameters from the model's config.json, a params file, or the defaults."""
    from hd_twin import physics as ph

    state: dict[str, Any] = {"revision": 0, "model_dir": model_dir, "model_version": "physics-standin",
                             "effects": list(ph.DEFAULT_EFFECTS), "degradation_law": {"name": "archard"},
                             "thresholds": {}, "references": {}, "normalisation": {}, "updated_by": "init", "history": []}
    params = ph.TwinParams.from_yaml(params_file or None)
    if model_dir:
        from pathlib import Path

        cfgp = Path(model_dir) / "config.json"
        try:
            cfg = json.loads(cfgp.read_text())
        except FileNotFoundError:
            raise ValueError(f"{cfgp}: twin model directory has no config.json") from None
        except json.JSONDecodeError as e:
            raise ValueError(f"{cfgp}: not valid JSON ({e})") from None
        if isinstance(cfg.get("params"), dict) and not params_file:
            params = ph.TwinParams.from_dict({k: v for k, v in cfg["params"].items() if k in ph.TwinParams.__dataclass_fields__ or k in ("mu_g", "K_out")}, str(cfgp))
        state["model_version"] = str(cfg.get("version") or cfg.get("model_version") or Path(model_dir).name)
        state["effects"] = list(cfg.get("effects", state["effects"]))
        state["normalisation"] = cfg.get("normalization", {})
    state["params"] = params.to_dict()
    return state


def apply_update(state: dict, upd: dict, source: str = "update") -> dict:
    """New state = ``state`` with ``upd`` merged, validated; raises ValueError naming the bad field."""
    from hd_onboard.detector import ChannelThreshold
    from hd_twin import physics as ph

    known = {"params", "thresholds", "references", "normalisation", "effects", "degradation_law", "model_dir", "model_version", "updated_by"}
    unknown = set(upd) - known
    if unknown:
        raise ValueError(f"{source}: unknown key(s) {sorted(unknown)}; known: {sorted(known)}")
    new = json.loads(json.dumps(state))
    if "params" in upd:
        if not isinstance(upd["params"], dict):
            raise ValueError(f"{source}: params must be a mapping")
        merged = {k: v for k, v in new["params"].items() if k not in ("mu_g", "K_out")}
        merged.update({k: v for k, v in upd["params"].items() if k not in ("mu_g", "K_out")})
        new["params"] = ph.TwinParams.from_dict(merged, where=f"{source} params").to_dict()
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
    new["updated_by"] = str(upd.get("updated_by", source))
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
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    from hd_onboard.node import declare, diag_status

    from hdphm.managed import ManagedNode, bring_up

    class TwinNode(ManagedNode):
        def __init__(self):
            po = [Parameter(k, value=v) for k, v in (overrides or {}).items()]
            super().__init__(NODE_NAME, context=context, parameter_overrides=po,
                             start_parameter_services=param_services)
            self.p = declare(self, PARAMS)

        def configure(self):
            self.state = initial_state(self.p["model_dir"], self.p["params_file"])
            self.pub = self.create_publisher(String, ru.TOPIC_TWIN_STATE, ru.qos("latched"))
            self.pub_diag = self.create_publisher(DiagnosticArray, ru.TOPIC_DIAGNOSTICS, ru.qos("diagnostics"))
            self.create_subscription(String, ru.TOPIC_TWIN_UPDATE, self._on_update, ru.qos("latched"))
            self.n_updates = self.n_refused = 0
            self._seen: set[str] = set()

        def activate(self):
            self._publish()

        def _publish(self):
            self.pub.publish(ru.json_msg(self.state))
            a = DiagnosticArray()
            a.header.stamp = self.get_clock().now().to_msg()
            a.status = [diag_status("hdphm/twin", 0, f"revision {self.state['revision']}", "twin-core",
                                    {"model_version": self.state["model_version"], "updates": self.n_updates,
                                     "refused": self.n_refused})]
            self.pub_diag.publish(a)

        def _on_update(self, msg):
            if msg.data in self._seen:  # a latched update re-delivered after a restart
                return
            self._seen.add(msg.data)
            try:
                upd = ru.parse_json_msg(msg, ru.TOPIC_TWIN_UPDATE)
                self.state = apply_update(self.state, upd, ru.TOPIC_TWIN_UPDATE)
            except ValueError as e:
                self.n_refused += 1
                self.get_logger().error(f"twin update refused: {e}")
                a = DiagnosticArray()
                a.header.stamp = self.get_clock().now().to_msg()
                a.status = [diag_status("hdphm/twin", 1, f"update refused: {str(e)[:180]}", "twin-core", {})]
                self.pub_diag.publish(a)
                return
            self.n_updates += 1
            self.get_logger().info(f"twin revision {self.state['revision']} by {self.state['updated_by']}")
            self._publish()

    return bring_up(TwinNode(), autostart)
