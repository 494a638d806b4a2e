"""Twin benchmarks.

Default (``hdphm bench twin``): **accuracy on held-out units, per plant family and on the second plant**,
in one run. For each data source a small fleet is written (``hdphm sim fleet --family NAME`` for every
family ``hd_sim.families`` knows, today's plant when it knows none, and the independent plant
``python -m tests.plants.ema2 fleet``); the first actuators train, the last ``--held-out`` are never
seen by any fit. On the same model-rate samples of the held-out units it prints NRMSE (RMSE / range of
the measured Q_red) and the maximum error of

* ``twin``: the physics-informed twin (identified physics path + gated LSTM remainder, r1..r4 loss,
  learnable lambda_c, adaptive scaling, ramp), ``small`` preset;
* ``physics path``: the twin's identified torque balance alone (``hd_twin.identify``);
* ``least squares``: the 4-term motor-side balance a competent engineer writes in an afternoon,
  ``Q_red ~ a tau_m + b d(omega_m)/dt + c tanh(omega_m / eps) + d omega_m``, fitted by ordinary least
  squares on the training units, ``eps`` the best in-sample of 8 log-spaced values 0.01-5 rad/s, the
  derivative the twin's (zero-phase Butterworth at 0.25 fs + central differences); see :func:`ls_fit`;
* ``pure LSTM``: the same network and preset with lambda_c = 0 and no physics path.

``hdphm bench twin --extra --streaming [MODEL_DIR]``: the former streaming benchmark (ONNX Runtime vs
PyTorch, sample by sample and in blocks; the physics overhead of one training step), and the streaming
twin's physics path before (``legacy_physics``: the derivative re-evaluated on the history at every call)
and after (fixed FIR weights; causal and fixed-lag), interleaved in the same run, with ratios.

``hdphm bench twin --extra --streaming-error MODEL_DIR BAGS [--block 20] [--settle 0.05]``: accuracy of the
streaming twin against the batch twin on every mission of BAGS fed in blocks: causal and fixed-lag mode,
NRMSE and maximum error on the samples the batch metrics score (edge samples out), plus the causal mode's
maximum outside the onboard's settle interval after each reset.

Options (after ``--extra``): ``--families a,b`` (default: all, plus ``plant2``), ``--actuators N``
(per source, default 6), ``--held-out K`` (default 2), ``--missions M`` (default 2), ``--duration S``
(default 10), ``--epochs E`` (default: the small preset's 15), ``--seed S``, ``--keep DIR`` (keep bags).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

#: Candidate Coulomb widths [rad/s at the motor] of the least-squares baseline.
LS_EPS_GRID = np.geomspace(0.01, 5.0, 8)


# ---- the plain least-squares baseline -------------------------------------------------------
def _ls_columns(seg, eps: float) -> np.ndarray:
    from hd_twin import data as D

    w = seg.X[:, 1]
    return np.column_stack([seg.X[:, 2], D.derivative(w, seg.dt), np.tanh(w / eps), w])


def ls_fit(segs) -> tuple[float, np.ndarray]:
    """(eps, coefficients) of Q_red ~ a tau_m + b omega_m' + c tanh(omega_m / eps) + d omega_m."""
    best = None
    for eps in LS_EPS_GRID:
        A = np.vstack([_ls_columns(s, eps)[s.mask] for s in segs])
        y = np.concatenate([s.Q_red[s.mask] for s in segs])
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        sse = float(np.sum((A @ coef - y) ** 2))
        if best is None or sse < best[0]:
            best = (sse, float(eps), coef)
    return best[1], best[2]


def ls_predict(segs, eps: float, coef: np.ndarray) -> np.ndarray:
    return np.concatenate([_ls_columns(s, eps) @ coef for s in segs])


# ---- data sources -----------------------------------------------------------------------------
def _families() -> list[str]:
    try:
        from hd_sim.families import FAMILIES  # noqa: PLC0415
    except ImportError:
        return ["hd_sim"]
    return list(FAMILIES)


