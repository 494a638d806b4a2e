"""Diagnosis (reads the simulator's truth; diagnosis only, never discovery): the deadzone-lugre clean tau_m gap.

``python bench/diag_lugre_presliding.py [--seed 1300]``

At seed 1300 the deadzone-lugre clean case reported on tau_m an ``unknown(theta_f)`` term (7.4 % of the held-out
error) and a baseline 2x worse than greedy's (held-out 0.2025 vs 0.119 N*m; docs/DISCOVERY_PASSES.md, ninth
pass). This script shows where the baseline goes wrong, on the bench's own missions (make_family_bags):

1. truth (noise-free internal state at the simulation rate): the simulator's input friction T_fric_in against
   the Dahl state of the true theta_m (hd_twin.identify.presliding_state) at several distances d, with the
   viscous column: the rate-independent pre-sliding law with d = T_C / sigma0 is (almost) exact;
2. logged bags, per bag: the plain baseline [alpha_m, Q_red/N, omega_m, s(theta_m; d)] fitted on that bag alone,
   RMSE against d, with the logged signals and with one logged signal replaced by the truth's block mean
   (alpha_m; Q_red/N; theta_m at the torque's block-mean timing; all): which logged signal moves the best d
   away from T_C / sigma0 (alpha_m: ``dataset_from_missions``' 20 ms window, the default before the eighth pass;
   discover now identifies the window, 10 ms + timing at seed 1300: docs/DISCOVERY_PASSES.md, ninth pass, item 6);
3. pooled (fit: missions 0-2, scored on the held-out mission 3, the bench's split) at d = T_C / sigma0: the
   held-out gain of discover's finding, the cubic in u = theta_f - mean times the state, (p0 + p1 u + p2 u^2 +
   p3 u^3) s, with the logged signals and with the truth's block means put in one after another (alpha_m, then
   Q_red/N, then theta_m at the torque's timing): which acquisition error the theta_f cubic stands in for.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_discover as bd  # noqa: E402

DS = (3e-4, 4.6e-4, 7e-4, 1e-3, 1.4e-3, 2e-3)


def _rmse(cols, y):
    X = np.stack(cols, 1)
    r = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    return float(np.sqrt(np.mean(r**2)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1300)
    ap.add_argument("--out", default=None, help="bag folder (default: a temporary one)")
    a = ap.parse_args(argv)
    import tempfile

    from hd_bag import read_mission
    from hd_ground.discovery.core import Options, choose_speed_timing, standstill_rows
    from hd_ground.discovery.data import dataset_from_missions
    from hd_sim.effects import EffectSet
    from hd_sim.families import family_unit, get_family
    from hd_sim.params import gear_ratio, sample_population
    from hd_sim.plant import simulate_mission
    from hd_twin.identify import presliding_state

    fam = "deadzone-lugre"
    unit = family_unit(fam, sample_population(1, a.seed, id_prefix=f"FAM{a.seed}")[0], EffectSet.preset("baseline"),
                       a.seed)
    N = gear_ratio(unit.params)
    T_C, s0 = unit.effects.p("coulomb_friction", "T_C"), unit.effects.p("lugre_friction", "sigma0")
    print(f"{fam} seed {a.seed}: N {N:g}, T_C {T_C:.3g} N*m, sigma0 {s0:.4g} N*m/rad, sigma1 "
          f"{unit.effects.p('lugre_friction', 'sigma1'):.3g}: T_C / sigma0 = {T_C / s0:.3g} rad")
    out = Path(a.out or tempfile.mkdtemp(prefix="diag_lugre_"))
    bags = bd.make_family_bags(out, fam, None, {}, seed=a.seed)
    ms = [read_mission(b) for b in bags]
    ds = dataset_from_missions(ms, bags)
    ho = ds.bag == len(bags) - 1
    ds = choose_speed_timing(dataset_from_missions(ms, bags, retime_speeds=False), ds, ho)[0]
    still = standstill_rows(ds, Options().standstill_sigmas)[0]
    S = ds.signals
    dec = max(bd.DECIM, int(np.ceil(bd.FS_SIM / float(unit.fs) - 1e-9)))
    fs_sim = dec * float(unit.fs)
    print("d grid (rad):", " ".join(f"{d:.2g}" for d in DS))
    pooled = {k: np.zeros(ds.n) for k in ("alpha_m", "Q_red_over_N", "theta_m")}
    aligned = True
    for i in range(len(bags)):
        prof = get_family(fam).profiles[i % len(get_family(fam).profiles)]
        _, tr = simulate_mission(unit.params, unit.effects, prof, 1000 * a.seed + i, duration=4.0, fs=fs_sim,
                                 n_sub=max(1, int(round(40000.0 / fs_sim))), mission_index=i,
                                 operating_hours=10.0 * i)
        I = tr["internal"]
        print(f"mission {i} ({prof}{', held out' if i == len(bags) - 1 else ''}):")
        print("  1. truth T_fric_in on [s(theta_m; d), omega_m]:",
              " ".join(f"{_rmse([presliding_state(I['theta_m'], d), I['omega_m']], I['T_fric_in']):.3f}" for d in DS))
        n = (len(I["t"]) // dec) * dec
        avg = lambda x: np.asarray(x[:n], float).reshape(-1, dec).mean(1)  # noqa: E731
        m = ds.bag == i
        keep = ~still[m]
        L = {k: S[k][m] for k in ("tau_m", "alpha_m", "Q_red_over_N", "omega_m", "theta_m")}
        seg = ds.segment[m]
        if len(L["tau_m"]) != len(avg(I["t"])):
            print("  (logged rows do not align with the truth's blocks; skipped)")
            aligned = False
            continue
        T = {"alpha_m": avg(I["alpha_m"]), "Q_red_over_N": avg(I["Q_red"]) / N, "theta_m": avg(I["theta_m"])}
        for k in pooled:
            pooled[k][m] = T[k]
        print(f"     rms(J_eq (alpha_m logged - true)) {0.0063 * np.sqrt(np.mean((L['alpha_m'] - T['alpha_m'])**2)):.3f} N*m"
              f", rms(Q_red/N logged - true) {np.sqrt(np.mean((L['Q_red_over_N'] - T['Q_red_over_N'])**2)):.3f} N*m")
        for name, rep in (("logged", {}), ("true alpha_m", {"alpha_m": T["alpha_m"]}),
                          ("true Q_red/N", {"Q_red_over_N": T["Q_red_over_N"]}),
                          ("theta_m at torque timing", {"theta_m": T["theta_m"]}), ("all three true", T)):
            X = dict(L, **rep)
            errs = [_rmse([X["alpha_m"][keep], X["Q_red_over_N"][keep], X["omega_m"][keep],
                           presliding_state(X["theta_m"], d, seg)[keep]], X["tau_m"][keep]) for d in DS]
            print(f"  2. {name:26s}", " ".join(f"{e:.3f}" for e in errs), f" best d {DS[int(np.argmin(errs))]:.2g}")
    if not aligned:
        return 0
    d0 = T_C / s0
    fit, sc = ~ho & ~still, ho & ~still
    u = S["theta_f"] - np.mean(S["theta_f"][fit])
    print(f"3. held-out RMSE (fit on missions 0-2) at d = {d0:.3g}: baseline | + cubic(theta_f) x s | held-out gain")
    X = {k: S[k] for k in ("alpha_m", "Q_red_over_N", "theta_m")}
    for name, key in (("logged", None), ("+ true alpha_m", "alpha_m"), ("+ true Q_red/N", "Q_red_over_N"),
                      ("+ theta_m at torque timing", "theta_m")):
        if key:
            X[key] = pooled[key]
        z = presliding_state(X["theta_m"], d0, ds.segment)
        base = [X["alpha_m"], X["Q_red_over_N"], S["omega_m"], z]
        e = []
        for cols in (base, base + [u * z, u**2 * z, u**3 * z]):
            A = np.stack(cols, 1)
            r = S["tau_m"] - A @ np.linalg.lstsq(A[fit], S["tau_m"][fit], rcond=None)[0]
            e.append(float(np.sqrt(np.mean(r[sc] ** 2))))
        print(f"  {name:28s} {e[0]:.4f} | {e[1]:.4f} | {1 - (e[1] / e[0]) ** 2:.1%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
