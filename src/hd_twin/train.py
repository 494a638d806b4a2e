"""Training of the physics-informed LSTM twin (the model directory it writes: :mod:`hd_twin.modeldir`).

``train_twin(missions, out_dir, cfg)`` is the pure core used by ``hdphm
train``, ``hdphm tune`` and the ablation; it takes :class:`Mission` objects
(read from bags by :func:`load_missions`) and writes a model directory::

    config.json          inputs, features, outputs, declared effects, extra_terms,
                         physical parameters, model_version, preprocessing,
                         normalisation, architecture, loss settings, data hashes
    model.pt             torch state_dict (network, lambda_c, residual scaler)
    twin.onnx            streaming export (x, h0, c0) -> (y, h_n, c_n)
    metrics.json         validation/training NRMSE, R^2, max error of Q_red,
                         RMS of r1..r4, physics-only baseline, training time
    history.json         per-epoch losses (total/data/physics, train/val), lambda_c
    *.png                paper Figures 4-7 + lambda_c trajectory
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from . import data as D
from . import physics as ph
from .modeldir import (MODEL_FORMAT, _device_of, load_pinn, predict_outputs, predict_segments,  # noqa: F401 (re-exported)
                       q_from_outputs, read_config, segment_phys, write_model)
from .physpath import PhysicsPath, choose_gate

_CR = "\r" if sys.stderr.isatty() else ""  # overwrite progress lines on a terminal only

#: Physical parameters the PINN identifies by default (those the data constrain: the
#: series stiffness, input friction, inertias and flank friction); the rest stay at the prior.
CALIBRATE_DEFAULT = ("k_m", "k_FS", "k_b", "T_C", "b_visc", "J_WG", "J_CS", "mu_c")

PRESETS: dict[str, dict[str, Any]] = {
    # The paper's Table 1 (GPU-sized).
    "paper": dict(layers=3, hidden=512, dropout=0.41873, lr=4.51e-3, lambda_init=8e-2,
                  epochs=60, seq_len=256, stride=128, batch=32, fs_target=None, ramp_epochs=10,
                  calibrate=list(CALIBRATE_DEFAULT)),
    # CPU/CI-sized: trains in minutes on 2 cores.
    # Short windows and small batches: many optimiser steps per epoch (what an LSTM needs on CPU).
    "small": dict(layers=2, hidden=64, dropout=0.0, lr=5e-3, lambda_init=8e-2,
                  epochs=15, seq_len=128, stride=128, batch=16, fs_target=250.0, ramp_epochs=3,
                  calibrate=list(CALIBRATE_DEFAULT)),
    # For unit tests only.
    "tiny": dict(layers=1, hidden=8, dropout=0.0, lr=1e-2, lambda_init=8e-2,
                 epochs=2, seq_len=48, stride=24, batch=8, fs_target=None, ramp_epochs=1),
}


@dataclass
class TrainConfig:
    """Everything that defines a training run (stored in config.json)."""

    preset: str = "small"
    layers: int = 2
    hidden: int = 48
    dropout: float = 0.0
    lr: float = 6e-3
    epochs: int = 25
    seq_len: int = 200
    stride: int = 100
    batch: int = 32
    fs_target: float | None = 250.0  # Hz; None = keep the bag rate
    lambda_init: float = 8e-2
    lambda_mode: str = "uncertainty"
    adaptive_scaling: bool = True
    ramp_epochs: int = 5
    washout: int = 16
    grad_clip: float = 1.0
    skip: bool = True  # linear feature-to-output path beside the LSTM
    calibrate: list[str] = field(default_factory=list)  # physical parameters identified jointly (log-multipliers)
    calib_reg: float = 1e-2  # weight of the prior on the log-multipliers
    weight_decay: float = 0.0
    val_frac: float = 0.25
    seed: int = 0
    threads: int = 1
    declared_effects: list[str] = field(default_factory=lambda: list(ph.DEFAULT_EFFECTS))
    extra_terms: list[dict] = field(default_factory=list)
    params: dict[str, Any] | None = None  # None = default_params.yaml
    model_version: int = 1
    parent: str | None = None  # model this one was derived from (discovery)
    export_onnx: bool = True
    plots: bool = True
    device: str = "auto"  # "auto" (CUDA when available), "cpu", "cuda"
    amp: bool = True  # float16 autocast of the network on CUDA (cuDNN LSTM); no effect on CPU
    eval_batch_samples: int = 1 << 20  # padded samples per batched full-sequence prediction
    # "auto": the torque balance identified by hd_twin.identify when available, else none;
    # "identified": required; "none": the network predicts the whole Q_red (models before this structure)
    physics_path: str = "auto"
    gate_blocks: int = 2  # contiguous blocks per validation unit in which the remainder must help
    features: list[str] = field(default_factory=lambda: list(D.FEATURES))  # network inputs (names of hd_twin.data)
    # re-timing of the logged speeds (hd_twin.speedtiming config entry, written by discovery); {} = as logged
    speed_timing: dict = field(default_factory=dict)
    # smoothing of theta_f for the twist (hd_twin.twistsmooth config entry, written by discovery); {} = as logged
    twist_smoothing: dict = field(default_factory=dict)

    @classmethod
    def from_preset(cls, name: str, **overrides) -> "TrainConfig":
        if name not in PRESETS:
            raise ValueError(f"unknown preset {name!r}; one of {sorted(PRESETS)}")
        kw = dict(PRESETS[name])
        kw.update({k: v for k, v in overrides.items() if v is not None})
        return cls(preset=name, **kw)

    def validate(self) -> "TrainConfig":
        for k in ("layers", "hidden", "epochs", "seq_len", "stride", "batch"):
            v = getattr(self, k)
            if not isinstance(v, int) or v < 1:
                raise ValueError(f"training config: {k} must be a positive integer, got {v!r}")
        if not (0 < self.lr < 1):
            raise ValueError(f"training config: lr = {self.lr} outside (0, 1)")
        if self.washout >= self.seq_len - 2:
            raise ValueError(f"training config: washout {self.washout} leaves nothing of seq_len {self.seq_len}")
        ph.check_effects(self.declared_effects)
        if not self.features:
            raise ValueError("training config: features must name at least one feature")
        D.feature_columns(self.features)
        from .speedtiming import SpeedTiming  # noqa: PLC0415

        SpeedTiming.from_config(self.speed_timing, "training config: speed_timing")
        from .twistsmooth import TwistSmoothing  # noqa: PLC0415

        TwistSmoothing.from_config(self.twist_smoothing, "training config: twist_smoothing")
        if not isinstance(self.extra_terms, list) or not all(isinstance(t, dict) for t in self.extra_terms):
            raise ValueError("training config: extra_terms must be a list of term dicts")
        if self.physics_path not in ("auto", "identified", "none"):
            raise ValueError(f"training config: physics_path must be auto, identified or none, got {self.physics_path!r}")
        return self


# ---- data assembly ------------------------------------------------------------
def load_missions(paths: Sequence[str | Path], progress: bool = True) -> list:
    """Read every bag under ``paths`` with ``hd_bag.read_mission`` (never the /sim topics)."""
    from hd_bag import read_mission  # noqa: PLC0415 (bag reader of the project)

    bags = D.find_bags(paths)
    out = []
    for i, b in enumerate(bags):
        if progress:
            print(f"{_CR}reading bags {i + 1}/{len(bags)}: {b.name}   ", end="" if _CR else "\n", file=sys.stderr, flush=True)
        m = read_mission(b)
        if not m.report.path:
            m.report.path = str(b)
        out.append(m)
    if progress:
        print(file=sys.stderr)
    return out


def mission_hash(m) -> str:
    """sha256 of the bag file when it exists, else of the mission's arrays."""
    p = Path(m.report.path) if m.report.path else None
    if p is not None and p.is_file():
        return D.file_sha256(p)
    h = hashlib.sha256()
    for a in (m.t, m.theta_m, m.theta_f, m.omega_m, m.omega_f, m.tau_m, m.Q_red):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()


