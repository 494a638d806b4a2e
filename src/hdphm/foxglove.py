"""The Foxglove layout shipped for recorded stack MCAPs (``ros2_ws/foxglove/hdphm.json``) and its check.

``layout_paths`` lists every (topic, field path, label) the layout's panels name; ``check_layout``
opens a recorded MCAP and says, for each, what is wrong: a topic absent from the file, a field path
that does not resolve in its first message, or, for our ``Float64MultiArray`` tables, a column index
whose name (``layout.dim[1].label``) is not the label the layout gives it (so a reordered table
breaks the check, not silently the plot).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

LAYOUT = Path(__file__).resolve().parents[2] / "ros2_ws" / "foxglove" / "hdphm.json"
_SEG = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?$")


def load_layout(path: str | Path = LAYOUT) -> dict:
    return json.loads(Path(path).read_text())


def layout_paths(layout: dict) -> list[tuple[str, str, str]]:
    """(topic, field path after the topic, label) for every panel path; topic-only panels give field ''."""
    out = []
    for pid, cfg in layout.get("configById", {}).items():
        for p in cfg.get("paths", []) or []:
            v = p["value"]
            topic, _, field = v.partition(".")
            out.append((topic, field, p.get("label", "")))
        for key in ("topicToRender", "topicPath"):
            if cfg.get(key):
                out.append((cfg[key], "", pid))
    return out


def _resolve(msg, field: str):
    obj = msg
    for seg in field.split(".") if field else []:
        m = _SEG.match(seg)
        if not m:
            raise KeyError(f"unsupported path segment {seg!r}")
        obj = getattr(obj, m.group(1))
        if m.group(2) is not None:
            idx = int(m.group(2))
            if idx >= len(obj):
                raise IndexError(f"{m.group(1)}[{idx}] but the message has {len(obj)} elements")
            obj = obj[idx]
    return obj


def check_layout(mcap_path: str | Path, layout: dict | None = None) -> list[str]:
    """Problems of the layout against one recorded MCAP (empty list: every path resolves)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    layout = layout or load_layout()
    wanted = layout_paths(layout)
    topics = {t for t, _f, _l in wanted}
    first: dict[str, object] = {}
    with open(mcap_path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, _message, decoded in reader.iter_decoded_messages(topics=sorted(topics)):
            if channel.topic not in first:
                first[channel.topic] = decoded
            if len(first) == len(topics):
                break
    problems = []
    for topic, field, label in wanted:
        if topic not in first:
            problems.append(f"{mcap_path}: topic {topic} (panel path {topic}.{field}) has no message in the file")
            continue
        if not field:
            continue
        msg = first[topic]
        try:
            _resolve(msg, field)
        except (AttributeError, KeyError, IndexError) as e:
            problems.append(f"{mcap_path}: {topic}.{field} does not resolve: {e}")
            continue
        m = re.fullmatch(r"data\[(\d+)\]", field)
        if m and hasattr(msg, "layout") and len(msg.layout.dim) >= 2:
            cols = msg.layout.dim[1].label.split(",")
            i = int(m.group(1))
            if i >= len(cols) or cols[i] != label:
                problems.append(f"{mcap_path}: {topic}.{field} is column {cols[i] if i < len(cols) else '?'!r} "
                                f"but the layout labels it {label!r}")
    return problems
