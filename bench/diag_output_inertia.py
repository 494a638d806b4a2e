"""Diagnosis (reads the simulator's truth; scoring/diagnosis only, never discovery): the Q_red output inertia.

``python bench/diag_output_inertia.py [--seed 1100] [--family default]``

Seed 1100's clean default-world case reported on Q_red a cubic in theta_f explaining 6.8 % of the held-out
residual (docs/DISCOVERY_PASSES.md, seventh pass). This script shows what it was:

1. on the simulator's noise-free internal state of the bench's missions (``/sim/internal`` columns), Q_red
   against [w, w'] (w = theta_m/N - theta_f) and against [w, w', theta_f''] (the output inertia of PHYSICS.md
   r4; the remainder of the acceleration coefficient beyond J_CS is the mesh force's own departure from K w
   under acceleration): RMSE and the coefficient;
2. on the bench's logged bags (fit: the first three, held out: the last), the held-out RMSE of least squares
   on [w, w'], [w, w', alpha_m/N], [w, w', 1, u, u^2, u^3] and both (u = theta_f - its fit mean): whether the
   cubic in theta_f adds anything once the inertia column is there.
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_discover as bd  # noqa: E402


def _ls(cols, y, fit=None, score=None):
    X = np.stack(cols, 1)
    fit = np.ones(len(y), bool) if fit is None else fit
    p = np.linalg.lstsq(X[fit], y[fit], rcond=None)[0]
    r = (y - X @ p)[fit if score is None else score]
    return p, float(np.sqrt(np.mean(r**2)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1100)
    ap.add_argument("--family", default="default")
    a = ap.parse_args(argv)
    from hd_bag import read_mission
    from hd_ground.discovery.data import dataset_from_missions
    from hd_sim.effects import EffectSet
    from hd_sim.families import family_unit, get_family
    from hd_sim.params import gear_ratio, sample_population
    from hd_sim.plant import simulate_mission

    fam = get_family(a.family)
    unit = family_unit(a.family, sample_population(1, a.seed, id_prefix=f"FAM{a.seed}")[0],
                       EffectSet.preset("baseline"), a.seed)
    N = gear_ratio(unit.params)
    print(f"{a.family} seed {a.seed}: N {N:g}, J_CS {unit.params.get('J_CS')}")
    print("1. truth (noise-free internal state): Q_red on [w, w'] | on [w, w', theta_f'']  (RMSE N*m; coef)")
    fs_sim = max(bd.DECIM, int(np.ceil(bd.FS_SIM / float(unit.fs) - 1e-9))) * float(unit.fs)
    for i in range(4):  # the bench's missions (make_family_bags)
        _, tr = simulate_mission(unit.params, unit.effects, fam.profiles[i % len(fam.profiles)], 1000 * a.seed + i,
                                 duration=4.0, fs=fs_sim, n_sub=max(1, int(round(40000.0 / fs_sim))),
                                 mission_index=i, operating_hours=10.0 * i)
        s = tr["internal"]
        w, wd = s["theta_m"] / N - s["theta_f"], s["omega_m"] / N - s["omega_f"]
        _, e0 = _ls([w, wd], s["Q_red"])
        p, e1 = _ls([w, wd, s["alpha_f"]], s["Q_red"])
        print(f"   mission {i}: {e0:.3f} | {e1:.3f}  (coef of theta_f'' {p[2]:+.4f} kg m^2)")
    with tempfile.TemporaryDirectory() as d:
        bags = bd.make_family_bags(Path(d) / "bags", a.family, None, {}, duration=4.0, seed=a.seed)
        ds = dataset_from_missions([read_mission(b) for b in bags], bags)
    s, ho = ds.signals, ds.bag == len(bags) - 1
    y, w, wd, af = s["Q_red"], s["windup"], s["windup_dot"], s["alpha_m"] / ds.gear_ratio
    u = s["theta_f"] - s["theta_f"][~ho].mean()
    one = np.ones_like(u)
    print("2. logged bags, least squares on the fit bags, held-out RMSE (N*m):")
    for name, cols in (("[w, w']", [w, wd]), ("+ alpha_f", [w, wd, af]), ("+ cubic(theta_f)", [w, wd, one, u, u**2, u**3]),
                       ("+ alpha_f + cubic(theta_f)", [w, wd, af, one, u, u**2, u**3])):
        p, e = _ls(cols, y, ~ho, ho)
        extra = f"  alpha_f coef {p[2]:+.4f}" if "alpha_f" in name else ""
        extra += f"  cubic coef {p[-1]:+.1f}" if "cubic" in name else ""
        print(f"   {name:28s} {e:.4f}{extra}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
