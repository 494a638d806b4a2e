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
torque balance is evaluated on the model-rate samples. Its derivative d(omega_m)/dt is a Savitzky-Golay
FIR whose weights are designed once per rate (:mod:`hd_twin.streamfir`). Two modes (``mode``):

* ``"causal"`` (the earlier behaviour, output for output): no delay; the newest samples of each call get
  the end-of-window (one-sided) rows, the older ones of the call the centre row, so the result depends on
  how the stream is cut into calls; speeds re-timed causally (:class:`hd_twin.speedtiming.CausalRetimer`), theta_f
  smoothed causally (:class:`hd_twin.twistsmooth.CausalSmoother`).
* ``"fixed_lag"``: the output of sample k is given out when sample k + lag arrives (:attr:`lag_samples`:
  half the derivative window at the model rate, plus half the re-timing window at the bag rate when the
  model re-times speeds, plus half theta_f's smoothing window when it smooths the twist, ``config.json:
  twist_smoothing``, :mod:`hd_twin.twistsmooth`; e.g. 15 ms at 1 kHz, 12 ms at 250 Hz), with the centred derivative and edge rule
  of the batch twin, so the streamed outputs equal the batch ones (``hdphm twin eval``, training metrics)
  whatever the calls; :meth:`flush` gives out the last samples at the end of a segment (the batch
  right-edge fit). ``out["index"]`` may then be negative (a row of an earlier call); ``out["sample"]``
  counts input rows since the reset.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import data as D

OUTPUT_NAMES = ("Q_red", "x_FS", "y_FS")
#: Seconds of model-rate samples the pre-FIR physics path kept (``legacy_physics=True``, the reference).
PHYS_HISTORY_S = 2.0
#: Streaming modes of :class:`StreamingTwin` (see the module docstring).
MODES = ("causal", "fixed_lag")


