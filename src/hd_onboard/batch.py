"""Batch driver: a whole :class:`hd_bag.mission.Mission` streamed through an :class:`hd_onboard.core.OnboardCore`
in blocks, exactly as the node streams it (batch evaluation, tests, benchmarks, the ground's calibration)."""

from __future__ import annotations

from typing import Any

import numpy as np

from hd_onboard.core import OnboardCore
from hd_onboard.detectors.levels import OK
from hd_onboard.residuals import RESIDUAL_COLUMNS


def run_mission(mission, core: OnboardCore | None = None, block: int = 1000, **kw) -> dict[str, Any]:
    """Batch: stream a whole Mission through an :class:`OnboardCore` in blocks of ``block`` samples.

    Temperatures and commands are pushed in stamp order between the blocks.
    Returns ``table`` (residual rows), ``windows`` (list of dicts), ``events``,
    ``level`` (final), ``max_level``, ``onset_s`` (first rise, s since the
    mission start or None), ``health`` (conditioning counts), ``core``.
    """
    if core is None:
        core = OnboardCore(gear_ratio=mission.meta.gear_ratio, **kw)
    t0 = mission.t0_ns
    stamps = t0 + np.round(mission.t * 1e9).astype(np.int64)
    V = np.column_stack([mission.theta_m, mission.theta_f, mission.omega_m, mission.omega_f, mission.tau_m, mission.Q_red])
    temps = []
    for frame, (tt, vv) in mission.temperatures.items():
        if frame == "gearbox" or "gearbox" not in mission.temperatures:
            temps = list(zip((t0 + np.round(np.asarray(tt) * 1e9)).astype(np.int64).tolist(), np.asarray(vv).tolist()))
            break
    cmds = list(zip((t0 + np.round(np.asarray(mission.t_cmd) * 1e9)).astype(np.int64).tolist(),
                    np.asarray(mission.theta_ref).tolist()))
    ti = ci = 0
    tables, windows, events = [], [], []
    for a in range(0, len(stamps), block):
        b = min(a + block, len(stamps))
        s0 = stamps[a]
        while ti < len(temps) and temps[ti][0] <= s0:
            core.push_temperature(*temps[ti])
            ti += 1
        while ci < len(cmds) and cmds[ci][0] <= s0:
            core.push_command(*cmds[ci])
            ci += 1
        r = core.push(stamps[a:b], V[a:b])
        tables.append(r.table)
        windows += r.windows
        events += r.events
    r = core.drain()  # a fixed-lag twin's last rows (before the last window closes)
    tables.append(r.table)
    windows += r.windows
    events += r.events
    windows += core.flush()
    core.end_mission()
    table = np.concatenate(tables) if tables else np.empty((0, len(RESIDUAL_COLUMNS)))
    max_level = int(table[:, 7].max()) if len(table) else OK
    return {
        "table": table,
        "windows": windows,
        "events": events,
        "level": core.level,
        "max_level": max_level,
        "onset_s": None if core.onset_ns is None else (core.onset_ns - t0) * 1e-9,
        "health": core.health,
        "core": core,
        "input": core.input_status(),  # (level, message): input problems and fallbacks (OnboardCore.input_status)
    }
