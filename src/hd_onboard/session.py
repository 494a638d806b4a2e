"""One actuator's onboard monitoring across missions (pure: no ROS; the onboard node feeds it).

:class:`OnboardSession` decides which :class:`hd_onboard.core.OnboardCore` runs and with what: the
twin (``model_dir`` of the twin state, else the node's), its parameters (gear ratio from the
mission metadata, the node's setting or the twin), this actuator's residual lines and monitor
references from the twin state. A new mission (``/hd/mission``) starts a new core; a new twin
state is applied to the running core (a new twin model only before the core's first sample).
Samples, commands and temperatures are pushed through it, so the node only decodes and publishes.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from hd_onboard.config import OnboardConfig
from hd_onboard.core import OnboardCore
from hd_onboard.expected import make_expected
from hd_onboard.features import window_feature_fn
from hd_twin import physics as ph


class OnboardSession:
    def __init__(self, cfg: OnboardConfig, model_dir: str = "", gear_ratio: float = 0.0, hardware_id: str = "",
                 log: Callable[[str], None] = print):
        self.cfg = cfg
        self.model_dir = model_dir  # the node's twin (ONNX dir); "" -> physics-only stand-in
        self.gear_ratio = float(gear_ratio or 0.0)  # the node's N; 0 -> mission metadata or twin
        self.log = log  # warnings (twin load fallbacks)
        self.twin_params = ph.TwinParams.from_yaml()
        self.twin_state: dict = {}
        self.thresholds_all: dict[str, dict[str, Any]] = {}  # actuator -> channel -> ChannelThreshold
        self.references_all: dict[str, dict[str, Any]] = {}  # actuator -> {"stiffness"/"friction": reference}
        self.hardware_id = hardware_id
        self.meta: dict = {}
        self.core: OnboardCore | None = None

    def new_core(self) -> str:
        """A fresh core for the current mission and twin state; returns why the twin fell back ("" if not)."""
        N = float(self.meta.get("gear_ratio") or self.gear_ratio or self.twin_params.N)
        params = self.twin_params.with_meta(gear_ratio=N)
        model_dir = self.twin_state.get("model_dir") or self.model_dir
        # rate unknown until the core has measured it (it then configures the twin or falls back, noted)
        exp = make_expected(model_dir, params, fs_hz=self.cfg.nominal_fs or None, log=self.log)
        self.core = OnboardCore(exp, params, None, self.thresholds_all.get(self.hardware_id), self.cfg,
                                feature_fn=window_feature_fn(self.meta, N))
        self.apply_references()
        self.core.defer_windows = True
        return getattr(exp, "fallback_reason", "") or ""

    def start_mission(self, meta: dict) -> str:
        """A validated ``hd_mission`` record: this actuator, a new core (returns :meth:`new_core`'s reason)."""
        self.meta = meta
        self.hardware_id = str(meta.get("actuator_id") or self.hardware_id or "unknown")
        return self.new_core()

    def apply_state(self, state: dict, params, thresholds: dict, references: dict) -> str | None:
        """A twin state read by :func:`hd_twin.state.read_state`. A new model replaces a core that has not
        seen a sample yet (returns :meth:`new_core`'s reason); otherwise the running core takes the new
        parameters, this actuator's lines and, when they changed, its references (returns None)."""
        model_changed = (state.get("model_dir") or "") != (self.twin_state.get("model_dir") or "")
        old_refs = self.references_all.get(self.hardware_id)
        self.twin_state, self.twin_params, self.thresholds_all, self.references_all = state, params, thresholds, references
        if model_changed and self.core is not None and self.core.last_ns is None:
            return self.new_core()
        if self.core is not None:
            self.core.set_params(params)
            if self.hardware_id in thresholds:
                self.core.set_thresholds(thresholds[self.hardware_id])
            if references.get(self.hardware_id) != old_refs:  # a new reference restarts that monitor's moments
                self.apply_references()
        return None

    def apply_references(self) -> None:
        """This actuator's ground references (if any) to the core, exactly as its thresholds."""
        refs = self.references_all.get(self.hardware_id) or {}
        if "stiffness" in refs:
            self.core.set_stiffness_reference(refs["stiffness"])
        if "friction" in refs:
            self.core.set_friction_reference(refs["friction"])

    def push_samples(self, stamps: np.ndarray, V: np.ndarray, short_max: int, max_block: int,
                     published_level: Callable[[], int], after: Callable[[], None],
                     probe: list[int] | None = None) -> None:
        """Decoded joint states to the core. At most ``short_max`` samples: one by one, ``after()`` as soon
        as the level differs from ``published_level()`` (the flag decision right after each sample;
        ``probe`` collects wall time - stamp per sample). More: blocks of ``max_block``, ``after()`` per block."""
        import time

        core = self.core
        n = len(stamps)
        if n <= short_max:
            for s_, v_ in zip(stamps.tolist(), V.tolist()):
                if core.push_one(s_, v_) != published_level():
                    after()
                if probe is not None:
                    probe.append(time.time_ns() - s_)
            return
        for a in range(0, n, max_block):
            r = core.push(stamps[a:a + max_block], V[a:a + max_block])
            if len(r.table):
                core.rows.extend(r.table)
            core.events.extend(r.events)
            core.windows.extend(r.windows)
            after()

    def push_commands(self, stamps: np.ndarray, V: np.ndarray) -> None:
        """Decoded ``/hd/command`` JointStates (column 0: position[0] = theta_ref): the core keeps the latest
        reference only; a command without a position is only counted (by the node)."""
        has = np.flatnonzero(~np.isnan(V[:, 0]))
        if len(has):
            i = int(has[-1])
            self.core.push_command(int(stamps[i]), float(V[i, 0]))

    def push_temperature(self, stamp_ns: int, frame: str, value: float) -> None:
        """A temperature sample: the gearbox frame when there is one, else the first frame seen, is used."""
        if frame == "gearbox" or self.meta.get("_temp_frame") in (None, frame):
            self.meta["_temp_frame"] = frame
            self.core.push_temperature(stamp_ns, value)