def _write_source(name: str, out: Path, a: argparse.Namespace) -> None:
    py = sys.executable
    if name == "plant2":
        cmd = [py, "-m", "tests.plants.ema2", "fleet", "--units", str(a.actuators), "--missions", str(a.missions),
               "--duration", str(a.duration), "--seed", str(a.seed), "--out", str(out)]
    else:
        cmd = [py, "-m", "hdphm.cli", "sim", "fleet", "--actuators", str(a.actuators), "--missions", str(a.missions),
               "--duration", str(a.duration), "--seed", str(a.seed), "--out", str(out), "--workers", "1", "--quiet",
               "--sim-internal-every", "0", "--profiles", "inspection,flight,sweep"]
        if name != "hd_sim":
            cmd += ["--family", name]
            i = cmd.index("--profiles")
            del cmd[i:i + 2]  # the family's own profile cycle
    r = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[1:5])} failed: {(r.stderr or r.stdout).strip().splitlines()[-1:]}")


def _common_rate(missions):
    """Missions one twin can be trained and scored on: one model rate (mixed log rates: the base rate
    that keeps the most missions, each an integer multiple of it within 5 %) and one gear ratio (the most
    common), and a note on what was left out."""
    rates = sorted({float(m.fs) for m in missions})

    def fits(fs, base):
        k = round(fs / base)
        return k >= 1 and abs(fs / k - base) <= 0.05 * base

    base = max(rates, key=lambda b: (sum(fits(m.fs, b) for m in missions), -b))
    keep = [m for m in missions if fits(m.fs, base)]
    notes = [] if len(keep) == len(missions) else [
        f"log rates {sorted({round(r) for r in rates})} Hz: {len(missions) - len(keep)} missions not an integer "
        f"multiple of {base:.0f} Hz left out"]
    # one twin per actuator type: the units of the most common gear ratio (a family may draw several)
    ratios = sorted({float(m.meta.gear_ratio) for m in keep})
    if len(ratios) > 1:
        acts = {r: {m.meta.actuator_id for m in keep if float(m.meta.gear_ratio) == r} for r in ratios}
        N = max(ratios, key=lambda r: (len(acts[r]), -r))
        notes.append(f"gear ratios {ratios}: the {len(acts[N])} units at N = {N:g} used (one twin per actuator type)")
        keep = [m for m in keep if float(m.meta.gear_ratio) == N]
    return keep, "; ".join(notes)


def _split_units(missions, held_out: int):
    acts = sorted({str(m.meta.actuator_id) for m in missions})
    if len(acts) <= held_out + 1:
        raise ValueError(f"{len(acts)} actuators: need more than held-out + 1")
    test = set(acts[-held_out:])
    return [m for m in missions if str(m.meta.actuator_id) not in test], [m for m in missions if str(m.meta.actuator_id) in test]


def _metrics(yt, yp) -> dict:
    from hd_twin.train import q_metrics

    return q_metrics(yt, yp)


