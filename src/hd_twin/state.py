"""Schema of the twin state and of updates on ``/hd/twin/update``: pure validation, no ROS.

Every field of an update is checked before anything is merged (issue 13: one message must not crash
a node, poison the state, or grow memory):

* the JSON text itself: at most :data:`MAX_UPDATE_BYTES` (state: :data:`MAX_STATE_BYTES`), nesting at
  most :data:`MAX_JSON_DEPTH` (checked on the text, before ``json.loads`` can recurse), no NaN or
  Infinity literals;
* types: mappings where mappings belong, numbers that are numbers (``true`` is not a gear ratio),
  strings no longer than :data:`MAX_TEXT`, lists no longer than :data:`MAX_LIST`, at most
  :data:`MAX_ENTRIES` keys per mapping;
* values: every number finite; twin parameters inside ``physics._BOUNDS`` and with a positive input
  inertia ``J_WG + J_rotor`` and output inertia ``J_CS``;
* identifiers (actuator ids, channel names) safe as file names (``hd_bag.writer.safe_identifier``);
* ``model_dir``: empty (physics stand-in) or a directory inside one of the configured model roots
  (symbolic links resolved), never any path a graph participant names.

A refusal is a ``ValueError`` whose message starts with the field path (``params.N: ...``).
The semantic checks of the per-actuator records (threshold and reference ``from_dict``,
:mod:`hd_twin.records`) run in :func:`parse_thresholds` / :func:`parse_references`; the state itself
is built and merged here too (:func:`initial_state`, :func:`apply_update`, :func:`read_state` for a
consumer), so the twin node and the onboard node only convert messages.
"""

from __future__ import annotations

import json
import math
import os
import time
from typing import Any, Iterable

from hd_bag.jsonsafe import json_depth, parse_json_object  # noqa: F401 - json_depth re-exported

#: An update carries parameters, thresholds and references of some actuators: a few KiB. 1 MiB
#: holds thresholds for thousands of actuators.
MAX_UPDATE_BYTES = 1 << 20
#: The published state (parsed by the onboard node): a fleet's thresholds and references.
MAX_STATE_BYTES = 16 << 20
#: Deepest legal nesting: references.<act>.<monitor>.<field>.<list> = 5; params.notes.<k> = 3.
MAX_JSON_DEPTH = 8
MAX_TEXT = 256  # updated_by, model_version, names
MAX_NOTE = 2048  # params.source / params.notes values (provenance text)
MAX_LIST = 4096
MAX_ENTRIES = 10_000
MAX_PATH = 4096
KNOWN_KEYS = ("params", "thresholds", "references", "normalisation", "effects", "degradation_law", "model_dir",
              "model_version", "updated_by")


class UpdateError(ValueError):
    """A refused update or state: ``field`` is the dotted path of the offending field."""

    def __init__(self, field: str, problem: str):
        self.field = field
        super().__init__(f"{field}: {problem}" if field else problem)


def parse_json(text: Any, what: str, max_bytes: int = MAX_UPDATE_BYTES, max_depth: int = MAX_JSON_DEPTH) -> dict:
    """A JSON object from ``text`` within the size and depth caps (:func:`hd_bag.jsonsafe.parse_json_object`);
    :class:`UpdateError` naming ``what`` otherwise."""
    try:
        return parse_json_object(text, what, max_bytes, max_depth)
    except ValueError as e:
        raise UpdateError("", str(e)) from None


