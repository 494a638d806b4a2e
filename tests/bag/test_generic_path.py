"""The generic-decoder fallback of the reader gives exactly what the vectorised path gives."""

import numpy as np

from hd_bag import cdr, read_mission, write_mission
from tests.bag.conftest import make_mission


def test_generic_fallback_equals_vectorised_path(tmp_path, monkeypatch):
    path = tmp_path / "m.mcap"
    write_mission(path, make_mission(n=1500))
    fast = read_mission(path)
    # Layouts the fast path cannot parse (e.g. another tool's encoding) go to the generic decoder.
    monkeypatch.setattr(cdr, "parse_jointstate_layout", lambda data: None)
    monkeypatch.setattr(cdr, "parse_temperature_frame", lambda data: None)
    slow = read_mission(path)
    assert slow.n == fast.n == 1500
    for name in ("t", "theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red", "t_cmd", "theta_ref"):
        np.testing.assert_array_equal(getattr(slow, name), getattr(fast, name), err_msg=name)
    assert slow.temperatures.keys() == fast.temperatures.keys()
    for frame, (tt, vv) in fast.temperatures.items():
        np.testing.assert_array_equal(slow.temperatures[frame][0], tt)
        np.testing.assert_array_equal(slow.temperatures[frame][1], vv)