def compare_source(name: str, bag_dir: Path, a: argparse.Namespace) -> dict:
    from hd_twin import data as D
    from hd_twin.train import TrainConfig, evaluate, load_missions, train_twin

    missions, note = _common_rate(load_missions([bag_dir], progress=False))
    if note:
        print(f"  {name}: {note}", flush=True)
    train_m, test_m = _split_units(missions, a.held_out)
    row: dict = {"source": name, "note": note, "n_train_units": len({m.meta.actuator_id for m in train_m}),
                 "n_test_units": len({m.meta.actuator_id for m in test_m})}
    kw = dict(plots=False, export_onnx=False, threads=a.threads, seed=a.seed)
    if a.epochs:
        kw["epochs"] = a.epochs
    t0 = time.perf_counter()
    tw = train_twin(train_m, None, TrainConfig.from_preset("small", **kw), progress=False)
    row["t_twin_s"] = time.perf_counter() - t0
    fs_model = tw.config["preprocessing"]["fs_model"]
    names = tw.config["features"]
    test_segs = [s for m in test_m for s in D.preprocess(m, fs_model, T_ref=tw.pinn.params.T_ref, names=names)]
    met = evaluate(tw.pinn, test_segs, tw.norm, residuals=False)
    row["twin"] = met
    row["physics_path"] = met["physics_only"] if tw.pinn.physpath.active else None
    row["gate"] = float(tw.pinn.gate)
    row["path_summary"] = tw.metrics["physics_path"]
    tr_segs = tw.segments[0] + tw.segments[1]  # the twin's training units (train + validation)
    yt = np.concatenate([np.where(s.mask, s.Q_red, np.nan) for s in test_segs])
    eps, coef = ls_fit(tr_segs)
    row["ls"] = _metrics(yt, ls_predict(test_segs, eps, coef)) | {"eps": eps, "coef": coef.tolist()}
    t0 = time.perf_counter()
    pure = train_twin(train_m, None, TrainConfig.from_preset("small", lambda_mode="fixed", lambda_init=0.0,
                                                             physics_path="none", **kw), progress=False)
    row["t_pure_s"] = time.perf_counter() - t0
    row["pure"] = evaluate(pure.pinn, test_segs, pure.norm, residuals=False)
    return row


def _fmt(m: dict | None) -> str:
    if not m:
        return "n/a"
    return f"{m['nrmse_pct']:.3f} % / {m['max_err']:.4g}"