# ---- generic checks ----------------------------------------------------------------------------------
def number(v: Any, field: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise UpdateError(field, f"must be a number, got {type(v).__name__} {_short(v)}")
    f = float(v)
    if not math.isfinite(f):
        raise UpdateError(field, f"{f!r} is not a finite number")
    if not lo <= f <= hi:
        raise UpdateError(field, f"{f!r} outside [{lo:g}, {hi:g}]")
    return f


def text(v: Any, field: str, max_len: int = MAX_TEXT) -> str:
    if not isinstance(v, str):
        raise UpdateError(field, f"must be a string, got {type(v).__name__} {_short(v)}")
    if len(v) > max_len:
        raise UpdateError(field, f"string of {len(v)} characters, above the cap of {max_len}")
    return v


def identifier(v: Any, field: str) -> str:
    from hd_bag.writer import safe_identifier

    s = text(v, field)
    why = safe_identifier(s, "identifier")
    if why:
        raise UpdateError(field, why)
    return s


def mapping(v: Any, field: str) -> dict:
    if not isinstance(v, dict):
        raise UpdateError(field, f"must be a mapping, got {type(v).__name__} {_short(v)}")
    if len(v) > MAX_ENTRIES:
        raise UpdateError(field, f"{len(v)} entries, above the cap of {MAX_ENTRIES}")
    return v


def tree(v: Any, field: str, depth: int = 0) -> Any:
    """Check a JSON value of free shape: finite numbers, short strings, short lists, bounded depth."""
    if depth > MAX_JSON_DEPTH:
        raise UpdateError(field, f"nested deeper than {MAX_JSON_DEPTH}")
    if v is None or isinstance(v, bool):
        return v
    if isinstance(v, (int, float)):
        return number(v, field)
    if isinstance(v, str):
        return text(v, field, MAX_NOTE)
    if isinstance(v, list):
        if len(v) > MAX_LIST:
            raise UpdateError(field, f"list of {len(v)} items, above the cap of {MAX_LIST}")
        return [tree(x, f"{field}[{i}]", depth + 1) for i, x in enumerate(v)]
    if isinstance(v, dict):
        mapping(v, field)
        return {text(k, f"{field} key"): tree(x, f"{field}.{k}", depth + 1) for k, x in v.items()}
    raise UpdateError(field, f"unsupported JSON value {type(v).__name__}")


def _short(v: Any) -> str:
    r = repr(v)
    return r if len(r) <= 60 else r[:57] + "..."


# ---- fields ------------------------------------------------------------------------------------------
def check_params(p: Any, field: str = "params") -> dict:
    """Twin parameters (a subset): known names, numbers (not bool) inside the physical bounds."""
    from hd_twin import physics as ph

    import dataclasses

    mapping(p, field)
    names = {f.name for f in dataclasses.fields(ph.TwinParams)}
    out: dict[str, Any] = {}
    for k, v in p.items():
        f = f"{field}.{k}"
        if k in ("mu_g", "K_out"):  # derived: recomputed from the others
            continue
        if k not in names:
            raise UpdateError(f, f"unknown parameter; known: {', '.join(sorted(names))}")
        if k == "source":
            out[k] = text(v, f, MAX_NOTE)
        elif k == "notes":
            mapping(v, f)
            if len(v) > 64:
                raise UpdateError(f, f"{len(v)} notes, above the cap of 64")
            out[k] = {text(a, f"{f} key"): text(b, f"{f}.{a}", MAX_NOTE) for a, b in v.items()}
        else:
            lo, hi = ph._BOUNDS.get(k, (-math.inf, math.inf))
            out[k] = number(v, f, lo, hi)
    return out


def check_merged_params(p: dict, field: str = "params") -> None:
    """Conditions across parameters of a complete set: inertias must be positive."""
    j_in = float(p.get("J_WG", 0.0)) + float(p.get("J_rotor", 0.0))
    if not j_in > 0:
        raise UpdateError(f"{field}.J_WG", f"input inertia J_WG + J_rotor = {j_in!r} kg*m^2 must be > 0")
    if not float(p.get("J_CS", 0.0)) > 0:
        raise UpdateError(f"{field}.J_CS", f"output inertia J_CS = {p.get('J_CS')!r} kg*m^2 must be > 0")


def check_per_actuator(v: Any, field: str) -> dict:
    """thresholds / references: {actuator id: {name: {field: value}}} with safe ids and finite values."""
    mapping(v, field)
    out = {}
    for act, inner in v.items():
        fa = f"{field}.{act}" if isinstance(act, str) and len(act) <= MAX_TEXT else f"{field}[...]"
        identifier(act, fa)
        mapping(inner, fa)
        out[act] = {}
        for name, vals in inner.items():
            fn = f"{fa}.{name}"
            identifier(name, fn)
            out[act][name] = tree(mapping(vals, fn), fn, 2)
    return out


def check_effects(v: Any, field: str = "effects") -> list[str]:
    if not isinstance(v, list):
        raise UpdateError(field, f"must be a list of effect names, got {type(v).__name__} {_short(v)}")
    if len(v) > 64:
        raise UpdateError(field, f"{len(v)} effects, above the cap of 64")
    out = [text(e, f"{field}[{i}]", 64) for i, e in enumerate(v)]
    if not all(out):
        raise UpdateError(field, "effect names must not be empty")
    if len(set(out)) != len(out):
        raise UpdateError(field, "duplicate effect names")
    return out


def check_degradation_law(v: Any, field: str = "degradation_law") -> dict:
    mapping(v, field)
    out = tree(v, field)
    if "name" in out:
        text(out["name"], f"{field}.name", 64)
    return out


def model_roots(configured: str | Iterable[str] = "", initial_model_dir: str = "") -> list[str]:
    """Directories a ``model_dir`` may lie in: the configured ones (``os.pathsep``-separated or a list),
    ``$HDPHM_MODEL_ROOTS``, and the parent of the model directory the node started with."""
    items: list[str] = []
    if isinstance(configured, str):
        items += [c for c in configured.split(os.pathsep) if c]
    else:
        items += [str(c) for c in configured if c]
    items += [c for c in os.environ.get("HDPHM_MODEL_ROOTS", "").split(os.pathsep) if c]
    if initial_model_dir:
        items.append(os.path.dirname(os.path.abspath(initial_model_dir)))
    out = []
    for c in items:
        r = os.path.realpath(c)
        if r not in out and r != os.path.sep:  # "/" as a root would allow everything
            out.append(r)
    return out


_roots = model_roots  # apply_update's parameter of that name shadows the function


def check_model_dir(v: Any, roots: list[str], field: str = "model_dir") -> str:
    s = text(v, field, MAX_PATH)
    if s == "":
        return s
    if "\x00" in s:
        raise UpdateError(field, "contains a NUL byte")
    real = os.path.realpath(s)
    inside = [r for r in roots if os.path.commonpath([real, r]) == r]
    if not inside:
        raise UpdateError(field, f"{_short(s)} is not inside a configured model root "
                                 f"({', '.join(roots) if roots else 'none configured: set model_roots'})")
    if not os.path.isdir(real):
        raise UpdateError(field, f"{_short(s)} is not a directory")
    return s


def check_update(upd: Any, roots: list[str], where: str = "update") -> dict:
    """Every field of an update checked (see the module docstring); returns the checked update (same shape,
    numbers as float). Raises :class:`UpdateError` naming the field."""
    mapping(upd, "")
    unknown = sorted(str(k)[:40] for k in upd if k not in KNOWN_KEYS)
    if unknown:
        raise UpdateError(unknown[0], f"unknown key(s) {unknown}; known: {', '.join(KNOWN_KEYS)}")
    out: dict[str, Any] = {}
    if "params" in upd:
        out["params"] = check_params(upd["params"])
    for k in ("thresholds", "references"):
        if k in upd:
            out[k] = check_per_actuator(upd[k], k)
    if "normalisation" in upd:
        out["normalisation"] = tree(mapping(upd["normalisation"], "normalisation"), "normalisation")
    if "degradation_law" in upd:
        out["degradation_law"] = check_degradation_law(upd["degradation_law"])
    if "effects" in upd:
        out["effects"] = check_effects(upd["effects"])
    if "model_dir" in upd:
        out["model_dir"] = check_model_dir(upd["model_dir"], roots)
    for k in ("model_version", "updated_by"):
        if k in upd:
            out[k] = text(upd[k], k)
    return out


#: /hd/mission values checked when present: (low, high, low inclusive)
_MISSION_NUMBERS = {"gear_ratio": (0.0, 10_000.0, False), "torque_constant": (0.0, 100.0, False),
                    "operating_hours": (0.0, 1e6, True), "mission_index": (0.0, 1e7, True)}


def check_mission(meta: dict, where: str = "/hd/mission") -> dict:
    """A ``/hd/mission`` document (the bag's ``hd_mission`` record as JSON, values usually strings):
    ``actuator_id`` a safe identifier, the numeric keys numbers (or numeric strings, not bool) that are
    finite and plausible (as ``hd_bag.writer.check_meta``). Returns ``meta``; UpdateError naming the key."""
    mapping(meta, where)
    if "actuator_id" in meta:
        if not isinstance(meta["actuator_id"], (str, int)) or isinstance(meta["actuator_id"], bool):
            raise UpdateError(f"{where} actuator_id", f"must be a string, got {_short(meta['actuator_id'])}")
        identifier(str(meta["actuator_id"]), f"{where} actuator_id")
    for k, (lo, hi, incl) in _MISSION_NUMBERS.items():
        if k not in meta:
            continue
        v = meta[k]
        f = f"{where} {k}"
        if isinstance(v, str):
            try:
                v = float(v.strip()[:64])
            except ValueError:
                raise UpdateError(f, f"{_short(meta[k])} is not a number") from None
        x = number(v, f, lo, hi)
        if not incl and x <= lo:
            raise UpdateError(f, f"{x!r} must be > {lo:g}")
    return meta


def refusal(source: str, e: UpdateError) -> ValueError:
    """``e`` with ``source`` in front of its message, keeping its field."""
    r = ValueError(f"{source}: {e}")
    r.field = e.field
    return r


def summary_of_refusal(e: Exception, data: str, wall_time: float) -> dict:
    """A short, bounded record of a refused update (kept in the node's refusal memory)."""
    import hashlib

    return {"wall_time": wall_time, "bytes": len(data), "sha1": hashlib.sha1(data.encode("utf-8", "replace")).hexdigest()[:12],
            "field": getattr(e, "field", ""), "problem": str(e)[:200]}


# ---- the per-actuator records (thresholds, monitor references) -----------------------------------
def parse_thresholds(ths: Any, where: str, channels: Iterable[str] | None = None) -> dict[str, dict[str, Any]]:
    """``{actuator: {channel: {...}}}`` -> ``{actuator: {channel: ChannelThreshold}}`` (validated; ValueError
    naming ``where``, the actuator and the channel). ``channels``: keep only these (the onboard core's)."""
    from hd_twin.records import ChannelThreshold

    if not isinstance(ths, dict):
        raise ValueError(f"{where}: thresholds must be a mapping actuator -> channel -> values")
    keep = None if channels is None else set(channels)
    out: dict[str, dict[str, Any]] = {}
    for act, chans in ths.items():
        if not isinstance(chans, dict):
            raise ValueError(f"{where}: thresholds[{act}] must be a mapping channel -> values")
        out[act] = {c: ChannelThreshold.from_dict(v, f"{where} thresholds[{act}][{c}]")
                    for c, v in chans.items() if keep is None or c in keep}
    return out


def parse_references(refs: Any, where: str = "update") -> dict[str, dict[str, Any]]:
    """``{actuator: {"stiffness": {...}, "friction": {...}}}`` (either monitor may be absent) ->
    ``{actuator: {"stiffness": StiffnessReference, "friction": FrictionReference}}``, checked entry by
    entry; ValueError naming ``where``, the actuator and the monitor. Used by the twin core (merging an
    update) and the onboard node (applying the state)."""
    from hd_twin.records import FrictionReference, StiffnessReference

    if not isinstance(refs, dict):
        raise ValueError(f"{where}: references must be a mapping actuator -> monitor -> values")
    out: dict[str, dict[str, Any]] = {}
    for act, mons in refs.items():
        if not isinstance(mons, dict):
            raise ValueError(f"{where}: references[{act}] must be a mapping monitor -> values")
        bad = set(mons) - {"stiffness", "friction"}
        if bad:
            raise ValueError(f"{where}: references[{act}]: unknown monitor(s) {sorted(bad)}; known: friction, stiffness")
        o: dict[str, Any] = {}
        if "stiffness" in mons:
            o["stiffness"] = StiffnessReference.from_dict(mons["stiffness"], f"{where} references[{act}][stiffness]")
        if "friction" in mons:
            o["friction"] = FrictionReference.from_dict(mons["friction"], f"{where} references[{act}][friction]")
        out[str(act)] = o
    return out


# ---- the twin state: initial, merged with an update, read by a consumer ----------------------------
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
    :func:`model_roots` for the state's current ``model_dir``)."""
    from hd_twin import physics as ph

    if model_roots is None:
        model_roots = _roots("", state.get("model_dir", ""))
    try:
        upd = check_update(upd, model_roots, source)
    except UpdateError as e:
        raise refusal(source, e) from None
    new = json.loads(json.dumps(state))
    if "params" in upd:
        if not isinstance(upd["params"], dict):
            raise ValueError(f"{source}: params must be a mapping")
        merged = {k: v for k, v in new["params"].items() if k not in ("mu_g", "K_out")}
        merged.update({k: v for k, v in upd["params"].items() if k not in ("mu_g", "K_out")})
        new["params"] = ph.TwinParams.from_dict(merged, where=f"{source} params").to_dict()
        try:
            check_merged_params(new["params"])
        except UpdateError as e:
            raise refusal(source, e) from None
    if "thresholds" in upd:
        for act, chans in parse_thresholds(upd["thresholds"], source).items():
            new["thresholds"].setdefault(act, {}).update({c: t.to_dict() for c, t in chans.items()})
    if "references" in upd:
        new.setdefault("references", {})
        for act, refs in parse_references(upd["references"], source).items():
            new["references"].setdefault(act, {}).update({m: r.to_dict() for m, r in refs.items()})
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
    new["updated_by"] = str(upd.get("updated_by", source))[:MAX_TEXT]
    size = len(json.dumps(new))
    if size > MAX_STATE_BYTES // 2:  # merged thresholds/references grow per actuator: bound the whole state
        raise ValueError(f"{source}: the state would grow to {size} bytes, above the cap of {MAX_STATE_BYTES // 2} "
                         "(hd_twin.state.MAX_STATE_BYTES / 2)")
    new["history"] = (state.get("history", []) + [{"revision": new["revision"], "by": new["updated_by"], "keys": sorted(upd),
                                                     "wall_time": time.time()}])[-20:]
    return new


def read_state(text: Any, where: str, roots: list[str], default_params, channels: Iterable[str] | None = None):
    """A published twin state as a consumer (the onboard node) applies it: ``(state, params, thresholds,
    references)`` with params a ``TwinParams`` (``default_params`` when the state has none), thresholds
    ``{actuator: {channel: ChannelThreshold}}`` (``channels`` only) and references as
    :func:`parse_references`. ``model_dir`` must lie inside ``roots`` (an ONNX file is loaded from it).
    ValueError naming ``where`` and the field otherwise."""
    from hd_twin import physics as ph

    st = parse_json(text, where, MAX_STATE_BYTES)
    if st.get("model_dir"):
        check_model_dir(st["model_dir"], roots, f"{where} model_dir")
    for k in ("thresholds", "references"):
        if st.get(k) is not None:
            check_per_actuator(st[k], f"{where} {k}")
    params = ph.TwinParams.from_dict(st.get("params", {}), where=where) if st.get("params") else default_params
    return (st, params, parse_thresholds(st.get("thresholds") or {}, where, channels),
            parse_references(st.get("references") or {}, where))


__all__ = ["MAX_UPDATE_BYTES", "MAX_STATE_BYTES", "MAX_JSON_DEPTH", "UpdateError", "parse_json", "json_depth",
           "check_update", "check_params", "check_merged_params", "check_model_dir", "model_roots",
           "summary_of_refusal", "parse_thresholds", "parse_references", "initial_state", "apply_update", "read_state"]
