"""The one JSON-safe converter of the project (reports, model configs, node messages, caches)."""

from __future__ import annotations

import math
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
