"""Robust alarm lines from healthy residuals: the one robust-threshold function (:func:`robust_threshold`),
used by the onboard warm-up self-calibration (:func:`calibrate_channel`) and by the ground's thresholds
from healthy missions (``hd_ground.thresholds.channel_threshold``)."""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np

from hd_onboard.detectors.ewma import ChannelThreshold, ewma


def persistent_peak(a: np.ndarray, p: int) -> float:
    """max over k of min(a[k:k+p]) (NaN ignored: they break the run)."""
    a = np.where(np.isfinite(a), a, -np.inf)
    if len(a) == 0:
        return 0.0
    p = max(1, min(int(p), len(a)))
    if p == 1:
        v = float(np.max(a))
    else:
        v = float(np.lib.stride_tricks.sliding_window_view(a, p).min(axis=1).max())
    return v if np.isfinite(v) else 0.0


def robust_threshold(segments: Iterable[np.ndarray], *, fs: float, ewma_tau_s: float, persistence_s: float,
                     warn_margin: float, error_margin: float, min_h_warn: float, min_h_error: float,
                     sigma_floor: float = 0.0, source: str, min_samples: int = 200,
                     where: str = "thresholds") -> ChannelThreshold | None:
    """Lines of one channel from healthy residual ``segments`` (each 1-D, NaN allowed): the one
    robust-threshold function, used by the onboard self-calibration (one warm-up segment, with a
    scale floor; :func:`calibrate_channel`) and the ground (healthy missions;
    ``hd_ground.thresholds.channel_threshold``).

    ``mu`` = median, ``sigma = max(1.4826 MAD, sigma_floor)`` (channel unit) over all finite
    samples, then per segment the persistent peak (:func:`persistent_peak` over
    ``persistence_s``) of |EWMA| of ``(r - mu)/sigma`` after one time constant ``ewma_tau_s``
    (the EWMA as onboard, :func:`ewma`), the largest over segments; ``h_warn = max(min_h_warn,
    warn_margin peak)``, ``h_error = max(min_h_error, error_margin peak, 1.5 h_warn)``.
    ``fs`` [Hz] residual sample rate. None with fewer than ``min_samples`` finite values;
    ValueError naming ``where`` for a non-positive ``fs``.
    """
    segs = [np.asarray(s, dtype=float) for s in segments]
    allr = np.concatenate(segs) if segs else np.empty(0)
    fin = allr[np.isfinite(allr)]
    if len(fin) < min_samples:
        return None
    if not (np.isfinite(fs) and fs > 0):
        raise ValueError(f"{where}: sample rate {fs!r} Hz is not positive")
    mu = float(np.median(fin))
    sigma = float(1.4826 * np.median(np.abs(fin - mu)))
    if not sigma > 0:
        sigma = float(np.std(fin)) or 1e-12
    if math.isfinite(sigma_floor) and sigma_floor > sigma:
        sigma = float(sigma_floor)
        source += ", sigma floor"
    lam = min(1.0, 1.0 / (ewma_tau_s * fs))
    p = max(1, int(round(persistence_s * fs)))
    peak = 0.0
    for s in segs:
        if np.isfinite(s).sum() < 2:
            continue
        e = ewma((s - mu) / sigma, lam, 0.0)
        e = np.where(np.isfinite(s), np.abs(e), np.nan)
        # skip the EWMA start-up (one time constant): it starts from 0, not from the data
        e[: int(ewma_tau_s * fs)] = np.nan
        peak = max(peak, persistent_peak(e, p))
    h_warn = max(min_h_warn, warn_margin * peak)
    h_error = max(min_h_error, error_margin * peak, 1.5 * h_warn)
    return ChannelThreshold(mu, sigma, float(h_warn), float(h_error), source).validate(where)


def calibrate_channel(r: np.ndarray, *, fs: float, ewma_tau_s: float, persistence_s: float, warn_margin: float,
                      error_margin: float, min_h_warn: float, min_h_error: float, sigma_floor: float = 0.0,
                      source: str = "self-calibrated (mission warm-up)", min_samples: int = 200) -> ChannelThreshold | None:
    """Lines of one channel from one healthy residual segment ``r`` (NaN allowed), with a scale floor:
    :func:`robust_threshold` on ``[r]``. The floor is what a short warm-up cannot show: the twin's
    error on manoeuvres the warm-up did not contain (the onboard core sets it from the load range
    seen, see ``OnboardConfig.sigma_floor_rel``). None with fewer than ``min_samples`` finite values.
    """
    return robust_threshold([r], fs=fs, ewma_tau_s=ewma_tau_s, persistence_s=persistence_s,
                            warn_margin=warn_margin, error_margin=error_margin, min_h_warn=min_h_warn,
                            min_h_error=min_h_error, sigma_floor=sigma_floor, source=source,
                            min_samples=min_samples, where="self-calibration")
