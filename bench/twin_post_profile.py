"""Time (and optionally cProfile) a twin's post-training steps on a trained model, without retraining.

    python bench/twin_post_profile.py MODEL_DIR BAGS_DIR OUT_DIR [--profile]

Rebuilds the training/validation segments named in MODEL_DIR/config.json from BAGS_DIR, then runs what
``train_twin``/``save_model`` do after the last epoch: predictions and metrics of both sets, model
files, ONNX export, figures, timing each step. Works with the code before issue 11 (``evaluate`` per
set, figures predicting again) and after it (one batched ``predict_outputs`` per set, reused by the gate,
the metrics and the figures): run it with ``PYTHONPATH`` pointing at either tree, e.g. the old one from
``git archive a459c52 src | tar -x -C /tmp/old``.
"""

from __future__ import annotations

import cProfile
import io
import json
import pstats
import shutil
import sys
import time
from pathlib import Path


def main(argv: list[str]) -> int:
    import torch

    from hd_twin import data as D
    from hd_twin import train as T
    from hd_twin.export import export_onnx
    from hd_twin.plots import plot_training

    torch.set_num_threads(2)
    model, bags, out = Path(argv[0]), argv[1], Path(argv[2])
    prof = "--profile" in argv
    pinn, norm, cfg = T.load_pinn(model)
    ms = {T.mission_label(m): m for m in T.load_missions([bags], progress=False)}
    fs = cfg["preprocessing"]["fs_model"]

    def seg(side):
        return [s for d in cfg["data"][side]
                for s in D.preprocess(ms[d["bag"]], fs, T_ref=pinn.params.T_ref, names=cfg["features"])]

    tr, va = seg("train"), seg("validation")
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    shutil.copy(model / "config.json", out / "config.json")
    hist = json.loads((model / "history.json").read_text())
    new = hasattr(T, "predict_outputs")
    tt: dict[str, float] = {}
    pr = cProfile.Profile() if prof else None
    if pr:
        pr.enable()
    t0 = time.perf_counter()

    def step(name, fn):
        t = time.perf_counter()
        r = fn()
        tt[name] = time.perf_counter() - t
        return r

    if new:
        ova = step("predict_val", lambda: T.predict_outputs(pinn, va, norm))
        otr = step("predict_train", lambda: T.predict_outputs(pinn, tr, norm))
        step("gate+metrics", lambda: (T.set_gate(pinn, va, ova), T.evaluate(pinn, va, norm, outs=ova),
                                      T.evaluate(pinn, tr, norm, residuals=False, outs=otr)))
        outs = (otr, ova)
    else:
        step("evaluate_val", lambda: T.evaluate(pinn, va, norm))
        step("evaluate_train", lambda: T.evaluate(pinn, tr, norm, residuals=False))
        outs = None
    step("model.pt", lambda: torch.save(pinn.state_dict(), out / "model.pt"))
    step("onnx", lambda: export_onnx(out))
    step("plots", lambda: plot_training(out, pinn, norm, tr, va, hist, outs=outs) if new
         else plot_training(out, pinn, norm, tr, va, hist))
    total = time.perf_counter() - t0
    print(f"{'after' if new else 'before'} issue 11: post-training {total:.2f} s "
          f"({sum(s.n for s in tr)} training + {sum(s.n for s in va)} validation samples, "
          f"LSTM {pinn.net.layers}x{pinn.net.hidden}, {torch.get_num_threads()} threads): "
          + ", ".join(f"{k} {v:.2f} s" for k, v in tt.items()))
    if pr:
        pr.disable()
        s = io.StringIO()
        pstats.Stats(pr, stream=s).sort_stats("tottime").print_stats(12)
        print(s.getvalue())
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main(sys.argv[1:]))
