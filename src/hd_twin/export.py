"""ONNX export of a trained twin for streaming inference.

The graph is ``(x [B, T, n_features] normalised, h0 [L, B, H], c0 [L, B, H])
-> (y [B, T, n_outputs] normalised, h_n, c_n)`` with dynamic B and T, so the
onboard node can feed one sample or a block at a time and carry the LSTM
state. Normalisation and output scaling stay outside the graph, in
``config.json`` (applied by :class:`hd_twin.runtime.StreamingTwin`).
"""

from __future__ import annotations

import warnings
from pathlib import Path

ONNX_NAME = "twin.onnx"
OPSET = 17


def export_onnx(model_dir: str | Path, out_path: str | Path | None = None) -> Path:
    """Export ``model_dir/model.pt`` to ONNX (default ``model_dir/twin.onnx``); returns the path."""
    import torch

    from .model import StreamWrapper
    from .modeldir import load_pinn

    model_dir = Path(model_dir)
    pinn, _norm, cfg = load_pinn(model_dir)
    net = pinn.net.eval()
    wrap = StreamWrapper(net).eval()
    L, H = net.layers, net.hidden
    x = torch.zeros(1, 4, net.n_in)
    h0 = torch.zeros(L, 1, H)
    c0 = torch.zeros(L, 1, H)
    path = Path(out_path) if out_path else model_dir / ONNX_NAME
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            wrap, (x, h0, c0), str(path), dynamo=False, opset_version=OPSET,
            input_names=["x", "h0", "c0"], output_names=["y", "h_n", "c_n"],
            dynamic_axes={"x": {0: "batch", 1: "time"}, "h0": {1: "batch"}, "c0": {1: "batch"},
                          "y": {0: "batch", 1: "time"}, "h_n": {1: "batch"}, "c_n": {1: "batch"}},
        )
    return path