def mission_label(m) -> str:
    return m.report.path or f"{m.meta.actuator_id}/mission{m.meta.mission_index}"


def resolve_params(cfg: TrainConfig, missions: Sequence) -> ph.TwinParams:
    """Twin parameters: config (or the default YAML) with N and k_t from the bags' metadata."""
    base = ph.TwinParams.from_dict(cfg.params, "model config params") if cfg.params else ph.TwinParams.from_yaml()
    Ns = {float(m.meta.gear_ratio) for m in missions}
    if len(Ns) > 1:
        raise ValueError(f"training missions mix gear ratios {sorted(Ns)}; train one twin per actuator type")
    # k_t varies from unit to unit (tau_m is already k_t i_q in N*m); the twin keeps the median
    kt = float(np.median([float(m.meta.torque_constant) for m in missions]))
    return base.with_meta(Ns.pop(), kt)


def fs_model_for(missions: Sequence, fs_target: float | None) -> float:
    """Model sample rate [Hz]: the lowest bag rate (a higher rate reaches it by integer decimation,
    checked per bag in ``preprocess``), lowered by an integer factor toward ``fs_target``.

    (The median rate was used before: with bags at 100 Hz and 10 kHz it gave 5050 Hz, which no
    bag can be decimated to.)
    """
    fs = float(min(m.fs for m in missions))
    if fs_target is None or fs <= fs_target:
        return fs
    return fs / max(1, int(round(fs / fs_target)))


