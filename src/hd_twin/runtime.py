"""Streaming inference of a trained twin with ONNX Runtime (used by the onboard node).

>>> twin = StreamingTwin("runs/twin_small")
>>> twin.reset()
>>> out = twin.step(X)          # X [n, 7] raw SI inputs, columns hd_twin.data.RAW_INPUTS
>>> out["Q_red"]                # [m] N*m, predicted reducer output torque

``step`` accepts samples at the *bag* rate ``fs_in`` (set at construction or
by :meth:`reset`); when the model runs at a lower rate (``fs_model`` in
config.json) the same causal anti-alias filter as in training is applied and
every ``decimation``-th sample produces an output: ``out["index"]`` gives the
row of X each output belongs to. LSTM state (h, c), filter state and
decimation phase carry across calls; :meth:`reset` clears them (new mission
or after a dropout gap).

Models with a physics path (``config.json:physics_path``, :mod:`hd_twin.physpath`) output
``Q_red = Q_phys + gate * remainder``: the network (ONNX) gives the remainder, and the identified
torque balance is evaluated on the model-rate samples received since the last reset (the last two
derivative-filter windows of them, at most ``PHYS_HISTORY_S`` seconds). Its derivative filter is centred (Savitzky-Golay); at the newest
samples of each call it uses the end-of-window polynomial fit, i.e. only past samples, so a streamed
Q_phys equals the batch one except within half a filter window of each call's last sample (a
whole segment in one call equals batch exactly).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import data as D

OUTPUT_NAMES = ("Q_red", "x_FS", "y_FS")
#: Seconds of model-rate samples the streaming physics path keeps (its filter needs far fewer).
PHYS_HISTORY_S = 2.0


class StreamingTwin:
    """ONNX Runtime twin with carried LSTM state; outputs in SI."""

    def __init__(self, model_dir: str | Path, fs_in: float | None = None, gear_ratio: float | None = None):
        import onnxruntime as ort

        self.model_dir = Path(model_dir)
        from .modeldir import read_config

        self.config = read_config(self.model_dir)
        onnx_path = self.model_dir / "twin.onnx"
        if not onnx_path.is_file():
            raise ValueError(f"{onnx_path}: missing; run `hdphm twin export {self.model_dir}`")
        so = ort.SessionOptions()
        so.intra_op_num_threads = 1
        so.inter_op_num_threads = 1
        self.session = ort.InferenceSession(str(onnx_path), so, providers=["CPUExecutionProvider"])
        self.norm = D.Normalizer.from_dict(self.config["normalization"])
        self.feature_names = tuple(self.config.get("features", D.FEATURES_V1))
        D.feature_columns(self.feature_names)  # ValueError on a feature this version cannot compute
        self.layers = int(self.config["arch"]["layers"])
        self.hidden = int(self.config["arch"]["hidden"])
        self.params = self.config["params"]
        self.N = float(gear_ratio if gear_ratio is not None else self.params["N"])
        self.fs_model = float(self.config["preprocessing"]["fs_model"])
        sc = self.config["output_scales"]
        self._scales = [tuple(sc[k]) for k in self.config["outputs"]]
        from .physpath import PhysicsPath  # noqa: PLC0415

        pp = self.config.get("physics_path")
        self.physpath = PhysicsPath.from_dict(pp)
        self.gate = float((pp or {}).get("gate", 1.0)) if self.physpath.active else 1.0
        from .speedtiming import SpeedTiming  # noqa: PLC0415

        self.speed_timing = SpeedTiming.from_config(self.config.get("speed_timing"),
                                                    f"{self.model_dir}/config.json speed_timing")
        cut = getattr(self.physpath.identified, "cutoff_hz", None) if self.physpath.active else None
        # edge samples after a reset: the derivative filter's window is not yet filled (hd_twin.data.edge_half_window)
        self._edge_n = 2 * D.edge_half_window(1.0 / self.fs_model, cut)
        self.reset(fs_in)

    @property
    def inputs(self) -> tuple[str, ...]:
        return tuple(self.config["inputs"])

    def reset(self, fs_in: float | None = None, gear_ratio: float | None = None) -> None:
        """Zero the LSTM and filter states; optionally set the input rate [Hz] and N."""
        if gear_ratio is not None:
            self.N = float(gear_ratio)
        self.fs_in = float(fs_in) if fs_in is not None else self.fs_model
        self.decimation = D.decimation_for(self.fs_in, self.fs_model, str(self.model_dir))
        self._sos = D.antialias_sos(self.fs_in, self.decimation)
        # causal re-timing of the logged speeds at the input rate (None: speeds as logged)
        self._retimer = self.speed_timing.streamer(self.fs_in) if self.speed_timing.active else None
        self._zi = None
        self._last = None
        self._prev = None
        self._phase = 0
        self._hist = np.zeros((0, len(D.RAW_INPUTS)))  # model-rate rows for the physics path
        self._n_model = 0  # model-rate samples since the reset
        self._n_out = 0  # outputs since the reset (edge flags)
        self._keep = None  # physics-path history length (set at the first step)
        self.h = np.zeros((self.layers, 1, self.hidden), np.float32)
        self.c = np.zeros((self.layers, 1, self.hidden), np.float32)

    def _filter(self, X: np.ndarray) -> np.ndarray:
        from scipy import signal as sps

        if self._sos is None:
            return X
        if self._zi is None:  # steady state at the first sample, per input (as in training)
            self._zi = sps.sosfilt_zi(self._sos)[:, :, None] * X[0][None, None, :]
        out, self._zi = sps.sosfilt(self._sos, X, axis=0, zi=self._zi)
        return out

    def step(self, X: np.ndarray) -> dict[str, np.ndarray]:
        """Feed ``X[n, 7]`` raw SI inputs (columns ``self.inputs``); returns SI outputs for the emitted samples.

        Keys: ``Q_red`` [N*m] (the twin: physics path + gate x remainder), ``Q_phys`` [N*m] (the
        identified physics path alone; zeros for a model without one), ``x_FS`` [m] (= u + r_b theta_m, unwrapped),
        ``y_FS`` [m], ``index`` (rows of X the outputs belong to). Non-finite
        inputs are replaced by the training mean of their feature.
        """
        X = np.asarray(X, dtype=np.float64)
        if X.ndim == 1:
            X = X[None, :]
        if X.ndim != 2 or X.shape[1] != len(self.inputs):
            raise ValueError(f"StreamingTwin.step: X must be (n, {len(self.inputs)}) with columns {self.inputs}, got {X.shape}")
        if len(X) == 0:
            return {k: np.zeros(0) for k in OUTPUT_NAMES + ("Q_phys",)} | {"index": np.zeros(0, int),
                                                                          "edge": np.zeros(0, bool)}
        if self._sos is not None:  # the filter must not see NaN: hold the last finite value per input
            X = X.copy()
            for j in range(X.shape[1]):
                bad = ~np.isfinite(X[:, j])
                if bad.any():
                    last = self._last[j] if self._last is not None else np.nan
                    ok_idx = np.where(~bad, np.arange(len(X)), -1)
                    ok_idx = np.maximum.accumulate(ok_idx)
                    X[:, j] = np.where(ok_idx >= 0, X[np.maximum(ok_idx, 0), j], last)
                    X[~np.isfinite(X[:, j]), j] = 0.0 if j != 5 else float(self.params["T_ref"])
            self._last = X[-1].copy()
        if self._retimer is not None:
            X = self._retimer.step(X)
        Xf = self._filter(X)
        idx = np.arange((-self._phase) % self.decimation, len(X), self.decimation)
        self._phase = (self._phase + len(X)) % self.decimation
        Xd = Xf[idx]
        if len(Xd) == 0:
            return {k: np.zeros(0) for k in OUTPUT_NAMES + ("Q_phys",)} | {"index": idx, "edge": np.zeros(0, bool)}
        F = D.features(Xd, self.N, self.decimation / self.fs_in, prev=self._prev, names=self.feature_names)
        self._prev = Xd[-1].copy()
        Z = self.norm.norm_features(F).astype(np.float32)[None]
        y, self.h, self.c = self.session.run(None, {"x": Z, "h0": self.h, "c0": self.c})
        y = y[0].astype(np.float64)
        si = [m + s * y[:, j] for j, (m, s) in enumerate(self._scales)]
        q_phys = self._phys(Xd) if self.physpath.active else np.zeros(len(Xd))
        if self.physpath.active:
            si[0] = q_phys + self.gate * si[0]
        edge = self._n_out + np.arange(len(Xd)) < self._edge_n
        self._n_out += len(Xd)
        return {"Q_red": si[0], "Q_phys": q_phys, "x_FS": si[1] + self.params["r_b"] * Xd[:, 0], "y_FS": si[2], "index": idx,
                "edge": edge}

    @property
    def edge_s(self) -> float:
        """Seconds after a reset whose outputs are edge samples (``step``'s ``edge``): the derivative filter's
        window of the physics path (w model-rate samples, :func:`hd_twin.data.edge_half_window`) is not yet
        filled, so its one-sided fit extrapolates over fewer samples; a mission that starts with a step in
        acceleration gives errors there that no model can avoid. The batch counterpart marks the first and
        last half-window of each segment (:func:`hd_twin.data.edge_samples`)."""
        return self._edge_n / self.fs_model

    def _phys_keep(self, dt: float) -> int:
        """Model-rate rows the physics path keeps: two windows of identify's derivative filter (all the
        newest samples' end-of-window fit needs), at most ``PHYS_HISTORY_S``."""
        cap = max(16, int(PHYS_HISTORY_S / dt))
        try:
            from .identify import sg_window  # noqa: PLC0415

            w = sg_window(1.0 / dt, float(getattr(self.physpath.identified, "cutoff_hz")))
        except (ImportError, AttributeError, TypeError, ValueError):
            return cap
        return int(min(cap, max(16, 2 * w + 2)))

    def _phys(self, Xd: np.ndarray) -> np.ndarray:
        """The identified physics path on the new model-rate rows, with the history since the reset."""
        Xd = Xd.copy()
        Xd[:, 5] = np.where(np.isfinite(Xd[:, 5]), Xd[:, 5], float(self.params["T_ref"]))
        for j in range(Xd.shape[1]):  # hold the last finite value (the network's inputs are mean-filled)
            bad = ~np.isfinite(Xd[:, j])
            if bad.any():
                last = self._hist[-1, j] if len(self._hist) else 0.0
                pos = np.maximum.accumulate(np.where(~bad, np.arange(len(Xd)), -1))
                Xd[:, j] = np.where(pos >= 0, Xd[np.maximum(pos, 0), j], last)
        H = np.vstack([self._hist, Xd])
        dt = self.decimation / self.fs_in
        q = self.physpath.predict_X(H, dt, t0=(self._n_model - len(self._hist)) * dt)[-len(Xd):]
        if self._keep is None:
            self._keep = self._phys_keep(dt)
        keep = self._keep
        self._hist = H[-keep:]
        self._n_model += len(Xd)
        return q

    def run_mission(self, mission) -> dict[str, np.ndarray]:
        """Whole-mission inference, one reset per gap-free segment (as the node does after a gap)."""
        D.check_twist_reference(mission, float(mission.meta.gear_ratio), mission.report.path or "mission")
        X = D.mission_inputs(mission)
        res = {k: [] for k in OUTPUT_NAMES + ("index", "edge")}
        for a, b in D.segment_bounds(mission.segment):
            self.reset(mission.fs, mission.meta.gear_ratio)
            o = self.step(X[a:b])
            o["index"] = o["index"] + a
            for k in res:
                res[k].append(o[k])
        return {k: np.concatenate(v) if v else np.zeros(0) for k, v in res.items()}
