"""Diagnosis of the smooth-cubic kinematic-error gap of ``hdphm bench discover`` (issue 10, twelfth pass), with the
simulator's truth: the torsion law's choice is bent by the quantised twist (errors in variables).

Diagnosis only (it re-simulates the bench's missions to read the true internal state; nothing here feeds an
estimator). Least squares on the fit missions (0-2), held-out mission 3, Q_red on the twist w with the baseline's
w' and alpha_f columns and the order-2 ripple sin/cos(2 theta_m) (with its |w| and w^2 couplings where said): the
cubic law k3 w^3 against the two-slope law dz(w; j), dz^3 at j = 7e-4 rad, as each logged signal is replaced by
the truth, then the twist read through a smoothed output angle (data.with_smoothed_twist's smoother).

    python bench/bench_discover.py --families smooth-cubic --family-effects kinematic_error_harmonic --no-plant2 \\
        --seed 101 --out /tmp/sc101
    python bench/diag_twist_quantisation.py /tmp/sc101/smooth-cubic/kinematic_error_harmonic/bags --seed 101
"""

from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_discover as bd
    from hd_bag import read_mission
    from hd_ground.discovery.data import dataset_from_missions, with_smoothed_twist
    from hd_sim.effects import EffectSet
    from hd_sim.families import family_unit, get_family
    from hd_sim.params import gear_ratio, sample_population
    from hd_sim.plant import simulate_mission

    ap = argparse.ArgumentParser()
    ap.add_argument("bags")
    ap.add_argument("--seed", type=int, required=True)
    a = ap.parse_args(argv)
    fam = get_family("smooth-cubic")
    unit = family_unit("smooth-cubic", sample_population(1, a.seed, id_prefix=f"FAM{a.seed}")[0],
                       EffectSet.preset("baseline"), a.seed)
    eff = unit.effects.with_on("kinematic_error_harmonic").with_params(**bd.FAMILY_EFFECTS["kinematic_error_harmonic"][0])
    N = gear_ratio(unit.params)
    fs_sim = max(bd.DECIM, int(np.ceil(bd.FS_SIM / float(unit.fs) - 1e-9))) * float(unit.fs)
    S = [simulate_mission(unit.params, eff, fam.profiles[i % len(fam.profiles)], 1000 * a.seed + i, duration=4.0,
                          fs=fs_sim, n_sub=max(1, int(round(40000.0 / fs_sim))), mission_index=i,
                          operating_hours=10.0 * i)[1]["internal"] for i in range(4)]
    bags = sorted(glob.glob(str(Path(a.bags) / "*.mcap")))
    ds = dataset_from_missions([read_mission(b) for b in bags], bags)
    sig, ho = ds.signals, ds.bag == len(bags) - 1
    fit = ~ho

    def truth(f):
        out = np.zeros(ds.n)
        for b in range(len(bags)):
            m = ds.bag == b
            out[m] = np.interp(ds.t[m], S[b]["t"], f(S[b]))
        return out

    w_t = truth(lambda s: s["theta_m"] / N - s["theta_f"])
    q_t, wd_t, af_t, thf_t = truth(lambda s: s["Q_red"]), truth(lambda s: s["omega_m"] / N - s["omega_f"]), \
        truth(lambda s: s["alpha_f"]), truth(lambda s: s["theta_f"])

    def ls(cols, y):
        X = np.stack(cols, 1)
        sc = np.sqrt((X[fit] ** 2).mean(0))
        r = y - X @ (np.linalg.lstsq(X[fit] / sc, y[fit], rcond=None)[0] / sc)
        return np.sqrt(np.mean(r[fit] ** 2)), np.sqrt(np.mean(r[ho] ** 2))

    def laws(w, q, wd, af, couplings):
        sn, cs = np.sin(2 * sig["theta_m"]), np.cos(2 * sig["theta_m"])
        base = [w, wd, af, sn, cs] + ([np.abs(w) * sn, np.abs(w) * cs, w**2 * sn, w**2 * cs] if couplings else [])
        dz = np.sign(w) * np.maximum(np.abs(w) - 7e-4, 0)
        c, d = ls(base + [w**3], q), ls(base + [dz, dz**3], q)
        return (f"cubic fit {c[0]:.2f} held-out {c[1]:.2f} | two-slope fit {d[0]:.2f} held-out {d[1]:.2f} "
                f"(fit MSE two-slope / cubic {d[0] ** 2 / c[0] ** 2:.3f})")

    print(f"smooth-cubic seed {a.seed}: N {N:g}; max |w| per mission (truth) "
          + ", ".join(f"{np.abs(w_t[ds.bag == b]).max():.3g}" for b in range(len(bags))) + " rad")
    print(f"logged - true: theta_f RMS {np.sqrt(np.mean((sig['theta_f'] - thf_t) ** 2)):.3g} rad, twist "
          f"{np.sqrt(np.mean((sig['windup'] - w_t) ** 2)):.3g} rad, Q_red {np.sqrt(np.mean((sig['Q_red'] - q_t) ** 2)):.3g} N*m")
    L = (sig["windup"], sig["Q_red"], sig["windup_dot"], sig["alpha_f"])
    for couplings in (False, True):
        print("ripple couplings |w| sin, w^2 sin " + ("in" if couplings else "out") + " (RMSE N*m):")
        for name, rep in (("logged", {}), ("true w", {0: w_t}), ("true Q_red", {1: q_t}), ("true w', alpha_f", {2: wd_t, 3: af_t}),
                          ("true w, Q_red", {0: w_t, 1: q_t}), ("all true", {0: w_t, 1: q_t, 2: wd_t, 3: af_t})):
            v = [rep.get(i, x) for i, x in enumerate(L)]
            print(f"  {name:17s} {laws(*v, couplings)}")
    print("twist through a smoothed theta_f (quadratic Savitzky-Golay), logged Q_red, couplings in:")
    for win in (5, 9, 17, 33):
        d2 = with_smoothed_twist(ds, win)
        w2 = d2.signals["windup"]
        print(f"  {win:2d} samples: twist error {np.sqrt(np.mean((w2 - w_t) ** 2)):.3g} rad; "
              + laws(w2, sig["Q_red"], sig["windup_dot"], sig["alpha_f"], True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
