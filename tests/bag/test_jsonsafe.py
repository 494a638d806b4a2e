"""hd_bag.jsonsafe.json_safe: the one converter writes valid JSON (non-finite -> null)."""

import json
import math

import numpy as np

from hd_bag.jsonsafe import json_safe


def test_json_safe_nonfinite_numpy_and_keys():
    o = {1: np.float32(0.5), "a": [math.nan, np.inf, -math.inf, np.int64(3)], "t": (1.0, np.arange(2.0)),
         "s": "NaN in a name stays"}
    out = json_safe(o)
    assert out == {"1": 0.5, "a": [None, None, None, 3], "t": [1.0, [0.0, 1.0]], "s": "NaN in a name stays"}
    assert type(out["a"][3]) is int
    json.dumps(out, allow_nan=False)  # valid JSON: raises on NaN/Infinity
