"""Input guard: conditioning of the joint-state stream of one mission and the input problems it found.

Signal conditioning (:meth:`InputGuard.order`, :meth:`InputGuard.condition`):

* stamps at or before the last accepted stamp (duplicates, late arrivals)
  are dropped and counted: a real-time monitor cannot wait to re-sort;
* the nominal rate is the median stamp step of the first stamps (fixed once
  known; or ``nominal_fs``);
* a stamp step longer than ``max_gap_samples`` nominal periods is a dropout:
  the twin's state is reset (new segment, :mod:`hd_onboard.residuals`) and the
  first ``settle_s`` seconds after it are not evaluated;
* NaN samples are held for the twin input and excluded from evaluation; a
  NaN run longer than ``max_gap_samples`` is treated like a dropout.

Input problems (:attr:`InputGuard.notes`, key -> (level, message), see
:meth:`InputGuard.status`): encoders without a common zero (first samples),
unit / sign errors over the warm-up (``hd_bag.reader``'s cross-checks), a
mission shorter than the warm-up; the residuals record the twin fallbacks here too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hd_bag.reader import WRAP_TOL, whole_turns

from hd_onboard.detectors.levels import OK, WARN, run_lengths


@dataclass
class InputHealth:
    """What conditioning did, for /diagnostics."""

    n_samples: int = 0
    n_dropped_order: int = 0  # duplicates / out-of-order stamps dropped
    n_nan: int = 0
    n_gaps: int = 0
    n_missing: int = 0  # samples missing in gaps
    n_resets: int = 0


class Conditioned:
    """A conditioned block: ``t`` [s since mission start], ``valid`` rows (finite twin inputs), ``reset_at``
    rows starting a new segment (after a dropout or a long NaN run), ``Vh`` the samples with NaN held."""

    __slots__ = ("t", "valid", "reset_at", "Vh")

    def __init__(self, t, valid, reset_at, Vh):
        self.t, self.valid, self.reset_at, self.Vh = t, valid, reset_at, Vh


class InputGuard:
    """Conditioning state and input problems of one mission (a new guard per mission)."""

    def __init__(self, cfg):
        self.cfg = cfg
        self.fs: float | None = cfg.nominal_fs or None  # Hz, joint-state rate (None: not known yet)
        self.t0_ns: int | None = None  # first accepted stamp
        self.last_ns: int | None = None  # last accepted stamp
        self._stamp_buf: list[int] = []
        self.health = InputHealth()
        #: input problems of this mission: key -> (level, message); see :meth:`status`
        self.notes: dict[str, tuple[int, str]] = {}
        self._notes_new: list[tuple[str, int, str]] = []
        self._twist_check: list[float] = []
        self.twist_checked = False
        self.nan_run = 0  # length of the NaN run at the end of the last block
        self.hold = np.full(6, np.nan)  # last sample, NaN held (twin input)
        #: per angle column (0 theta_m, 1 theta_f): last finite raw angle, its speed and stamp, the turns removed so
        #: far [rad] and the whole-turn steps seen (:meth:`unwrap`)
        self._wrap = {c: [np.nan, np.nan, 0, 0.0, 0] for c in (0, 1)}

    # ---- input problems ------------------------------------------------------------------------------
    def note(self, key: str, level: int, message: str) -> None:
        """Record an input problem of this mission (once per key; the highest level wins)."""
        old = self.notes.get(key)
        if old is None or level > old[0]:
            self.notes[key] = (int(level), message)
            self._notes_new.append((key, int(level), message))

    def take_notes(self) -> list[tuple[str, int, str]]:
        """Input problems recorded since the last call: ``(key, level, message)``, oldest first."""
        out, self._notes_new = self._notes_new, []
        return out

    def status(self) -> tuple[int, str]:
        """Worst input problem of this mission: ``(level, message)`` (OK, "ok" when none)."""
        if not self.notes:
            return OK, "ok"
        lev = max(v[0] for v in self.notes.values())
        return lev, "; ".join(m for _, m in sorted(self.notes.values(), key=lambda v: -v[0]))

    # ---- the block path --------------------------------------------------------------------------------
    def order(self, stamps_ns: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Count the samples; drop stamps not after everything accepted before (counted)."""
        self.health.n_samples += len(stamps_ns)
        if len(stamps_ns) == 0:
            return stamps_ns, V
        prev = np.maximum.accumulate(np.concatenate([[self.last_ns if self.last_ns is not None else np.iinfo(np.int64).min], stamps_ns[:-1]]))
        keep = stamps_ns > prev
        if not keep.all():
            self.health.n_dropped_order += int((~keep).sum())
            stamps_ns, V = stamps_ns[keep], V[keep]
        return stamps_ns, V

    def unwrap(self, stamps_ns: np.ndarray, V: np.ndarray) -> np.ndarray:
        """An angle arriving within one turn (a single-turn encoder's driver, modulo 2 pi; contract: unwrapped):
        each step between neighbouring samples that its own speed does not show and that is a whole number k != 0
        of turns (to ``hd_bag.reader.WRAP_TOL`` after the trapezoid of the two speeds) loses 2 pi k, across blocks,
        noted once per angle. The bag reader's rule (``hd_bag.reader._unwrap_check``) sample by sample: a real-time
        monitor cannot look at the whole mission first. Such a step needs a motion of about a turn in one sample
        that the speed does not show, so an unwrapped stream is never changed; a corrupt sample that happens to sit
        a whole turn off is undone by the step back. Without it every wrap is a twist step of 2 pi / N: a fault
        flag. ``V`` is returned (a copy when changed)."""
        out = V
        for c_th, c_om, name in ((0, 2, "theta_m"), (1, 3, "theta_f")):
            st = self._wrap[c_th]
            th, om = V[:, c_th], V[:, c_om]
            fin = np.flatnonzero(np.isfinite(th))
            if len(fin) == 0:
                continue
            x = np.concatenate([[st[0]], th[fin]])
            w = np.concatenate([[st[1]], om[fin]])
            ts = np.concatenate([[st[2]], stamps_ns[fin]]).astype(np.float64) * 1e-9
            dts = np.diff(ts)
            k = whole_turns(np.diff(x), 0.5 * (w[:-1] + w[1:]) * dts)
            if self.fs and not st[4]:
                # across a dropout the speeds' trapezoid is no measure of the motion: a stream not yet seen to wrap
                # is not unwrapped there (one that has is: it is a single-turn stream)
                k = np.where(dts * self.fs <= 1.5, k, 0.0)
            wrap = k != 0
            off = st[3] - 2.0 * np.pi * np.cumsum(k)
            st[0], st[1], st[2] = float(th[fin[-1]]), float(om[fin[-1]]), int(stamps_ns[fin[-1]])
            if wrap.any() or st[3] != 0.0:
                if out is V:
                    out = V.copy()
                out[fin, c_th] = th[fin] + off
                st[3] = float(off[-1])
            if wrap.any():
                st[4] += int(wrap.sum())
                self._wrap_note(name)
        return out

    def unwrap_one(self, stamp_ns: int, tm: float, wm: float, tf: float, wf: float) -> tuple[float, float]:
        """:meth:`unwrap` of one finite sample (the real-time short path), in scalars: (theta_m, theta_f)."""
        return self._unwrap1(0, "theta_m", stamp_ns, tm, wm), self._unwrap1(1, "theta_f", stamp_ns, tf, wf)

    def _unwrap1(self, c: int, name: str, stamp_ns: int, th: float, om: float) -> float:
        # hd_bag.reader.whole_turns in scalars: numpy's per-call cost on one sample would dominate the short path
        st = self._wrap[c]
        step = th - st[0]
        moved = 0.5 * (om + st[1]) * (stamp_ns - st[2]) * 1e-9
        d = step - moved
        if math.isfinite(d) and abs(d) > math.pi:
            k = round(d / (2.0 * math.pi))
            if k and abs(d - 2.0 * math.pi * k) < WRAP_TOL:
                st[3] -= 2.0 * math.pi * k
                st[4] += 1
                self._wrap_note(name)
        st[0], st[1], st[2] = th, om, stamp_ns
        return th + st[3]

    def _wrap_note(self, name: str) -> None:
        self.note(f"wrapped_{name}", OK, f"{name} arrives within one turn (modulo 2 pi; contract: unwrapped): unwrapped "
                  "in the stream with its own speed (each step of a whole turn it does not show)")

    def start(self, stamps_ns: np.ndarray) -> bool:
        """Mission start and nominal rate from the first stamps (fixed once known); True when the rate
        became known in this block."""
        if self.t0_ns is None:
            self.t0_ns = int(stamps_ns[0])
        if self.fs is None:
            self._stamp_buf.extend(stamps_ns[:64].tolist())
            if len(self._stamp_buf) >= 16:
                d = np.diff(np.asarray(self._stamp_buf[:64]))
                d = d[d > 0]
                if len(d):
                    self.fs = 1e9 / float(np.median(d))
                    return True
        return False

    def condition(self, stamps_ns: np.ndarray, V: np.ndarray) -> Conditioned:
        """Gaps and NaN -> resets and validity (Q_red may be absent: it is no twin input); NaN held."""
        cfg = self.cfg
        fs = self.fs or 1000.0
        t = (stamps_ns - self.t0_ns) * 1e-9  # s since mission start
        valid = np.isfinite(V[:, :5]).all(axis=1)
        last = self.last_ns if self.last_ns is not None else int(stamps_ns[0])
        step = np.diff(np.concatenate([[last], stamps_ns])) * 1e-9 * fs
        gap = step > cfg.max_gap_samples + 0.5
        if (step > 1.5).any():
            big = step > 1.5
            self.health.n_gaps += int(big.sum())
            self.health.n_missing += int(np.round(step[big] - 1).sum())
        # NaN runs longer than max_gap_samples: a reset at the first valid sample after
        nanrun = self.nan_run
        reset_at = gap.copy()
        if not valid.all():
            self.health.n_nan += int((~valid).sum())
            runs = run_lengths(~valid, nanrun)
            after = np.concatenate([[nanrun], runs[:-1]])
            reset_at |= valid & (after > cfg.max_gap_samples)
            self.nan_run = int(runs[-1])
        else:
            self.nan_run = 0
        Vh = V.copy()
        if not valid.all():
            prevrow = self.hold
            Vx = np.vstack([prevrow[None, :], Vh])
            ok = np.isfinite(Vx)
            idx = np.maximum.accumulate(np.where(ok, np.arange(len(Vx))[:, None], 0), axis=0)
            Vh = Vx[idx, np.arange(6)[None, :]][1:]
        self.hold = Vh[-1].copy()
        return Conditioned(t, valid, reset_at, Vh)

    # ---- checks ------------------------------------------------------------------------------------------
    def check_twist_reference(self, V: np.ndarray, N: float) -> str | None:
        """First 16 valid samples: |median(theta_f - theta_m / N)| beyond any transmission twist
        (``hd_bag.mission.MAX_TWIST_OFFSET``) means encoders without a common zero: the problem's message
        (the caller records it, see :meth:`hd_onboard.residuals.Residuals.twist_reference_problem`), else None."""
        from hd_bag.mission import MAX_TWIST_OFFSET

        tw = V[:, 1] - V[:, 0] / N
        self._twist_check += tw[np.isfinite(tw)][:16].tolist()
        if len(self._twist_check) < 16:
            return None
        self.twist_checked = True
        med = float(np.median(self._twist_check))
        if abs(med) <= MAX_TWIST_OFFSET:
            return None
        return (f"theta_f - theta_m / N = {med:.6g} rad (N = {N:g}), beyond any transmission twist "
                f"(> {MAX_TWIST_OFFSET:g} rad): encoders without a common zero; twist channel and stiffness monitor "
                "run relative to the warm-up's twist zero")

    def check_units(self, w: np.ndarray, N: float) -> None:
        """End of the warm-up: the bag reader's unit / sign cross-checks (``hd_bag.reader``) on the warm-up
        samples ``w`` (rows ``t, JS_COLS``)."""
        if len(w) < 20:
            return
        from types import SimpleNamespace

        from hd_bag import reader as rd
        from hd_bag.mission import ReadReport

        rep = ReadReport()
        try:
            rd._consistency(SimpleNamespace(problems=[]), rep, w[:, 0], w[:, 1:], N)
        except (TypeError, AttributeError):  # the reader's internals changed: the check is skipped, said once
            self.note("unit_check", WARN, "unit / sign cross-checks unavailable (hd_bag.reader changed)")
            return
        for m in rep.suspect:
            key = "torque_sign" if "Q_red" in m else "speed_scale"
            self.note(key, WARN, m + " (over the warm-up; residual lines self-calibrate on it: detection unreliable)")

    def end_mission(self, warmup_done: bool) -> None:
        """End of the mission: a mission that ended inside the warm-up is noted (nothing was evaluated)."""
        if self.t0_ns is not None and not warmup_done and self.last_ns is not None:
            dur = (self.last_ns - self.t0_ns) * 1e-9
            self.note("short", WARN, f"mission of {dur:.3g} s ended inside the {self.cfg.warmup_s:g} s warm-up "
                      "(twist zero, self-calibration, monitor references): nothing evaluated")