def stack_windows(segs: Sequence[D.Segment], norm: D.Normalizer, length: int, stride: int) -> dict[str, np.ndarray]:
    """Cut segments into windows [W, T] of every channel the loss needs (float32, x is [W, T, 11])."""
    idx = D.windows([s.n for s in segs], length, stride)
    if not idx:
        raise ValueError(f"no segment is long enough for windows of {length} samples")
    chans = ("Q_red", "theta_m_dd", "theta_f_dd", "phi", "phi_d", "temperature", "Q_phys")
    W = len(idx)
    out = {k: np.zeros((W, length), np.float32) for k in chans + ("omega_m", "tau_m", "theta_m", "theta_f", "omega_f")}
    out["mask"] = np.zeros((W, length), bool)
    out["x"] = np.zeros((W, length, len(norm.f_mean)), np.float32)
    out["dt"] = np.zeros((W, 1), np.float32)
    Z = [norm.norm_features(s.F) for s in segs]
    for w, (i, s0) in enumerate(idx):
        seg = segs[i]
        sl = slice(0, seg.n) if s0 < 0 else slice(s0, s0 + length)
        n = sl.stop - sl.start
        src = {
            "Q_red": np.nan_to_num(seg.Q_red[sl]), "theta_m_dd": seg.theta_m_dd[sl], "theta_f_dd": seg.theta_f_dd[sl],
            "phi": seg.phi[sl], "phi_d": seg.phi_d[sl], "temperature": seg.temperature[sl],
            "Q_phys": np.zeros(n) if seg.Q_phys is None else seg.Q_phys[sl],
            "omega_m": seg.X[sl, 1], "tau_m": seg.X[sl, 2],
            # wrapped to [-pi, pi): float32 keeps sin(k theta_m) exact for the extra terms
            "theta_m": np.angle(np.exp(1j * seg.X[sl, 0])), "theta_f": seg.X[sl, 3], "omega_f": seg.X[sl, 4],
        }
        for k, v in src.items():
            out[k][w, :n] = v
            if n < length:
                out[k][w, n:] = v[-1]
        out["x"][w, :n] = Z[i][sl]
        if n < length:
            out["x"][w, n:] = Z[i][sl][-1]
        out["mask"][w, :n] = seg.mask[sl]
        out["dt"][w, 0] = seg.dt
    return out


def _to_torch(batch: dict, sel=None, device=None) -> dict:
    import torch

    out = {k: torch.from_numpy(v if sel is None else v[sel]) for k, v in batch.items()}
    return out if device is None or str(device) == "cpu" else {k: v.to(device) for k, v in out.items()}


def save_model(result: TrainResult, cfg: TrainConfig, progress: bool = True) -> None:
    """Write the model directory: the data files (:func:`hd_twin.modeldir.write_model`), then
    ``twin.onnx`` (``cfg.export_onnx``) and the figures (``cfg.plots``)."""
    out = write_model(result)
    if cfg.export_onnx:
        from .export import export_onnx

        export_onnx(out)
    if cfg.plots:
        from .plots import plot_training

        tr, va = result.segments
        outs = getattr(result, "outputs", None)
        plot_training(out, result.pinn, result.norm, tr, va, result.history, outs=outs)
    if progress:
        print(f"model written to {out}", file=sys.stderr)


# ---- evaluation ------------------------------------------------------------------
def q_metrics(y_true: np.ndarray, y_pred: np.ndarray) -> dict[str, float]:
    """NRMSE (RMSE / range of the true signal, %), R^2, max abs error [N*m], RMSE [N*m]."""
    ok = np.isfinite(y_true) & np.isfinite(y_pred)
    yt, yp = y_true[ok], y_pred[ok]
    if len(yt) < 2:
        return {"n": int(len(yt)), "nrmse_pct": float("nan"), "r2": float("nan"), "max_err": float("nan"), "rmse": float("nan")}
    e = yp - yt
    rmse = float(np.sqrt(np.mean(e**2)))
    rng = float(np.ptp(yt))
    ss = float(np.sum((yt - yt.mean()) ** 2))
    return {
        "n": int(len(yt)),
        "rmse": rmse,
        "nrmse_pct": 100.0 * rmse / rng if rng > 0 else float("nan"),
        "r2": 1.0 - float(np.sum(e**2)) / ss if ss > 0 else float("nan"),
        "max_err": float(np.max(np.abs(e))),
        "range": rng,
    }