def compare(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="hdphm bench twin")
    p.add_argument("--families", help="comma-separated sources (families of hd_sim, 'hd_sim', 'plant2')")
    p.add_argument("--actuators", type=int, default=6)
    p.add_argument("--held-out", type=int, default=2)
    p.add_argument("--missions", type=int, default=2)
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--epochs", type=int)
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--keep", help="write the bags here and keep them")
    a = p.parse_args(argv)
    sources = a.families.split(",") if a.families else _families() + ["plant2"]
    tmp = None
    root = Path(a.keep) if a.keep else Path(tmp := tempfile.mkdtemp(prefix="bench_twin_"))
    print(f"held-out accuracy per source: {a.actuators} actuators x {a.missions} missions x {a.duration:g} s, "
          f"the last {a.held_out} held out; twin and pure LSTM: small preset"
          + (f", {a.epochs} epochs" if a.epochs else "") + f", seed {a.seed}, {a.threads} threads", flush=True)
    rows = []
    for src in sources:
        t0 = time.perf_counter()
        try:
            d = root / src
            if not d.exists():
                _write_source(src, d, a)
            row = compare_source(src, d, a)
        except Exception as e:  # one failing source must not hide the others
            print(f"  {src}: error: {type(e).__name__}: {e}", flush=True)
            rows.append({"source": src, "error": str(e)})
            continue
        row["t_s"] = time.perf_counter() - t0
        rows.append(row)
        print(f"  {src}: done in {row['t_s']:.0f} s (gate {row['gate']:.3f}, LS eps {row['ls']['eps']:.3g} rad/s)",
              flush=True)
    print("\nNRMSE / max error [N*m] on held-out units (same model-rate samples for every column)\n")
    print("| source | twin | physics path (identified) | least squares (4-term) | pure LSTM (lambda_c = 0) | gate |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        if "error" in r:
            print(f"| {r['source']} | error: {r['error'][:80]} | | | | |")
            continue
        print(f"| {r['source']} | {_fmt(r['twin'])} | {_fmt(r['physics_path'])} | {_fmt(r['ls'])} | "
              f"{_fmt(r['pure'])} | {r['gate']:.2f} |")
    ok = [r for r in rows if "error" not in r and r["physics_path"]]
    if ok:
        worse = [r["source"] for r in ok if r["twin"]["nrmse_pct"] > r["physics_path"]["nrmse_pct"]]
        ratio = [r["physics_path"]["nrmse_pct"] / r["ls"]["nrmse_pct"] for r in ok]
        print(f"\ntwin worse than its physics path on: {worse or 'none'}; physics path / least squares NRMSE: "
              + ", ".join(f"{r['source']} {q:.2f}x" for r, q in zip(ok, ratio)))
    if tmp:
        import shutil

        shutil.rmtree(tmp, ignore_errors=True)
    return 0 if all("error" not in r for r in rows) else 1


# ---- streaming (ONNX Runtime vs PyTorch) and training-step cost --------------------------------
def _median_time(fn, repeat: int) -> float:
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def streaming(argv: list[str]) -> int:
    import torch

    torch.set_num_threads(1)
    sys.path.insert(0, str(REPO / "tests" / "twin"))
    from synth import synth_fleet, synth_mission  # noqa: PLC0415

    from hd_twin import data as D
    from hd_twin.runtime import StreamingTwin
    from hd_twin.train import TrainConfig, _to_torch, load_pinn, stack_windows, train_twin

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

    # the physics path before / after the FIR, interleaved (same process, same load)
    legacy = StreamingTwin(model_dir, fs_in=fs_model, gear_ratio=m.meta.gear_ratio, legacy_physics=True)
    lagged = StreamingTwin(model_dir, fs_in=fs_model, gear_ratio=m.meta.gear_ratio, mode="fixed_lag")

    def feed(t, block, n):
        def f():
            t.reset(fs_model)
            for i in range(0, n, block):
                t.step(X[i:i + block])
        return f

    variants = (("before (re-fit per call)", legacy), ("after, causal", tw), ("after, fixed-lag", lagged))
    cases = [(name, kind, feed(t, b, n)) for name, t in variants for kind, b, n in (("one", 1, 200), ("block", 100, 2000))]
    rounds = {(name, kind): [] for name, kind, _ in cases}
    for _ in range(7):  # interleaved rounds: a load change hits every variant alike
        for name, kind, f in cases:
            rounds[(name, kind)].append(_median_time(f, 1))
    # the physics path alone, one model-rate row per call (what the FIR replaced), before / after
    rows = X[:200]

    def path_legacy():
        legacy.reset(fs_model)
        for i in range(200):
            legacy._phys_legacy(rows[i:i + 1])

    def path_fir():
        tw.reset(fs_model)
        for i in range(200):
            tw._phys_causal(rows[i:i + 1])

    for name, f in (("path before", path_legacy), ("path after", path_fir)):
        rounds[(name, "one")] = []
    for _ in range(7):
        for name, f in (("path before", path_legacy), ("path after", path_fir)):
            rounds[(name, "one")].append(_median_time(f, 1))
    med = {k: statistics.median(v) for k, v in rounds.items()}
    pb, pa = med[("path before", "one")], med[("path after", "one")]
    print(f"  physics path alone, one row per call: before {pb / 200 * 1e6:.1f} us, after (FIR) {pa / 200 * 1e6:.1f} us"
          f"   speed-up x{pb / pa:.1f}")
    print(f"streaming twin with its physics path ({'active' if tw.physpath.active else 'none'}; fixed-lag latency "
          f"{lagged.lag_samples} samples = {lagged.lag_s * 1e3:.1f} ms), median of 7 interleaved rounds, 1 thread:")
    for kind, n in (("one", 200), ("block", 2000)):
        base = med[("before (re-fit per call)", kind)]
        for name, _ in variants:
            v = med[(name, kind)]
            print(f"  {kind:5s} {name:26s} {v / n * 1e6:8.1f} us/sample  {n / v / fs_model:8.1f} x real time  "
                  f"speed-up vs before x{base / v:5.2f}")

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


def streaming_error(argv: list[str]) -> int:
    """Streaming (causal, fixed-lag) vs batch twin on the missions of BAGS (see the module docstring)."""
    p = argparse.ArgumentParser(prog="hdphm bench twin --extra --streaming-error")
    p.add_argument("model")
    p.add_argument("bags", nargs="+")
    p.add_argument("--block", type=int, default=20, help="input rows per call (default 20)")
    p.add_argument("--settle", type=float, default=0.05, help="onboard settle interval [s] (default 0.05)")
    a = p.parse_args(argv)
    from hd_twin import data as D
    from hd_twin.modeldir import predict_outputs, q_from_outputs
    from hd_twin.runtime import StreamingTwin
    from hd_twin.train import load_missions, load_pinn

    pinn, norm, cfg = load_pinn(a.model)
    fs_model = cfg["preprocessing"]["fs_model"]
    missions = load_missions(a.bags)
    errs = {"batch": [], "causal": [], "fixed_lag": []}
    y_all, worst_settled = [], (0.0, "")
    for m in missions:
        segs = D.preprocess(m, fs_model, T_ref=pinn.params.T_ref, names=cfg["features"],
                            speed_timing=cfg.get("speed_timing"))
        ref = q_from_outputs(pinn, segs, predict_outputs(pinn, segs, norm))
        X = D.mission_inputs(m)
        bounds = [(s0, s1) for s0, s1 in D.segment_bounds(m.segment) if s1 - s0 >= max(3, 16 * round(m.fs / fs_model))]
        streams = {}
        for mode in ("causal", "fixed_lag"):
            tw = StreamingTwin(a.model, fs_in=m.fs, gear_ratio=m.meta.gear_ratio, mode=mode)
            per = []
            for s0, s1 in bounds:
                tw.reset(m.fs, m.meta.gear_ratio)
                outs = [tw.step(X[i:min(i + a.block, s1)]) for i in range(s0, s1, a.block)] + [tw.flush()]
                per.append(np.concatenate([o["Q_red"] for o in outs]))
            streams[mode] = per
        for k, seg in enumerate(segs):
            ok = seg.mask  # the batch metrics' samples: measured, not edge samples
            y_all.append(seg.Q_red[ok])
            errs["batch"].append((ref[k] - seg.Q_red)[ok])
            for mode in ("causal", "fixed_lag"):
                q = streams[mode][k]
                if len(q) != seg.n:
                    raise SystemExit(f"{m.report.path}: {mode} gave {len(q)} outputs for {seg.n} model samples")
                errs[mode].append((q - seg.Q_red)[ok])
            q = streams["causal"][k]
            settled = ok & (np.arange(seg.n) * seg.dt >= a.settle)
            e = np.abs(q - seg.Q_red)[settled]
            if len(e) and e.max() > worst_settled[0]:
                worst_settled = (float(e.max()), f"{m.report.path} sample {int(np.flatnonzero(settled)[np.argmax(e)])}")
    y = np.concatenate(y_all)
    rng_y = float(y.max() - y.min())
    print(f"model {a.model} ({fs_model:.0f} Hz), {len(missions)} missions, {len(y)} scored samples (edge samples out), "
          f"streamed in blocks of {a.block} input rows")
    for mode, ee in errs.items():
        e = np.concatenate(ee)
        print(f"  {mode:9s}  NRMSE {100 * np.sqrt(np.mean(e ** 2)) / rng_y:6.3f} %   max error {np.max(np.abs(e)):8.1f} N*m")
    print(f"  causal, after the onboard settle ({a.settle * 1e3:.0f} ms after each reset): max {worst_settled[0]:.1f} N*m "
          f"({worst_settled[1]})")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = list(argv or [])
    if argv and argv[0] == "--streaming":
        return streaming(argv[1:])
    if argv and argv[0] == "--streaming-error":
        return streaming_error(argv[1:])
    return compare(argv)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main(sys.argv[1:]))
