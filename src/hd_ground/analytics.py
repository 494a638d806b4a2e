"""Fleet analytics of the ground node: run the onboard core in batch over an archive of missions.

``scan_archive(dir)`` groups the bags of a directory tree by actuator (from
each bag's ``hd_mission`` metadata), reads them (contract topics only) and
runs :func:`hd_onboard.batch.run_mission` on each: per mission it keeps the
residual table, the window statistics and the flag summary. These are what
the ground aggregates across missions (thresholds, recalibration, trends).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np


def find_bags(root: str | os.PathLike) -> list[Path]:
    root = Path(root)
    if not root.exists():
        raise ValueError(f"{root}: mission archive directory does not exist")
    if not root.is_dir():
        return []
    from hd_bag.files import find_bags as find

    return find([root], files_only=True, empty_error=False)


def load_archive(root: str | os.PathLike, log=None) -> dict[str, list]:
    """actuator_id -> list of Missions sorted by mission_index (unreadable bags are logged and skipped)."""
    from hd_bag import read_mission

    out: dict[str, list] = {}
    for p in find_bags(root):
        try:
            m = read_mission(p)
        except (ValueError, OSError) as e:
            if log:
                log(f"skipping {p}: {e}")
            continue
        out.setdefault(m.meta.actuator_id, []).append(m)
    for v in out.values():
        v.sort(key=lambda m: m.meta.mission_index)
    return out


def mission_summary(res: dict) -> dict:
    """Per-mission aggregate of a batch onboard result (residual statistics per channel, flags)."""
    tab = res["table"]
    out = {"max_level": int(res["max_level"]), "onset_s": res["onset_s"], "n": int(len(tab))}
    for c, col in (("Q_red", 3), ("twist", 5)):
        r = tab[:, col]
        r = r[np.isfinite(r)]
        out[f"{c}.mean"] = float(r.mean()) if len(r) else float("nan")
        out[f"{c}.rms"] = float(np.sqrt(np.mean(r**2))) if len(r) else float("nan")
    return out
