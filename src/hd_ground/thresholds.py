"""Adaptive per-actuator thresholds from healthy-mission residual statistics (pure numpy).

For one residual channel of one actuator, given the residuals of missions
known (or assumed) healthy:

* ``mu`` = median, ``sigma`` = 1.4826 MAD (robust: a few transients do not
  inflate the scale), both in the channel's unit;
* the EWMA ``e`` of the normalised residual is run exactly as onboard
  (:func:`hd_onboard.detectors.ewma.ewma`, same time constant; the arithmetic is
  :func:`hd_onboard.calibration.robust_threshold`, shared with the onboard self-calibration), and its
  *persistent peak* is taken: the largest value that |e| held for the
  onboard persistence time (a sliding minimum over P samples, then the max);
* ``h_warn = max(min_h_warn, warn_margin * peak)``,
  ``h_error = max(min_h_error, error_margin * peak, 1.5 h_warn)``.

So on the calibration data itself no flag would rise (the lines sit a margin
above the healthy peak), and the margin is what the false-alarm rate on
*other* healthy missions measures (``tests/ros``, ``hdphm`` reports).
The onboard core uses the same function on a mission's warm-up when the
ground has not calibrated that actuator yet.
"""

from __future__ import annotations

from typing import Iterable, Sequence

import numpy as np

from hd_onboard.calibration import persistent_peak, robust_threshold
from hd_onboard.detectors.ewma import ChannelThreshold

__all__ = ["MIN_SAMPLES", "persistent_peak", "channel_threshold", "actuator_thresholds"]

MIN_SAMPLES = 200


def channel_threshold(segments: Iterable[np.ndarray], *, fs: float, ewma_tau_s: float = 0.1,
                      persistence_s: float = 0.05, warn_margin: float = 1.5, error_margin: float = 3.0,
                      min_h_warn: float = 3.0, min_h_error: float = 6.0,
                      source: str = "ground (healthy missions)") -> ChannelThreshold | None:
    """Thresholds of one channel from residual ``segments`` (each a 1-D array, NaN allowed).

    ``fs`` [Hz] sample rate of the residuals; returns None when fewer than
    ``MIN_SAMPLES`` finite residuals are available (the caller keeps its
    previous lines). The arithmetic is :func:`hd_onboard.calibration.robust_threshold`
    (the same function the onboard self-calibration runs), with no scale floor.
    """
    return robust_threshold(segments, fs=fs, ewma_tau_s=ewma_tau_s, persistence_s=persistence_s,
                            warn_margin=warn_margin, error_margin=error_margin, min_h_warn=min_h_warn,
                            min_h_error=min_h_error, source=source, min_samples=MIN_SAMPLES, where="thresholds")


def actuator_thresholds(results: Sequence[dict], *, channels: Sequence[str] = ("Q_red", "twist"),
                        fs: float | None = None, **kw) -> dict[str, ChannelThreshold]:
    """Per-channel thresholds of one actuator from batch onboard results (:func:`hd_onboard.batch.run_mission`).

    Each result's residual table gives one segment per channel (columns
    ``r_Q_red`` and ``r_twist``); ``fs`` defaults to the median stamp rate.
    """
    from hd_onboard.residuals import RESIDUAL_COLUMNS

    col = {"Q_red": RESIDUAL_COLUMNS.index("r_Q_red"), "twist": RESIDUAL_COLUMNS.index("r_twist")}
    out: dict[str, ChannelThreshold] = {}
    if fs is None:
        rates = []
        for r in results:
            st = r["table"][:, 0]
            if len(st) > 2:
                rates.append(1.0 / float(np.median(np.diff(st))))
        fs = float(np.median(rates)) if rates else 1000.0
    for c in channels:
        th = channel_threshold([r["table"][:, col[c]] for r in results], fs=fs, **kw)
        if th is not None:
            out[c] = th
    return out