def residual_rms(pinn, segs: Sequence[D.Segment], norm: D.Normalizer, params: ph.TwinParams | None = None,
                 outs: Sequence[np.ndarray] | None = None) -> dict[str, float]:
    """RMS of r1..r4 (SI) of the trained twin on full segments (valid interior samples).

    ``outs``: the network outputs of :func:`predict_outputs` (computed when not given)."""
    import torch

    from .model import physics_residuals_torch

    pinn.eval()
    outs = predict_outputs(pinn, segs, norm) if outs is None else outs
    segment_phys(pinn, segs)
    sq = np.zeros(4)
    cnt = 0
    with torch.no_grad():
        for s, o in zip(segs, outs):
            if s.n < 3:
                continue
            b = stack_windows([s], norm, s.n, s.n)
            tb = _to_torch(b)
            pred = pinn.to_SI(torch.from_numpy(o.astype(np.float32))[None], tb["Q_phys"])
            p = params or pinn.calibrated_params()
            if abs(p.N - s.N) > 1e-9:
                p = p.with_meta(s.N, s.k_t)
            r = physics_residuals_torch(pred, tb, p, pinn.effects, pinn.extra_terms)
            m = tb["mask"][:, 1:-1].numpy()
            R = np.stack([ri.double().cpu().numpy() for ri in r])
            sq += (R[:, m] ** 2).sum(axis=1)
            cnt += int(m.sum())
    rms = np.sqrt(sq / max(cnt, 1))
    return {f"r{j + 1}_rms": float(rms[j]) for j in range(4)} | {"units": "r1, r4 N*m; r2, r3 N"}


def physics_baseline(segs: Sequence[D.Segment], params: ph.TwinParams, effects) -> np.ndarray:
    """Concatenated quasi-static Q_red of the prior (uncalibrated) three-body physics on the segments [N*m]."""
    return np.concatenate(
        [ph.quasi_static_Q_red(params.with_meta(s.N, s.k_t), effects, s.X[:, 2], s.X[:, 1], s.temperature,
                               s.theta_m_dd, s.theta_f_dd) for s in segs]
    )


def evaluate(pinn, segs: Sequence[D.Segment], norm: D.Normalizer, residuals: bool = True,
             outs: Sequence[np.ndarray] | None = None, batch_samples: int = 1 << 20) -> dict:
    """Q_red metrics of the twin, of its physics path alone and of the ungated network; r1..r4 RMS.

    ``physics_only`` is the identified physics path (the prior three-body physics, ``physics_prior``,
    when the model has none)."""
    outs = predict_outputs(pinn, segs, norm, batch_samples) if outs is None else outs
    yt = np.concatenate([np.where(s.mask, s.Q_red, np.nan) for s in segs])
    met = q_metrics(yt, np.concatenate(q_from_outputs(pinn, segs, outs)))
    # measured samples within half a derivative window of a segment edge (hd_twin.data.edge_samples): not scored
    met["edge_excluded"] = int(sum(int(s.edge.sum()) for s in segs if s.edge is not None))
    met["gate"] = float(pinn.gate)
    if residuals:
        met.update(residual_rms(pinn, segs, norm, outs=outs))
    prior = q_metrics(yt, physics_baseline(segs, pinn.params, pinn.declared_effects))
    if pinn.physpath.active:
        met["physics_only"] = q_metrics(yt, np.concatenate(segment_phys(pinn, segs)))
        met["physics_prior"] = prior
        met["ungated"] = q_metrics(yt, np.concatenate(q_from_outputs(pinn, segs, outs, gate=1.0)))
    else:
        met["physics_only"] = prior
    return met


def group_segments(segs: Sequence[D.Segment]) -> list[list[int]]:
    """Indices of ``segs`` per held-out group: per actuator when there are >= 2, else per mission."""
    acts = sorted({s.actuator_id for s in segs})
    key = (lambda s: s.actuator_id) if len(acts) >= 2 else (lambda s: (s.source, s.mission_index))
    groups: dict = {}
    for i, s in enumerate(segs):
        groups.setdefault(key(s), []).append(i)
    return list(groups.values())