class StreamingTwin:
    """ONNX Runtime twin with carried LSTM state; outputs in SI.

    ``mode``: ``"causal"`` (no delay, one-sided derivative at each call's newest samples) or
    ``"fixed_lag"`` (outputs equal to the batch twin, :attr:`lag_samples` late; :meth:`flush` at a segment's
    end). ``legacy_physics``: evaluate the causal physics path as the runtime before the FIR did (the
    identification's derivative over the history at every call); kept as the reference of the speed
    benchmark and of the equality test only.
    """

    def __init__(self, model_dir: str | Path, fs_in: float | None = None, gear_ratio: float | None = None,
                 mode: str = "causal", legacy_physics: bool = False):
        import onnxruntime as ort

        if mode not in MODES:
            raise ValueError(f"StreamingTwin: mode must be one of {MODES}, got {mode!r}")
        if legacy_physics and mode != "causal":
            raise ValueError("StreamingTwin: legacy_physics is the causal reference only")
        self.mode = mode
        self.legacy_physics = bool(legacy_physics)
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
        self._out_mean = np.array([m for m, _ in self._scales], float)
        self._out_scale = np.array([s for _, s in self._scales], float)
        from .physpath import PhysicsPath  # noqa: PLC0415

        pp = self.config.get("physics_path")
        self.physpath = PhysicsPath.from_dict(pp)
        self.gate = float((pp or {}).get("gate", 1.0)) if self.physpath.active else 1.0
        idf = self.physpath.identified if self.physpath.active else None
        self._needs_alpha = idf is not None and "alpha_m" in list(idf.names)
        from .speedtiming import SpeedTiming  # noqa: PLC0415

        self.speed_timing = SpeedTiming.from_config(self.config.get("speed_timing"),
                                                    f"{self.model_dir}/config.json speed_timing")
        from .twistsmooth import TwistSmoothing  # noqa: PLC0415

        self.twist_smoothing = TwistSmoothing.from_config(self.config.get("twist_smoothing"),
                                                          f"{self.model_dir}/config.json twist_smoothing")
        self._cutoff = getattr(idf, "cutoff_hz", None) if idf is not None else None
        # edge samples after a reset: the derivative filter's window is not yet filled (hd_twin.data.edge_half_window)
        self._edge_half = D.edge_half_window(1.0 / self.fs_model, self._cutoff)
        self._edge_n = self._edge_half if mode == "fixed_lag" else 2 * self._edge_half
        self.reset(fs_in)

    @property
    def inputs(self) -> tuple[str, ...]:
        return tuple(self.config["inputs"])

    def set_mode(self, mode: str) -> None:
        """Switch between ``"causal"`` and ``"fixed_lag"`` (then reset at the same rate)."""
        if mode not in MODES:
            raise ValueError(f"StreamingTwin: mode must be one of {MODES}, got {mode!r}")
        if mode != "causal" and self.legacy_physics:
            raise ValueError("StreamingTwin: legacy_physics is the causal reference only")
        self.mode = mode
        self._edge_n = self._edge_half if mode == "fixed_lag" else 2 * self._edge_half
        self.reset(self.fs_in)

    def reset(self, fs_in: float | None = None, gear_ratio: float | None = None) -> None:
        """Zero the LSTM and filter states; optionally set the input rate [Hz] and N. In ``fixed_lag`` mode the
        samples not given out yet are dropped (:meth:`flush` first to have them)."""
        if gear_ratio is not None:
            self.N = float(gear_ratio)
        self.fs_in = float(fs_in) if fs_in is not None else self.fs_model
        self.decimation = D.decimation_for(self.fs_in, self.fs_model, str(self.model_dir))
        self._sos = D.antialias_sos(self.fs_in, self.decimation)
        dt = self.decimation / self.fs_in
        # re-timing of the logged speeds at the input rate (None: speeds as logged)
        self._retimer = (self.speed_timing.streamer(self.fs_in, fixed_lag=self.mode == "fixed_lag")
                         if self.speed_timing.active else None)
        # theta_f smoothed for the twist as the model's Q_red terms were fitted (None: as logged)
        self._smoother = (self.twist_smoothing.streamer(self.fs_in, fixed_lag=self.mode == "fixed_lag")
                          if self.twist_smoothing.active else None)
        self._zi = None
        self._last = None
        self._prev = None
        self._n_in = 0  # input rows since the reset
        self._base = 0  # input row of the last step's X[0]
        self._n_stream = 0  # (re-timed) rows through the anti-alias filter since the reset
        self._n_out = 0  # outputs since the reset (edge flags)
        self._phys_last = None  # last model-rate row given to the physics path (non-finite values held)
        self._hist = np.zeros((0, len(D.RAW_INPUTS)))  # legacy_physics: model-rate rows of the history
        self._n_model = 0
        self._keep = None
        self._deriv = None  # the physics path's derivative filter (hd_twin.streamfir)
        self._pending = []  # fixed_lag: [(model sample, Xd row, network outputs row)] waiting for their derivative
        if self._needs_alpha and not self.legacy_physics:
            from .identify import sg_window  # noqa: PLC0415
            from .streamfir import CausalSGHistory, CentredFIR, sg_weights  # noqa: PLC0415

            cut = float(self._cutoff) if self._cutoff is not None else None
            w = sg_window(1.0 / dt, cut) if cut is not None else sg_window(1.0 / dt)
            wt = sg_weights(w, 3, dt)
            self._deriv = CentredFIR(wt) if self.mode == "fixed_lag" else CausalSGHistory(wt)
        self.h = np.zeros((self.layers, 1, self.hidden), np.float32)
        self.c = np.zeros((self.layers, 1, self.hidden), np.float32)

    @property
    def lag_samples(self) -> int:
        """Input rows between a sample's arrival and its output in steady state (0 in ``causal`` mode): half the
        physics path's derivative window at the model rate (times the decimation) plus half the speed
        re-timing window and half theta_f's smoothing window at the input rate. The first outputs after a reset come once a whole window is in."""
        if self.mode != "fixed_lag":
            return 0
        lag = self._deriv.lag * self.decimation if self._deriv is not None else 0
        return (lag + (self._retimer.lag if self._retimer is not None else 0)
                + (self._smoother.lag if self._smoother is not None else 0))

    @property
    def lag_s(self) -> float:
        """:attr:`lag_samples` in seconds at the input rate."""
        return self.lag_samples / self.fs_in

    def _filter(self, X: np.ndarray) -> np.ndarray:
        from scipy import signal as sps

        if self._sos is None:
            return X
        if self._zi is None:  # steady state at the first sample, per input (as in training)
            self._zi = sps.sosfilt_zi(self._sos)[:, :, None] * X[0][None, None, :]
        out, self._zi = sps.sosfilt(self._sos, X, axis=0, zi=self._zi)
        return out

    def _empty(self, idx=None) -> dict[str, np.ndarray]:
        out = {k: np.zeros(0) for k in OUTPUT_NAMES + ("Q_phys",)}
        out["index"] = np.zeros(0, int) if idx is None else idx
        out["sample"] = np.zeros(0, int) if idx is None else idx + self._base
        out["edge"] = np.zeros(0, bool)
        return out

    def step(self, X: np.ndarray) -> dict[str, np.ndarray]:
        """Feed ``X[n, 7]`` raw SI inputs (columns ``self.inputs``); returns SI outputs for the emitted samples.

        Keys: ``Q_red`` [N*m] (the twin: physics path + gate x remainder), ``Q_phys`` [N*m] (the
        identified physics path alone; zeros for a model without one), ``x_FS`` [m] (= u + r_b theta_m, unwrapped),
        ``y_FS`` [m], ``index`` (rows of X the outputs belong to; negative: a row of an earlier call, in
        ``fixed_lag`` mode), ``sample`` (input rows since the reset), ``edge`` (edge samples). Non-finite
        inputs are replaced by the training mean of their feature.
        """
        X = np.asarray(X, dtype=np.float64)
        if X.ndim == 1:
            X = X[None, :]
        if X.ndim != 2 or X.shape[1] != len(self.inputs):
            raise ValueError(f"StreamingTwin.step: X must be (n, {len(self.inputs)}) with columns {self.inputs}, got {X.shape}")
        self._base = self._n_in
        self._n_in += len(X)
        if len(X) == 0:
            return self._empty()
        # hold the last finite value per input (the filter must not see NaN, nor the fixed-lag re-timing)
        if self._sos is not None or ((self._retimer is not None or self._smoother is not None)
                                     and self.mode == "fixed_lag"):
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
        if self._smoother is not None:
            X = self._smoother.step(X)
        return self._model_rows(X, final=False)

    def flush(self) -> dict[str, np.ndarray]:
        """End of a segment (``fixed_lag``): the outputs not given out yet (the last :attr:`lag_samples` rows;
        the batch right-edge fit), with ``index`` relative to the last :meth:`step`'s X. ``causal``: nothing.
        Call :meth:`reset` before feeding the next segment."""
        if self.mode != "fixed_lag":
            return self._empty()
        X = self._retimer.flush() if self._retimer is not None else np.zeros((0, len(D.RAW_INPUTS)))
        if self._smoother is not None:
            parts = [self._smoother.step(X) if len(X) else np.zeros((0, len(D.RAW_INPUTS))), self._smoother.flush()]
            X = np.vstack([p.reshape(-1, len(D.RAW_INPUTS)) for p in parts])
        return self._model_rows(X, final=True)

    def _model_rows(self, X: np.ndarray, final: bool) -> dict[str, np.ndarray]:
        """Anti-alias filter, decimation, network and physics path on (re-timed) input rows ``X``."""
        s0 = self._n_stream
        self._n_stream += len(X)
        if len(X):
            Xf = self._filter(X)
            idx = np.arange((-s0) % self.decimation, len(X), self.decimation)
            Xd = Xf[idx]
        else:
            idx, Xd = np.zeros(0, int), np.zeros((0, len(D.RAW_INPUTS)))
        sample = s0 + idx  # input rows since the reset
        if len(Xd):
            F = D.features(Xd, self.N, self.decimation / self.fs_in, prev=self._prev, names=self.feature_names)
            self._prev = Xd[-1].copy()
            Z = self.norm.norm_features(F).astype(np.float32)[None]
            y, self.h, self.c = self.session.run(None, {"x": Z, "h0": self.h, "c0": self.c})
            y = y[0].astype(np.float64)
            si = self._out_mean + self._out_scale * y
        else:
            si = np.zeros((0, len(self._scales)))
        if self.mode == "fixed_lag" and self._needs_alpha:
            Xd, si, sample, q_phys = self._phys_fixed_lag(Xd, si, sample, final)
            if len(sample) == 0:
                return self._empty()
        elif len(Xd) == 0:
            return self._empty(idx)
        elif not self.physpath.active:
            q_phys = np.zeros(len(Xd))
        elif self.legacy_physics:
            q_phys = self._phys_legacy(Xd)
        else:
            q_phys = self._phys_causal(Xd)
        rem = si[:, 0]
        q = q_phys + self.gate * rem if self.physpath.active else rem
        j = sample // self.decimation  # model samples since the reset
        edge = j < self._edge_n
        if self.mode == "fixed_lag" and final:  # the segment's last half window (hd_twin.data.edge_samples)
            n_model = -(-self._n_stream // self.decimation)
            edge = edge | (j >= n_model - self._edge_half)
        self._n_out += len(j)
        return {"Q_red": q, "Q_phys": q_phys, "x_FS": si[:, 1] + self.params["r_b"] * Xd[:, 0], "y_FS": si[:, 2],
                "index": sample - self._base, "sample": sample, "edge": edge}

    @property
    def edge_s(self) -> float:
        """Seconds after a reset whose outputs are edge samples (``step``'s ``edge``): the derivative filter's
        window of the physics path (w model-rate samples, :func:`hd_twin.data.edge_half_window`) is not yet
        filled, so its one-sided fit extrapolates over fewer samples; a mission that starts with a step in
        acceleration gives errors there that no model can avoid. ``causal``: 2 half windows (the window fill);
        ``fixed_lag``: the first half window, as the batch counterpart, which marks the first and last half
        window of each segment (:func:`hd_twin.data.edge_samples`; the last ones come from :meth:`flush`)."""
        return self._edge_n / self.fs_model

    def _hold(self, Xd: np.ndarray) -> np.ndarray:
        """Model-rate rows for the physics path: temperature NaN -> T_ref, other non-finite values held (the
        network's inputs are mean-filled instead)."""
        Xd = Xd.copy()
        Xd[:, 5] = np.where(np.isfinite(Xd[:, 5]), Xd[:, 5], float(self.params["T_ref"]))
        fin = np.isfinite(Xd)
        for j in np.flatnonzero(~fin.all(axis=0)):
            last = self._phys_last[j] if self._phys_last is not None else 0.0
            pos = np.maximum.accumulate(np.where(fin[:, j], np.arange(len(Xd)), -1))
            Xd[:, j] = np.where(pos >= 0, Xd[np.maximum(pos, 0), j], last)
        if len(Xd):
            self._phys_last = Xd[-1].copy()
        return Xd

    def _q_phys(self, Xh: np.ndarray, alpha: np.ndarray | None) -> np.ndarray:
        """The identified balance on held model-rate rows with their derivative ``alpha`` (None: not needed);
        the balance's columns are pointwise in (omega_m, tau_m, alpha_m), so only those signals are passed."""
        sig = {"t": np.zeros(len(Xh)), "theta_m": Xh[:, 0], "omega_m": Xh[:, 1], "tau_m": Xh[:, 2],
               "theta_f": Xh[:, 3], "omega_f": Xh[:, 4], "temperature": Xh[:, 5]}
        if alpha is not None:
            sig["alpha_m"] = alpha
        return self.physpath.predict_signals(sig)

    def _phys_causal(self, Xd: np.ndarray) -> np.ndarray:
        """Causal physics path: the FIR derivative (:class:`hd_twin.streamfir.CausalSGHistory`) on the new rows."""
        Xh = self._hold(Xd)
        alpha = self._deriv.step(Xh[:, 1]) if self._deriv is not None else None
        return self._q_phys(Xh, alpha)

    def _phys_fixed_lag(self, Xd, si, sample, final):
        """Fixed-lag physics path: rows wait until their centred derivative is known (batch rule)."""
        Xh = self._hold(Xd)
        if len(Xh):
            self._pending.append((sample, Xh, si))
        alpha = self._deriv.push(Xh[:, 1]) if len(Xh) else np.zeros(0)
        if final:
            alpha = np.concatenate([alpha, self._deriv.flush()])
        k = len(alpha)
        if k == 0:
            return np.zeros((0, Xd.shape[1])), np.zeros((0, si.shape[1])), np.zeros(0, int), np.zeros(0)
        S = np.concatenate([p[0] for p in self._pending])
        XX = np.vstack([p[1] for p in self._pending])
        SI = np.vstack([p[2] for p in self._pending])
        self._pending = [(S[k:], XX[k:], SI[k:])] if k < len(S) else []
        return XX[:k], SI[:k], S[:k], self._q_phys(XX[:k], alpha)

    # ---- the pre-FIR physics path (reference for the speed benchmark and the equality test) ----
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

    def _phys_legacy(self, Xd: np.ndarray) -> np.ndarray:
        """The identified physics path on the new model-rate rows, re-evaluated on the history since the reset."""
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
        """Whole-mission inference, one reset per gap-free segment (as the node does after a gap); in
        ``fixed_lag`` mode each segment is flushed at its end."""
        D.check_twist_reference(mission, float(mission.meta.gear_ratio), mission.report.path or "mission")
        X = D.mission_inputs(mission)
        res = {k: [] for k in OUTPUT_NAMES + ("Q_phys", "index", "edge")}
        for a, b in D.segment_bounds(mission.segment):
            self.reset(mission.fs, mission.meta.gear_ratio)
            for o in (self.step(X[a:b]), self.flush()):
                o["index"] = o["sample"] + a
                for k in res:
                    res[k].append(o[k])
        return {k: np.concatenate(v) if v else np.zeros(0) for k, v in res.items()}

