"""The one JSON-safe converter of the project (reports, model configs, node messages, caches), and the
capped JSON reader of untrusted text (node messages: size and nesting checked before ``json.loads``)."""

from __future__ import annotations

import json
import math
import re
from typing import Any

import numpy as np


def json_safe(o: Any) -> Any:
    """``o`` with numpy scalars and arrays as Python numbers and lists, dict keys as strings, tuples as
    lists, and every non-finite float (NaN, +-inf) as None, so ``json.dumps`` writes valid JSON
    (``null``; readers map it back to NaN where a number is expected). Other values are returned as
    they are."""
    if isinstance(o, dict):
        return {str(k): json_safe(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [json_safe(v) for v in o]
    if isinstance(o, (np.floating, float)):
        f = float(o)
        return f if math.isfinite(f) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.ndarray):
        return json_safe(o.tolist())
    return o


_STRING_RE = re.compile(r'"(?:[^"\\]|\\.)*"', re.S)


def json_depth(text: str) -> int:
    """Deepest bracket nesting of a JSON text (strings skipped), without recursion."""
    stripped = _STRING_RE.sub("", text)
    a = np.frombuffer(stripped.encode("utf-8", "replace"), np.uint8)
    if a.size == 0:
        return 0
    step = ((a == ord("{")) | (a == ord("["))).astype(np.int32) - ((a == ord("}")) | (a == ord("]"))).astype(np.int32)
    return int(np.cumsum(step).max())


def _no_constant(name: str):
    raise ValueError(f"{name} is not a finite number (NaN/Infinity are not allowed)")


def parse_json_object(text: Any, what: str, max_bytes: int, max_depth: int) -> dict:
    """A JSON object from ``text`` within the size and depth caps (checked on the text, before
    ``json.loads`` can recurse), without NaN/Infinity literals; ValueError naming ``what`` otherwise."""
    if not isinstance(text, str):
        raise ValueError(f"{what}: expected JSON text, got {type(text).__name__}")
    if len(text) > max_bytes or len(text.encode("utf-8", "replace")) > max_bytes:
        raise ValueError(f"{what}: {len(text)} characters, above the cap of {max_bytes} bytes")
    d = json_depth(text)
    if d > max_depth:
        raise ValueError(f"{what}: JSON nested {d} deep, above the cap of {max_depth}")
    try:
        obj = json.loads(text, parse_constant=_no_constant)
    except RecursionError:
        raise ValueError(f"{what}: JSON nested too deep") from None
    except ValueError as e:  # JSONDecodeError is a ValueError; so is _no_constant's
        raise ValueError(f"{what}: not valid JSON ({e})") from None
    if not isinstance(obj, dict):
        raise ValueError(f"{what}: expected a JSON object, got {type(obj).__name__}")
    return obj
