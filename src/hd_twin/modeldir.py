"""The twin model directory: its format, save/load, the one ``config.json`` reader, prediction.

A model directory (written by :func:`write_model` + :func:`hd_twin.train.save_model`)::

    config.json          inputs, features, outputs, declared effects, extra_terms,
                         physical parameters, model_version, preprocessing,
                         normalisation, architecture, loss settings, data hashes
    model.pt             torch state_dict (network, lambda_c, residual scaler)
    twin.onnx            streaming export (:mod:`hd_twin.export`)
    metrics.json, history.json, *.png

Every reader of a model's ``config.json`` (training/evaluation, ONNX runtime, twin node,
``hdphm twin show``, ground discovery) goes through :func:`read_config`. This module sits
below :mod:`hd_twin.train`, :mod:`hd_twin.export` and :mod:`hd_twin.plots` and imports none of
them, so those no longer import each other in a circle.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from . import data as D
from . import physics as ph
from .physpath import PhysicsPath

MODEL_FORMAT = "hd_twin/1"
CONFIG_NAME = "config.json"


def read_config(model_dir: str | Path, *, check_format: bool = False) -> dict[str, Any]:
    """The model's ``config.json`` as a dict; ValueError naming the directory or file when it is
    missing, not JSON, not a mapping, or (``check_format``) not of format ``MODEL_FORMAT``."""
    model_dir = Path(model_dir)
    p = model_dir / CONFIG_NAME
    try:
        cfg = json.loads(p.read_text())
    except FileNotFoundError:
        raise ValueError(f"{model_dir}: not a twin model directory (no config.json)") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"{p}: corrupt JSON ({e})") from None
    if not isinstance(cfg, dict):
        raise ValueError(f"{p}: expected a JSON object, got {type(cfg).__name__}")
    if check_format and cfg.get("format") != MODEL_FORMAT:
        raise ValueError(f"{model_dir}: model format {cfg.get('format')!r}, expected {MODEL_FORMAT!r}")
    return cfg


# ---- save / load ------------------------------------------------------------------
def write_model(result) -> Path:
    """Write the data files of a trained model directory ``result.model_dir``: ``model.pt``,
    ``config.json`` (``result.config``), ``history.json``, ``metrics.json``; ``result`` a
    :class:`hd_twin.train.TrainResult`. The ONNX export and the figures are added by
    :func:`hd_twin.train.save_model`. Returns the directory."""
    import torch

    out = Path(result.model_dir)
    out.mkdir(parents=True, exist_ok=True)
    torch.save(result.pinn.state_dict(), out / "model.pt")
    (out / CONFIG_NAME).write_text(json.dumps(result.config, indent=2))
    (out / "history.json").write_text(json.dumps(result.history))
    (out / "metrics.json").write_text(json.dumps(result.metrics, indent=2))
    return out


def load_pinn(model_dir: str | Path):
    """(PINN in eval mode, Normalizer, config dict) from a model directory."""
    import torch

    from .model import LossConfig, PINN, TwinLSTM

    model_dir = Path(model_dir)
    cfgd = read_config(model_dir, check_format=True)
    a, t = cfgd["arch"], cfgd["train"]
    params = ph.TwinParams.from_dict(cfgd["params"], f"{model_dir}/config.json params")
    norm = D.Normalizer.from_dict(cfgd["normalization"])
    net = TwinLSTM(len(cfgd["features"]), len(cfgd["outputs"]), a["hidden"], a["layers"], a["dropout"], a.get("skip", False))
    lcfg = LossConfig(lambda_mode=t["lambda_mode"], lambda_init=t["lambda_init"], adaptive_scaling=t["adaptive_scaling"],
                      ramp_epochs=t["ramp_epochs"], washout=t["washout"])
    pp = cfgd.get("physics_path")
    r_mean, r_std = cfgd["output_scales"]["Q_red"]
    pinn = PINN(net, params, cfgd["declared_effects"], norm.q_mean, norm.q_std, lcfg, cfgd.get("extra_terms", []),
                t.get("calibrate", []), t.get("calib_reg", 1e-2), physpath=PhysicsPath.from_dict(pp),
                r_mean=r_mean, r_std=r_std)
    try:
        sd = torch.load(model_dir / "model.pt", weights_only=True)
    except FileNotFoundError:
        raise ValueError(f"{model_dir}: model.pt missing") from None
    missing, unexpected = pinn.load_state_dict(sd, strict=False)
    if "gate" in missing and pp:
        pinn.gate.fill_(float(pp.get("gate", 1.0)))
    if unexpected or set(missing) - {"calib", "lam.s_d", "gate"}:  # older models lack these (defaults reproduce them)
        raise ValueError(f"{model_dir}/model.pt does not match config.json (missing {missing}, unexpected {unexpected})")
    pinn.eval()
    return pinn, norm, cfgd


# ---- prediction -------------------------------------------------------------------
def _device_of(pinn):
    return next(pinn.parameters()).device


def segment_phys(pinn, segs: Sequence[D.Segment]) -> list[np.ndarray]:
    """The physics path per segment (cached on the segment; zeros without one)."""
    out = []
    for s in segs:
        if s.Q_phys is None or len(s.Q_phys) != s.n:
            s.Q_phys = pinn.physpath.predict_segment(s)
        out.append(s.Q_phys)
    return out


def predict_outputs(pinn, segs: Sequence[D.Segment], norm: D.Normalizer, batch_samples: int = 1 << 20) -> list[np.ndarray]:
    """Raw network outputs [n, n_out] per segment, full sequences from a zero state (as streaming).

    Vectorised: segments sorted by length and run as padded batches (the LSTM is causal, so padding
    after a segment's end never changes its outputs) on the model's device, under autocast on CUDA;
    ``batch_samples`` bounds the padded samples per batch.
    """
    import torch

    pinn.eval()
    dev = _device_of(pinn)
    out: list[np.ndarray | None] = [None] * len(segs)
    order = sorted(range(len(segs)), key=lambda i: segs[i].n, reverse=True)
    k = 0
    with torch.no_grad():
        while k < len(order):
            L = segs[order[k]].n
            nb = max(1, min(len(order) - k, batch_samples // max(L, 1)))
            idx = order[k:k + nb]
            x = np.zeros((nb, L, len(norm.f_mean)), np.float32)
            for j, i in enumerate(idx):
                z = norm.norm_features(segs[i].F)
                x[j, :len(z)] = z
                x[j, len(z):] = z[-1]
            y, _ = pinn.forward_net(torch.from_numpy(x).to(dev))
            y = y.float().cpu().numpy()
            for j, i in enumerate(idx):
                out[i] = y[j, :segs[i].n].astype(np.float64)
            k += nb
    return out  # type: ignore[return-value]


def q_from_outputs(pinn, segs: Sequence[D.Segment], outs: Sequence[np.ndarray], gate: float | None = None) -> list[np.ndarray]:
    """The twin's Q_red [N*m] per segment: physics path + gate x remainder."""
    g = float(pinn.gate) if gate is None else float(gate)
    return [qp + g * (pinn.r_mean + pinn.r_std * o[:, 0]) for qp, o in zip(segment_phys(pinn, segs), outs)]


def predict_segments(pinn, segs: Sequence[D.Segment], norm: D.Normalizer) -> list[np.ndarray]:
    """Full-sequence Q_red prediction [N*m] per segment (zero initial state, as streaming)."""
    return q_from_outputs(pinn, segs, predict_outputs(pinn, segs, norm))