def set_gate(pinn, segs: Sequence[D.Segment], outs: Sequence[np.ndarray], blocks: int = 2) -> dict:
    """Choose the remainder's gate on held-out segments (:func:`hd_twin.physpath.choose_gate`) and set it.

    Groups: each held-out unit (:func:`group_segments`) cut into ``blocks`` contiguous blocks, so the
    remainder must help in every block of every unit to be kept."""
    import torch

    if not pinn.physpath.active:
        pinn.gate.fill_(1.0)
        return {"gate": 1.0, "rule": "no physics path: the network predicts Q_red (gate 1)"}
    qp = segment_phys(pinn, segs)
    rem = [pinn.r_mean + pinn.r_std * o[:, 0] for o in outs]
    ys, qs, rs = [], [], []
    for g in group_segments(segs):
        y_u = np.concatenate([np.where(segs[i].mask, segs[i].Q_red, np.nan) for i in g])
        q_u = np.concatenate([qp[i] for i in g])
        r_u = np.concatenate([rem[i] for i in g])
        for part in np.array_split(np.arange(len(y_u)), max(1, int(blocks))):
            ys.append(y_u[part])
            qs.append(q_u[part])
            rs.append(r_u[part])
    gate, det = choose_gate(ys, qs, rs)
    det["blocks_per_unit"] = int(blocks)
    with torch.no_grad():
        pinn.gate.fill_(gate)
    return {"gate": gate} | det


# ---- training -------------------------------------------------------------------
@dataclass
class TrainResult:
    model_dir: Path
    metrics: dict
    history: dict
    config: dict


def _set_seed(seed: int, threads: int):
    import random

    import torch

    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    torch.set_num_threads(max(1, int(threads)))


def build_segments(missions: Sequence, fs_model: float, T_ref: float) -> list[list[D.Segment]]:
    return [D.preprocess(m, fs_model, T_ref=T_ref) for m in missions]


