"""Benchmark: our particle filter vs progpy's on the same Archard model (and the UKF), speed and accuracy.

Prints medians (ms) and ratios measured in this run:
  * PF step (predict + update + ESS-triggered resampling) with 10 000 particles (target < 2 ms),
  * full RUL distribution from 10 000 particles (target < 20 ms),
  * progpy ParticleFilter.estimate on the equivalent progpy model, same particles (target ratio >= 10x),
  * UKF step,
and the wear-tracking accuracy of the three filters on the same synthetic runs (RMSE of h, coverage of
the truth by the P5-P95 band).

    hdphm bench pf [--extra --particles 10000 --reps 50]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _setup(n_particles: int, seed: int = 0):
    from hd_prognostic.models import ArchardWear
    from hd_prognostic.observation import ObservationModel

    obs = ObservationModel(coef=[1e-5, 3e-5, 0.5e-5], s0=1.5e-6, s1=1e-6, h_ref=1e-5)
    model = ArchardWear(h_fail=30e-6, log_kappa_mean=np.log(1e-12), log_kappa_std=0.4, sigma_proc=0.2,
                        sigma_log_kappa=0.01, observe_fn=obs)
    return model, obs


def _truth(model, obs, n, W, seed):
    rng = np.random.default_rng(seed)
    x = model.sample_prior(1, rng)
    xs = [x]
    for _ in range(n):
        x = model.propagate(x, W, rng)
        xs.append(x)
    X = np.vstack(xs)
    z = obs.mean(X[:, 0]) + obs.std(X[:, 0]) * rng.standard_normal(len(X))
    return X, z


def _median_ms(f, reps: int) -> float:
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(ts))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench pf")
    ap.add_argument("--particles", type=int, default=10000)
    ap.add_argument("--reps", type=int, default=50)
    ap.add_argument("--progpy-reps", type=int, default=5)
    ap.add_argument("--runs", type=int, default=3, help="synthetic runs for the accuracy comparison")
    ap.add_argument("--progpy-particles", type=int, default=None, help="default: same as --particles")
    a = ap.parse_args(argv or [])
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass
    from hd_prognostic.pf import ParticleFilter, weighted_quantile
    from hd_prognostic.rul import rul_distribution
    from hd_prognostic.ukf import UnscentedKalmanFilter

    n = a.particles
    model, obs = _setup(n)
    W = 1e5
    X, z = _truth(model, obs, 80, W, seed=11)
    fail = np.flatnonzero(X[:, 0] >= model.h_fail)
    print(f"model: ArchardWear (h, log_kappa), heteroscedastic observation; {n} particles; synthetic truth "
          + (f"fails at step {fail[0]}" if len(fail) else f"still below h_fail after {len(X) - 1} steps"))

    # ---- our PF step ------------------------------------------------------------
    pf = ParticleFilter(model, n, seed=0)
    for k in range(1, 30):
        pf.step(W, z[k])
    state = (pf.x.copy(), pf.logw.copy())
    k_iter = iter(range(10**9))

    def our_step():
        pf.step(W, z[30 + next(k_iter) % 10])

    t_pf = _median_ms(our_step, a.reps)
    pf.x, pf.logw = state

    def our_update_only():
        pf.update(z[30])

    t_upd = _median_ms(our_update_only, a.reps)
    pf.x, pf.logw = state
    # ---- RUL distribution ---------------------------------------------------------------------
    t_rul = _median_ms(lambda: rul_distribution(model, pf.x, pf.weights, W, 1.0, 1000, 0), max(5, a.reps // 5))
    r = rul_distribution(model, pf.x, pf.weights, W, 1.0, 1000, 0)
    # ---- UKF ---------------------------------------------------------------------------------
    ukf = UnscentedKalmanFilter.from_prior(model)
    t_ukf = _median_ms(lambda: ukf.step(W, z[30]), a.reps)
    # ---- progpy PF -------------------------------------------------------------------------------
    t_pp = float("nan")
    pp_err = None
    npp = a.progpy_particles or n
    try:
        from hd_prognostic.progpy_adapter import make_progpy_pf

        x0 = model.sample_prior(npp, np.random.default_rng(0))
        ppf, _ = make_progpy_pf(model, x0, obs_std=float(obs.std(15e-6)))
        kk = iter(range(1, 10**9))

        def pp_step():
            k = next(kk)
            ppf.estimate(float(k), {"W": W}, {"y": float(z[min(k, len(z) - 1)])})

        t_pp = _median_ms(pp_step, a.progpy_reps)
    except Exception as e:  # noqa: BLE001 - the baseline is optional
        pp_err = f"{type(e).__name__}: {e}"

    print("\n--- speed (median ms per call) ---")
    print(f"our PF step (predict+update+resample), {n} particles : {t_pf:8.3f} ms   (target < 2 ms)")
    print(f"our PF update only                                   : {t_upd:8.3f} ms")
    print(f"RUL distribution, {n} particles (P50 {r.p50:.0f} steps)  : {t_rul:8.3f} ms   (target < 20 ms)")
    print(f"UKF step                                             : {t_ukf:8.3f} ms")
    if pp_err:
        print(f"progpy PF: unavailable ({pp_err})")
    else:
        print(f"progpy PF estimate, {npp} particles                   : {t_pp:8.3f} ms")
        print(f"ratio progpy / ours (same model, particles)          : {t_pp / t_pf * (n / npp):8.1f} x  (target >= 10x)"
              + ("" if npp == n else f"  [progpy time scaled linearly from {npp} particles]"))

    # ---- accuracy on the same synthetic runs -----------------------------------------------
    print("\n--- accuracy on the same synthetic runs (RMSE of h over steps 10..end, um; P5-P95 coverage of truth) ---")
    acc = {"PF": [], "UKF": [], "progpy PF": []}
    cov = {"PF": [], "UKF": [], "progpy PF": []}
    na = min(n, 2000)
    for run in range(a.runs):
        X, z = _truth(model, obs, 60, W, seed=100 + run)
        p = ParticleFilter(model, na, seed=run)
        u = UnscentedKalmanFilter.from_prior(model, seed=run)
        pp = None
        if not pp_err:
            from hd_prognostic.progpy_adapter import make_progpy_pf

            pp, _ = make_progpy_pf(model, model.sample_prior(na, np.random.default_rng(run)),
                                   obs_std=float(obs.std(15e-6)), seed=run)
        e = {k: [] for k in acc}
        c = {k: [] for k in acc}
        for k in range(1, len(z)):
            p.step(W, z[k])
            u.step(W, z[k])
            if k >= 10:
                q = weighted_quantile(p.x[:, 0], p.weights, [0.05, 0.95])
                e["PF"].append(p.mean()[0] - X[k, 0])
                c["PF"].append(q[0] <= X[k, 0] <= q[1])
                sd = np.sqrt(max(u.P[0, 0], 0))
                e["UKF"].append(u.x[0] - X[k, 0])
                c["UKF"].append(abs(u.x[0] - X[k, 0]) <= 1.645 * sd)
            if pp is not None:
                pp.estimate(float(k), {"W": W}, {"y": float(z[k])})
                if k >= 10:
                    hp = np.asarray(pp.particles["h"])
                    e["progpy PF"].append(np.mean(hp) - X[k, 0])
                    qq = np.quantile(hp, [0.05, 0.95])
                    c["progpy PF"].append(qq[0] <= X[k, 0] <= qq[1])
        for k in acc:
            if e[k]:
                acc[k].append(np.sqrt(np.mean(np.square(e[k]))))
                cov[k].append(np.mean(c[k]))
    for k in acc:
        if acc[k]:
            print(f"{k:10s}: RMSE {1e6 * np.mean(acc[k]):.3f} um, P5-P95 coverage {np.mean(cov[k]):.2f} "
                  f"({a.runs} runs, {na} particles)")
    ok = t_pf < 2.0 and t_rul < 20.0
    print(f"\ntargets: PF step < 2 ms {'met' if t_pf < 2 else 'NOT met'}; RUL < 20 ms {'met' if t_rul < 20 else 'NOT met'}"
          + ("" if pp_err else f"; >= 10x progpy {'met' if t_pp / t_pf * (n / npp) >= 10 else 'NOT met'}"))
    return 0 if ok else 1


if __name__ == "__main__":  # pragma: no cover
    import sys

    sys.exit(main(sys.argv[1:]))
