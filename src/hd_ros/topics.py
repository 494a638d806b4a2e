"""Topics of the hdphm stack: names, message types, and the one table of topic -> (type, QoS class).

Only standard message types travel on the wire (no custom .msg packages can be built from the
wheels): ``sensor_msgs``, ``std_msgs``, ``diagnostic_msgs``. Every topic of the stack is listed in
:data:`STACK_TOPICS` with its QoS class (:mod:`hd_ros.qos`), so nodes, replay and the recorder agree
by construction; ``docs/INTERFACES.md`` is the human table of the same facts.

Also here: :func:`message_class` (a type name -> message class, from a fixed table of interface
packages only) and :func:`message_definition` (the ``ros2msg`` schema text ``ros2 bag`` writes).
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path

# --------------------------------------------------------------------------
# topic names
# --------------------------------------------------------------------------
TOPIC_JOINT_STATES = "/hd/joint_states"
TOPIC_COMMAND = "/hd/command"
TOPIC_TEMPERATURE = "/hd/temperature"
CONTRACT_TOPICS = (TOPIC_JOINT_STATES, TOPIC_COMMAND, TOPIC_TEMPERATURE)
#: Mission metadata (the bag's ``hd_mission`` record) as JSON, latched; published by replay
#: (or a live actuator's driver) before the samples of a mission.
TOPIC_MISSION = "/hd/mission"
TOPIC_TWIN_STATE = "/hd/twin/state"
TOPIC_TWIN_UPDATE = "/hd/twin/update"
TOPIC_RESIDUALS = "/hd/onboard/residuals"
TOPIC_FEATURES = "/hd/onboard/features"
TOPIC_HEALTH = "/hd/prognostic/health"
TOPIC_GROUND_REPORT = "/hd/ground/report"
TOPIC_DIAGNOSTICS = "/diagnostics"

#: type strings as they appear in the ROS graph and in MCAP schema names
TYPE_JOINT_STATE = "sensor_msgs/msg/JointState"
TYPE_TEMPERATURE = "sensor_msgs/msg/Temperature"
TYPE_STRING = "std_msgs/msg/String"
TYPE_F64_ARRAY = "std_msgs/msg/Float64MultiArray"
TYPE_DIAG_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"

#: topic -> (type, qos key) for every topic the stack itself publishes or consumes.
STACK_TOPICS: dict[str, tuple[str, str]] = {
    TOPIC_JOINT_STATES: (TYPE_JOINT_STATE, "sensor"),
    TOPIC_COMMAND: (TYPE_JOINT_STATE, "sensor"),
    TOPIC_TEMPERATURE: (TYPE_TEMPERATURE, "sensor"),
    TOPIC_MISSION: (TYPE_STRING, "latched"),
    TOPIC_TWIN_STATE: (TYPE_STRING, "latched"),
    TOPIC_TWIN_UPDATE: (TYPE_STRING, "latched"),
    TOPIC_RESIDUALS: (TYPE_F64_ARRAY, "stream"),
    TOPIC_FEATURES: (TYPE_F64_ARRAY, "stream"),
    TOPIC_HEALTH: (TYPE_F64_ARRAY, "stream"),
    TOPIC_GROUND_REPORT: (TYPE_STRING, "latched"),
    TOPIC_DIAGNOSTICS: (TYPE_DIAG_ARRAY, "diagnostics"),
}


#: Interface packages of the ROS distribution whose message modules may be imported to subscribe to a
#: topic (``pkg.msg`` of these packages only): a type name advertised on the graph or written in a bag
#: selects a class from this fixed set, it never names a module to import (issue 13: a participant
#: advertising ``evilpkg/msg/X`` would have made the recorder import ``evilpkg.msg``).
MESSAGE_PACKAGES = frozenset((
    "std_msgs", "sensor_msgs", "diagnostic_msgs", "geometry_msgs", "builtin_interfaces", "rcl_interfaces",
    "nav_msgs", "trajectory_msgs", "shape_msgs", "stereo_msgs", "visualization_msgs", "tf2_msgs",
    "action_msgs", "unique_identifier_msgs", "statistics_msgs", "rosgraph_msgs", "lifecycle_msgs",
    "type_description_interfaces", "service_msgs",
))
_NAME_RE = None


def message_class(type_name: str):
    """Message class from a type string ``pkg/msg/Name`` (or ``pkg/Name``) of a package in
    :data:`MESSAGE_PACKAGES`; ValueError for anything else (nothing is imported for it)."""
    import re

    global _NAME_RE
    if _NAME_RE is None:
        _NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,127}")
    parts = str(type_name).split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(parts) or parts[1] != "msg" or not _NAME_RE.fullmatch(parts[2]):
        raise ValueError(f"not a ROS message type name: {str(type_name)[:80]!r}")
    if parts[0] not in MESSAGE_PACKAGES:
        raise ValueError(f"message type {type_name!r} is not in the fixed table of interface packages "
                         f"(hd_ros.topics.MESSAGE_PACKAGES); not imported")
    try:
        mod = importlib.import_module(f"{parts[0]}.msg")
        cls = getattr(mod, parts[2])
    except (ImportError, AttributeError):
        raise ValueError(f"message type {type_name!r} is not installed in this environment") from None
    if not hasattr(cls, "_TYPE_SUPPORT") and not hasattr(type(cls), "_TYPE_SUPPORT"):
        raise ValueError(f"{type_name!r} is not a message class")
    return cls


_SHARE_DIRS: list[Path] | None = None


def _share_dirs() -> list[Path]:
    global _SHARE_DIRS
    if _SHARE_DIRS is None:
        import sys

        cands = [Path(sys.prefix) / "share"]
        cands += [Path(p) / "share" for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
        _SHARE_DIRS = [c for c in cands if c.is_dir()]
    return _SHARE_DIRS


def _msg_file(pkg: str, name: str) -> str:
    for d in _share_dirs():
        f = d / pkg / "msg" / f"{name}.msg"
        if f.is_file():
            return f.read_text()
    raise ValueError(f"no .msg definition found for {pkg}/msg/{name} under {', '.join(map(str, _share_dirs()))}")


_PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
    "int64", "uint64", "string", "wstring",
}


def message_definition(type_name: str) -> str:
    """Full ``ros2msg`` schema text of a type with its dependencies, as ``ros2 bag`` writes it.

    The main definition, then for every nested type a ``====`` separator line
    and ``MSG: pkg/Name`` followed by its definition (depth-first, each once).
    """
    parts = type_name.split("/")
    pkg, name = parts[0], parts[-1]
    seen: list[str] = []
    texts: dict[str, str] = {}

    def deps(p: str, text: str) -> list[str]:
        out = []
        for line in text.splitlines():
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            tok = line.split()[0]
            base = tok.split("[", 1)[0].split("<=", 1)[0]
            if base in _PRIMITIVES or "=" in line.split(None, 1)[-1][:1]:
                continue
            if base == "Header":
                q = "std_msgs/Header"
            elif "/" in base:
                q = base.replace("/msg/", "/")
            else:
                q = f"{p}/{base}"
            out.append(q)
        return out

    def visit(q: str) -> None:
        if q in texts:
            return
        p, n = q.split("/")
        texts[q] = _msg_file(p, n)
        seen.append(q)
        for d in deps(p, texts[q]):
            visit(d)

    visit(f"{pkg}/{name}")
    main = texts[seen[0]]
    out = [main.rstrip("\n")]
    for q in seen[1:]:
        out.append("=" * 80 + f"\nMSG: {q}\n" + texts[q].rstrip("\n"))
    return "\n".join(out) + "\n"