def train_twin(missions: Sequence, out_dir: str | Path | None, cfg: TrainConfig,
               split: tuple[Sequence[int], Sequence[int]] | None = None, progress: bool = True,
               epoch_callback: Callable[[int, dict], None] | None = None) -> TrainResult:
    """Train a PINN twin on ``missions`` and (if ``out_dir``) write the model directory.

    ``split`` = (train indices, validation indices) into ``missions``; default
    :func:`hd_twin.data.split_missions` at actuator level with ``cfg.val_frac``.
    ``epoch_callback(epoch, record)`` may raise to stop (Optuna pruning).
    """
    import torch

    from .model import LossConfig, PINN, TwinLSTM

    cfg = copy.deepcopy(cfg).validate()
    _set_seed(cfg.seed, cfg.threads)
    if len(missions) < 2:
        raise ValueError("training needs at least two missions (one for validation)")
    keys = [(str(m.meta.actuator_id), mission_label(m)) for m in missions]
    tr_idx, va_idx = split if split is not None else D.split_missions(keys, cfg.val_frac, cfg.seed)
    if set(tr_idx) & set(va_idx):
        raise ValueError("training and validation missions overlap")
    params = resolve_params(cfg, [missions[i] for i in tr_idx])
    fs_model = fs_model_for(missions, cfg.fs_target)  # validation missions must reach it too
    rates = sorted({round(float(m.fs), 1) for m in missions})
    if rates[-1] > 1.01 * rates[0]:
        print(f"note: bags at {rates} Hz; model rate {fs_model:.5g} Hz (the lowest), higher rates decimated",
              file=sys.stderr)
    t0 = time.perf_counter()
    segs_by_m = {}
    for k, i in enumerate(list(tr_idx) + list(va_idx)):
        if progress:
            print(f"{_CR}pre-processing {k + 1}/{len(tr_idx) + len(va_idx)}", end="" if _CR else "\n", file=sys.stderr, flush=True)
        segs_by_m[i] = D.preprocess(missions[i], fs_model, T_ref=params.T_ref, names=cfg.features,
                                    speed_timing=cfg.speed_timing, twist_smoothing=cfg.twist_smoothing)
    if progress:
        print(file=sys.stderr)
    t_pre = time.perf_counter() - t0
    t0 = time.perf_counter()
    tr_segs = [s for i in tr_idx for s in segs_by_m[i]]
    va_segs = [s for i in va_idx for s in segs_by_m[i]]
    if not tr_segs or not va_segs:
        raise ValueError("no usable segment in the training or the validation missions")
    # the physics path: identified on the training missions only (the validation units choose the gate)
    t1 = time.perf_counter()
    path = PhysicsPath.fit(tr_segs, cfg.physics_path)
    for s_ in tr_segs + va_segs:
        s_.Q_phys = path.predict_segment(s_)
    # the paper's input-side parameters the identified balance determines become the physics prior
    params, three_body = path.three_body(params) if cfg.params is None else (params, {"kept": {"all": "params given"}})
    t_ident = time.perf_counter() - t1
    norm = D.Normalizer.fit(tr_segs, cfg.features)
    rem = np.concatenate([(s_.Q_red - s_.Q_phys)[s_.mask] for s_ in tr_segs])
    r_mean, r_std = float(np.mean(rem)), float(np.std(rem))
    r_std = r_std if r_std > 1e-12 * max(1.0, norm.q_std) else norm.q_std
    Wtr = stack_windows(tr_segs, norm, cfg.seq_len, cfg.stride)
    Wva = stack_windows(va_segs, norm, cfg.seq_len, cfg.seq_len)

    net = TwinLSTM(len(cfg.features), len(D.OUTPUTS), cfg.hidden, cfg.layers, cfg.dropout, cfg.skip)
    lcfg = LossConfig(lambda_mode=cfg.lambda_mode, lambda_init=cfg.lambda_init, adaptive_scaling=cfg.adaptive_scaling,
                      ramp_epochs=cfg.ramp_epochs, washout=cfg.washout)
    dev = torch.device("cuda" if cfg.device == "auto" and torch.cuda.is_available() else
                       ("cpu" if cfg.device == "auto" else cfg.device))
    amp = bool(cfg.amp and dev.type == "cuda")
    pinn = PINN(net, params, cfg.declared_effects, norm.q_mean, norm.q_std, lcfg, cfg.extra_terms,
                cfg.calibrate, cfg.calib_reg, physpath=path, r_mean=r_mean, r_std=r_std, amp=amp)
    physics_on = not (cfg.lambda_mode == "fixed" and cfg.lambda_init == 0)
    if dev.type == "cuda":
        torch.backends.cudnn.benchmark = True  # cuDNN picks its fastest LSTM kernels for the fixed window shape
    pinn.to(dev)
    scaler = torch.amp.GradScaler("cuda") if amp else None
    opt = torch.optim.Adam([{"params": net.parameters(), "weight_decay": cfg.weight_decay},
                            {"params": list(pinn.lam.parameters()) + [pinn.calib], "weight_decay": 0.0}], lr=cfg.lr)
    n_tr = len(Wtr["x"])
    steps_per_epoch = max(1, math.ceil(n_tr / cfg.batch))
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.lr, total_steps=cfg.epochs * steps_per_epoch,
                                                pct_start=0.15, anneal_strategy="cos")
    rng = np.random.default_rng(cfg.seed)
    hist: dict[str, list] = {k: [] for k in ("epoch", "train_total", "train_data", "train_physics", "val_total",
                                             "val_data", "val_physics", "lambda_c", "ramp", "lr", "time_s")}
    hist["lambda_c_steps"] = []
    Vt = _to_torch(Wva, device=dev)
    Tt = _to_torch(Wtr, device=dev)  # the training windows live on the device: no host copy per step
    zero = torch.zeros((), device=dev)
    for ep in range(cfg.epochs):
        pinn.train()
        perm = torch.from_numpy(rng.permutation(n_tr)).to(dev)
        acc_t, lam_t = [], []
        for b in range(steps_per_epoch):
            sel = perm[b * cfg.batch:(b + 1) * cfg.batch]
            batch = {k: v[sel] for k, v in Tt.items()}
            res = pinn.losses(batch, epoch=ep + b / steps_per_epoch, physics=physics_on)
            opt.zero_grad(set_to_none=True)
            if scaler is not None:
                scaler.scale(res["L_tot"]).backward()
                scaler.unscale_(opt)
            else:
                res["L_tot"].backward()
            if cfg.grad_clip > 0:
                torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.grad_clip)
            if scaler is not None:
                scaler.step(opt)
                scaler.update()
            else:
                opt.step()
            sched.step()
            # kept as tensors and read once per epoch (a float() per step would synchronise the device)
            acc_t.append(torch.stack([res["L_tot_report"].float(), res["L_d"].detach().float(),
                                      res.get("L_c_ref", zero).detach().float()]))
            lam_t.append(pinn.lam.value().detach())
        acc = torch.stack(acc_t).double().mean(dim=0).cpu().numpy()
        hist["lambda_c_steps"] += [float(v) for v in torch.stack(lam_t).cpu().numpy()]
        pinn.eval()
        with torch.no_grad():
            vr = pinn.losses(Vt, epoch=ep, physics=True, update_scaler=False)
        rec = dict(epoch=ep + 1, train_total=acc[0], train_data=acc[1], train_physics=acc[2],
                   val_total=float(vr["L_d"] + float(pinn.lam.value().detach()) * vr["L_c_ref"]) if physics_on else float(vr["L_d"]),
                   val_data=float(vr["L_d"]), val_physics=float(vr["L_c_ref"]), lambda_c=float(pinn.lam.value().detach()),
                   ramp=float(res["ramp"]), lr=float(sched.get_last_lr()[0]), time_s=time.perf_counter() - t0)
        for k, v in rec.items():
            hist[k].append(v)
        if progress:
            print(f"epoch {ep + 1:3d}/{cfg.epochs}  L_tot {acc[0]:.4g}  L_d {acc[1]:.4g}  L_c {acc[2]:.4g}  "
                  f"val L_d {rec['val_data']:.4g}  lambda_c {rec['lambda_c']:.4g}  {rec['time_s']:.0f}s",
                  file=sys.stderr, flush=True)
        if not all(math.isfinite(rec[k]) for k in ("train_total", "val_data")):
            raise FloatingPointError(f"training diverged at epoch {ep + 1} (non-finite loss); lower the learning rate")
        if epoch_callback is not None:
            epoch_callback(ep, rec)
    train_time = time.perf_counter() - t0

    # post-training, on the training device: one batched prediction per set, reused by the gate,
    # the metrics and the figures
    t1 = time.perf_counter()
    outs_va = predict_outputs(pinn, va_segs, norm, cfg.eval_batch_samples)
    outs_tr = predict_outputs(pinn, tr_segs, norm, cfg.eval_batch_samples)
    gate_info = set_gate(pinn, va_segs, outs_va, cfg.gate_blocks)
    pinn.cpu()
    metrics = {
        "validation": evaluate(pinn, va_segs, norm, outs=outs_va),
        "training": evaluate(pinn, tr_segs, norm, residuals=False, outs=outs_tr),
        "physics_path": path.summary() | {"notes": path.notes, "identify_time_s": t_ident, "three_body": three_body},
        "gate": gate_info,
        "eval_time_s": time.perf_counter() - t1,
        "train_time_s": train_time,
        "preprocess_time_s": t_pre,
        "n_train_missions": len(tr_idx),
        "n_val_missions": len(va_idx),
        "n_train_samples": int(sum(s.n for s in tr_segs)),
        "n_val_samples": int(sum(s.n for s in va_segs)),
        "lambda_c_final": float(pinn.lam.value().detach()),
        "amp": amp,
        "torch_threads": torch.get_num_threads(),
        "device": str(dev),
        "nrmse_definition": "RMSE / (max - min) of the measured Q_red over the set, in %",
    }
    config = {
        "format": MODEL_FORMAT,
        "model_version": cfg.model_version,
        "parent": cfg.parent,
        "inputs": list(D.RAW_INPUTS),
        "features": list(cfg.features),
        "outputs": list(D.OUTPUTS),
        "output_scales": {k: list(v) for k, v in pinn.output_scales().items()},
        # Q_red = physics path + gate * (output_scales.Q_red applied to network output 0)
        "physics_path": path.to_dict() | {"gate": float(pinn.gate)},
        "declared_effects": list(cfg.declared_effects),
        "extra_terms": list(cfg.extra_terms),
        **({"speed_timing": dict(cfg.speed_timing)} if cfg.speed_timing else {}),
        **({"twist_smoothing": dict(cfg.twist_smoothing)} if cfg.twist_smoothing else {}),
        "params": params.to_dict(),
        "calibrated_params": pinn.calibrated_params().to_dict() if cfg.calibrate else None,
        "preprocessing": {"fs_model": fs_model, "antialias": "causal Butterworth order 4, 0.8 x new Nyquist (when decimating)",
                          "differentiation": "per segment: zero-phase Butterworth(2) at 0.25 fs + 2nd-order central differences",
                          "temperature_frame": "gearbox (motor_winding fallback)"},
        "normalization": norm.to_dict(),
        "arch": {"type": "lstm", "layers": cfg.layers, "hidden": cfg.hidden, "dropout": cfg.dropout, "bidirectional": False,
                 "skip": cfg.skip},
        "train": dataclasses.asdict(cfg),
        "data": {
            "train": [{"bag": mission_label(missions[i]), "actuator_id": str(missions[i].meta.actuator_id),
                       "sha256": mission_hash(missions[i])} for i in tr_idx],
            "validation": [{"bag": mission_label(missions[i]), "actuator_id": str(missions[i].meta.actuator_id),
                            "sha256": mission_hash(missions[i])} for i in va_idx],
        },
        "torch_version": torch.__version__,
    }
    result = TrainResult(Path(out_dir) if out_dir else None, metrics, hist, config)
    result.pinn, result.norm, result.segments = pinn, norm, (tr_segs, va_segs)
    result.outputs = (outs_tr, outs_va)
    if out_dir is not None:
        save_model(result, cfg, progress=progress)
    return result


