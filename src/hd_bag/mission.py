"""In-memory form of one contract bag (one mission of one actuator).

Every package works on :class:`Mission`: the reader fills it from MCAP, the
simulator fills it before writing, the twin, features, filter and discovery
read it. Signals are numpy arrays in SI units (angles in rad, temperatures in
degrees Celsius), named as in ``../shared/CONTRACT.md`` and the paper's
nomenclature.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: Metadata keys the contract requires in the ``hd_mission`` record.
REQUIRED_META_KEYS = (
    "contract",
    "actuator_id",
    "mission_index",
    "operating_hours",
    "gear_ratio",
    "torque_constant",
    "source",
)
SOURCES = ("simulation", "test_bench", "flight")

#: Joint-state signals, in the contract's field order.
JOINT_SIGNALS = ("theta_m", "theta_f", "omega_m", "omega_f", "tau_m", "Q_red")

TOPIC_JOINT_STATES = "/hd/joint_states"
TOPIC_COMMAND = "/hd/command"
TOPIC_TEMPERATURE = "/hd/temperature"
CONTRACT_TOPICS = (TOPIC_JOINT_STATES, TOPIC_COMMAND, TOPIC_TEMPERATURE)
TEMPERATURE_FRAMES = ("motor_winding", "gearbox")
#: rad at the output: |median(theta_f - theta_m / N)| above this is not a twist of the
#: transmission (wind-up plus lost motion of a harmonic drive at peak torque stays below ~0.01 rad)
#: but motor and output encoders without a common zero (CONTRACT: theta_m = N theta_f + compliance).
MAX_TWIST_OFFSET = 0.05
#: Gaps longer than this many nominal sample periods are never interpolated.
MAX_INTERP_GAP_SAMPLES = 10


@dataclass
class MissionMeta:
    """The ``hd_mission`` metadata record, typed."""

    actuator_id: str
    mission_index: int
    operating_hours: float
    gear_ratio: float  # N, motor turns per output turn
    torque_constant: float  # k_t, N*m/A
    source: str = "simulation"
    contract: str = "1"
    extra: dict[str, str] = field(default_factory=dict)  # optional keys (seed, profile, ...)

    def to_record(self) -> dict[str, str]:
        rec = {
            "contract": str(self.contract),
            "actuator_id": str(self.actuator_id),
            "mission_index": str(int(self.mission_index)),
            "operating_hours": repr(float(self.operating_hours)),
            "gear_ratio": repr(float(self.gear_ratio)),
            "torque_constant": repr(float(self.torque_constant)),
            "source": str(self.source),
        }
        rec.update({k: str(v) for k, v in self.extra.items() if k not in rec})
        return rec


@dataclass
class ReadReport:
    """What the reader found and did; printed by ``hdphm validate`` and kept with the data."""

    path: str = ""
    n_messages: dict[str, int] = field(default_factory=dict)  # per topic, as found in the file
    n_duplicates: int = 0  # joint-state samples with a repeated stamp, dropped (first kept)
    n_reordered: int = 0  # joint-state samples that arrived out of stamp order, re-sorted
    gaps: list[tuple[int, int]] = field(default_factory=list)  # (index after the gap, missing samples)
    n_nan: dict[str, int] = field(default_factory=dict)  # NaN samples per signal (kept as NaN)
    nominal_dt: float = float("nan")  # s, median stamp step
    #: rad, median of theta_f - theta_m / N (output-side twist; physically below ~0.01 rad). Larger
    #: means the two encoders are not co-referenced: twist-based estimates are meaningless.
    twist_offset: float = float("nan")
    notes: list[str] = field(default_factory=list)  # human-readable account of every action
    #: readable, but the signals disagree with each other or with the contract (encoders without
    #: a common zero, speeds not the derivative of the angles, Q_red sign): results derived from
    #: this mission are doubtful; commands that use it repeat these lines in their output
    suspect: list[str] = field(default_factory=list)
    gear_ratio_encoders: float = float("nan")  # theta_m / theta_f slope seen by the encoders

    def summary(self) -> str:
        lines = [f"{self.path}:"]
        lines += [f"  {t}: {n} messages" for t, n in self.n_messages.items()]
        if self.n_duplicates:
            lines.append(f"  dropped {self.n_duplicates} duplicate joint-state stamps")
        if self.n_reordered:
            lines.append(f"  re-sorted {self.n_reordered} out-of-order joint-state samples")
        if self.gaps:
            tot = sum(n for _, n in self.gaps)
            lines.append(f"  {len(self.gaps)} dropout gaps, {tot} samples missing (not interpolated)")
        for k, n in self.n_nan.items():
            if n:
                lines.append(f"  {k}: {n} NaN samples")
        lines += [f"  note: {s}" for s in self.notes]
        return "\n".join(lines)


@dataclass
class Mission:
    """One mission: joint states, command and temperatures on their own time bases.

    Times are seconds (float64) since ``t0_ns``, the first joint-state stamp.
    Joint-state arrays all have the length of ``t`` (sorted, duplicates
    removed; NaN kept where the sensor gave NaN). ``segment`` numbers the
    stretches between dropout gaps longer than ``MAX_INTERP_GAP_SAMPLES``:
    differentiate, filter and run recurrent models per segment.
    """

    meta: MissionMeta
    t: np.ndarray  # s
    theta_m: np.ndarray  # rad, motor / wave-generator angle, unwrapped
    theta_f: np.ndarray  # rad, output / flap angle
    omega_m: np.ndarray  # rad/s
    omega_f: np.ndarray  # rad/s
    tau_m: np.ndarray  # N*m, k_t * i_q
    Q_red: np.ndarray  # N*m, reducer output torque (NaN where not measured)
    t_cmd: np.ndarray  # s
    theta_ref: np.ndarray  # rad, commanded output angle
    temperatures: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)  # frame -> (t s, degC)
    t0_ns: int = 0
    segment: np.ndarray | None = None
    report: ReadReport = field(default_factory=ReadReport)
    #: Ground truth from ``/sim/...`` topics, only when explicitly asked for
    #: (evaluation code only: no estimator may read it). topic -> name -> array.
    sim: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.segment is None:
            self.segment = np.zeros(len(self.t), dtype=np.int32)

    # ---- convenience views -------------------------------------------------
    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self.t) > 1 else 0.0

    @property
    def fs(self) -> float:
        """Nominal sample rate, Hz (from the median stamp step)."""
        d = np.diff(self.t)
        return float(1.0 / np.median(d)) if len(d) else float("nan")

    @property
    def i_q(self) -> np.ndarray:
        """Motor q-axis current, A (contract: i_q = tau_m / k_t)."""
        return self.tau_m / self.meta.torque_constant

    def signal(self, name: str) -> np.ndarray:
        """A joint-state signal by its contract name."""
        if name not in JOINT_SIGNALS:
            raise KeyError(f"unknown signal {name!r}; one of {JOINT_SIGNALS}")
        return getattr(self, name)

    def theta_ref_on_t(self) -> np.ndarray:
        """Command held (zero-order) onto the joint-state time base; NaN before the first command."""
        return hold_on(self.t_cmd, self.theta_ref, self.t)

    def temperature_on_t(self, frame: str = "gearbox") -> np.ndarray:
        """Temperature of ``frame`` held onto the joint-state time base.

        Falls back to the other frame when ``frame`` is absent; all-NaN when
        the bag has no temperature at all.
        """
        if frame not in self.temperatures:
            others = [f for f in self.temperatures if f != frame]
            if not others:
                return np.full(len(self.t), np.nan)
            frame = others[0]
        tt, vv = self.temperatures[frame]
        out = np.interp(self.t, tt, vv) if len(tt) > 1 else np.full(len(self.t), vv[0] if len(vv) else np.nan)
        return out


def hold_on(t_src: np.ndarray, v_src: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Zero-order hold of (t_src, v_src) sampled at t_dst (NaN before the first source sample)."""
    if len(t_src) == 0:
        return np.full(len(t_dst), np.nan)
    idx = np.searchsorted(t_src, t_dst, side="right") - 1
    out = v_src[np.clip(idx, 0, None)].astype(float)
    out[idx < 0] = np.nan
    return out
