"""Twin benchmarks: streaming inference (ONNX Runtime) and training-step cost.

Prints medians and ratios against baselines measured in the same run:

* streaming: ``StreamingTwin.step`` on one sample and on 100-sample blocks
  versus the PyTorch network on the same inputs carrying the same state
  (the baseline the ONNX export must beat or match); samples/s and the ratio
  to the real-time rate of the model (fs_model).
* training: one optimiser step of the PINN (data + physics loss) versus the
  same step with lambda_c = 0 (the physics overhead).

Usage: ``hdphm bench twin [--extra MODEL_DIR]`` (default: a freshly trained
tiny model on synthetic missions, so it runs without bags).
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path


def _median_time(fn, repeat: int) -> float:
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def main(argv: list[str] | None = None) -> int:
    import numpy as np
    import torch

    torch.set_num_threads(1)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "twin"))
    from synth import synth_fleet, synth_mission  # noqa: PLC0415

    from hd_twin import data as D
    from hd_twin.runtime import StreamingTwin
    from hd_twin.train import TrainConfig, _to_torch, load_pinn, stack_windows, train_twin

    argv = argv or []
    tmp = None
    if argv:
        model_dir = Path(argv[0])
    else:
        tmp = tempfile.TemporaryDirectory()
        model_dir = Path(tmp.name)
        print("training a small model on synthetic missions for the benchmark ...", flush=True)
        train_twin(synth_fleet(4, 2, duration=3.0), model_dir,
                   TrainConfig.from_preset("small", epochs=1, fs_target=None, plots=False), progress=False)
    pinn, norm, cfg = load_pinn(model_dir)
    fs_model = cfg["preprocessing"]["fs_model"]
    m = synth_mission("BENCH", 0, fs=fs_model, duration=max(4.0, 2100 / fs_model), seed=1)
    X = D.mission_inputs(m)
    tw = StreamingTwin(model_dir, fs_in=fs_model, gear_ratio=m.meta.gear_ratio)
    net = pinn.net.eval()
    Z = torch.from_numpy(norm.norm_features(D.features(X, m.meta.gear_ratio, 1.0 / fs_model)).astype(np.float32))[None]
    L, H = net.layers, net.hidden

    def onnx_one():
        tw.reset(fs_model)
        for i in range(200):
            tw.step(X[i:i + 1])

    def torch_one():
        st = (torch.zeros(L, 1, H), torch.zeros(L, 1, H))
        with torch.no_grad():
            for i in range(200):
                _, st = net(Z[:, i:i + 1], st)

    def onnx_block():
        tw.reset(fs_model)
        for i in range(0, 2000, 100):
            tw.step(X[i:i + 100])

    def torch_block():
        st = (torch.zeros(L, 1, H), torch.zeros(L, 1, H))
        with torch.no_grad():
            for i in range(0, 2000, 100):
                _, st = net(Z[:, i:i + 100], st)

    rep = 7
    res = {k: _median_time(f, rep) for k, f in (("onnx_one", onnx_one), ("torch_one", torch_one),
                                                 ("onnx_block", onnx_block), ("torch_block", torch_block))}
    print(f"model {model_dir}: LSTM {L}x{H}, fs_model {fs_model:.1f} Hz, 1 thread, median of {rep}")
    for kind, n in (("one", 200), ("block", 2000)):
        o, t = res[f"onnx_{kind}"], res[f"torch_{kind}"]
        print(f"  streaming {kind:5s}: ONNX Runtime {n / o:10.0f} samples/s ({o / n * 1e6:7.1f} us/sample, "
              f"{n / o / fs_model:7.1f} x real time)   PyTorch baseline {n / t:10.0f} samples/s   ratio ONNX/PyTorch speed {t / o:5.2f}")

    # training step: PINN vs lambda_c = 0
    segs = D.preprocess(m, fs_model)
    W = stack_windows(segs, norm, 200, 100)
    b = _to_torch(W)

    def step(physics):
        def f():
            pinn.train()
            r = pinn.losses(b, epoch=10, physics=physics)
            pinn.zero_grad()
            r["L_tot"].backward()
        return f

    tp = _median_time(step(True), rep)
    td = _median_time(step(False), rep)
    nb = W["x"].shape[0] * W["x"].shape[1]
    print(f"  training step ({W['x'].shape[0]} windows x 200): PINN {tp * 1e3:.1f} ms   data-only baseline {td * 1e3:.1f} ms"
          f"   physics overhead x{tp / td:.2f}   ({nb / tp:.0f} samples/s)")
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main(sys.argv[1:]))