#: |z| of a normalised network feature beyond which a sample is outside the training data.
OOR_SIGMA = 8.0
#: Fraction of such samples above which :func:`eval_model` notes the feature.
OOR_FRAC = 0.01


def out_of_range(norm, segs: Sequence, names: Sequence[str]) -> dict:
    """Features whose values lie beyond ``OOR_SIGMA`` training standard deviations in more than
    ``OOR_FRAC`` of the samples: ``{name: {"frac", "max_z"}}`` (empty when the data are in range)."""
    F = np.concatenate([s.F for s in segs])
    with np.errstate(invalid="ignore", divide="ignore"):
        Z = np.abs((F - norm.f_mean) / norm.f_std)
    out = {}
    for j, nm in enumerate(names):
        z = Z[:, j][np.isfinite(Z[:, j])]
        if len(z) and (z > OOR_SIGMA).mean() > OOR_FRAC:
            out[nm] = {"frac": float((z > OOR_SIGMA).mean()), "max_z": float(z.max())}
    return out


def eval_model(model_dir: str | Path, missions: Sequence) -> dict:
    """Metrics of a trained model on other missions (N, k_t from each bag's metadata)."""
    pinn, norm, cfgd = load_pinn(model_dir)
    fs_model = cfgd["preprocessing"]["fs_model"]
    names = cfgd.get("features", D.FEATURES_V1)
    N_model = float(cfgd.get("params", {}).get("N", float("nan")))
    segs, notes, used = [], [], 0
    for m in missions:
        where = mission_label(m)
        try:
            s_m = D.preprocess(m, fs_model, T_ref=pinn.params.T_ref, names=names,
                               speed_timing=cfgd.get("speed_timing"), twist_smoothing=cfgd.get("twist_smoothing"))
        except ValueError as e:
            if len(missions) == 1:
                raise
            notes.append(f"skipped: {e}")  # one unusable bag of many: say so, score the others
            continue
        notes += [f"{where}: suspect data: {x}" for x in getattr(m.report, "suspect", [])]
        if np.isfinite(N_model) and abs(float(m.meta.gear_ratio) - N_model) > 1e-6 * N_model:
            notes.append(f"{where}: gear ratio N = {float(m.meta.gear_ratio):g} differs from the N = {N_model:g} "
                         "the model was trained on: the physics uses the bag's N, the network extrapolates")
        segs += s_m
        used += 1
    if not segs:
        raise ValueError("no usable segment in the given missions: " + "; ".join(notes))
    F_all = np.concatenate([s_.F for s_ in segs])
    absent = [nm for j, nm in enumerate(names) if not np.isfinite(F_all[:, j]).any()]
    if absent:
        notes.append(f"network inputs {absent} not available in these bags (no /hd/command, no /hd/temperature, "
                     "...): replaced by their training mean, as the onboard runtime does")
    oor = out_of_range(norm, segs, names)
    if oor:
        worst = ", ".join(f"{k} ({v['frac']:.0%} of samples, up to {v['max_z']:.3g} sigma)" for k, v in oor.items())
        notes.append(f"inputs far outside the training data (> {OOR_SIGMA:g} sigma of the training "
                     f"normalisation): {worst}; the network extrapolates and these metrics say little about the "
                     "twin (other hardware, other operating range, encoder offsets or units?)")
    met = evaluate(pinn, segs, norm)
    if oor:
        met["out_of_range"] = oor
    met["n_missions"] = used
    if notes:
        met["notes"] = notes
    return met
