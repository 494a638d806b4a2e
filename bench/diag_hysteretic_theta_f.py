"""Diagnosis (reads the simulator's truth; scoring/diagnosis only, never discovery): what the Q_red
``unknown(theta_f)`` of the clean hysteretic-robot case stands in for.

``python bench/diag_hysteretic_theta_f.py BAGS_DIR [--seed 1900] [--window 65]``

At seed 1900 the clean hysteretic-robot case reports on Q_red, beside the world's own hysteresis, a cubic in
theta_f explaining 51 % of the held-out baseline residual (contribution 6.3 %, 2.8 paired SE)
(docs/DISCOVERY_PASSES.md, thirteenth pass). This script re-simulates the bench's four missions (the same
calls as ``bench_discover.make_family_bags``), puts the truth on the bags' sample grid (angles sampled at a
block's start, the Bouc-Wen state z_h averaged over the block as Q_red is) and prints, least squares on the
fit bags (0-2), RMSE on the held-out bag (3), each model with and without the cubic in theta_f:

1. the truth alone: Q_red on [w, w', alpha_f, 1] per mission and with z_h (what the torque sensor obeys);
2. the logged twist's error against the true one (per bag), as logged and through the twist smoother;
3. on the logged (or smoothed) twist: the true z_h, a Dahl state of ``windup_q`` (discover's input) and a
   Bouc-Wen state with linear unloading (phi = 0, the world's beta = gamma) at several distances, and of the
   true twist;
4. the held-out residual of the Dahl model and of the true-z_h model by quintile of theta_f (where the
   cubic's gain comes from);
5. the fit blocks' leave-one-block-out CV SSE of the discovered model (Dahl state of windup_q) with and
   without the cubic, per block and bag, and over the blocks in which theta_f moves.
"""

import argparse
import glob
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_discover as bd  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bags", help="folder of the case's bags (the bench's hysteretic-robot/clean/bags)")
    ap.add_argument("--seed", type=int, default=1900)
    ap.add_argument("--family", default="hysteretic-robot")
    ap.add_argument("--window", type=int, default=65, help="twist smoother (samples) for parts 3-5")
    ap.add_argument("--d-h", type=float, default=1.03e-4, help="Dahl distance of part 5 (discover's identified one)")
    a = ap.parse_args(argv)
    from hd_bag import read_mission
    from hd_ground.discovery.data import dataset_from_missions, with_smoothed_twist
    from hd_sim.effects import EffectSet
    from hd_sim.families import family_unit, get_family
    from hd_sim.params import gear_ratio, sample_population
    from hd_sim.plant import simulate_mission
    from hd_twin.identify import hysteresis_state, presliding_state

    bags = sorted(glob.glob(str(Path(a.bags) / "*.mcap")))
    ds0 = dataset_from_missions([read_mission(b) for b in bags], bags)
    fam = get_family(a.family)
    unit = family_unit(a.family, sample_population(1, a.seed, id_prefix=f"FAM{a.seed}")[0],
                       EffectSet.preset("baseline"), a.seed)
    N = gear_ratio(unit.params)
    dec = max(bd.DECIM, int(math.ceil(bd.FS_SIM / float(unit.fs) - 1e-9)))
    fs_sim = dec * float(unit.fs)
    zh, w_t = np.zeros(ds0.n), np.zeros(ds0.n)
    print(f"{a.family} seed {a.seed}: log {unit.fs:g} Hz, N {N:g}, J_L {unit.params.get('J_L'):.3g}, "
          f"K_aero {unit.params.get('K_aero'):.4g}; encoders {unit.effects.p('encoder_quantisation', 'bits_m'):g} / "
          f"{unit.effects.p('encoder_quantisation', 'bits_f'):g} bits (output step "
          f"{2 * np.pi / 2 ** unit.effects.p('encoder_quantisation', 'bits_f'):.3g} rad), sigma_Q "
          f"{unit.effects.p('sensor_noise', 'sigma_Q'):.2f} N*m, loop loss {unit.effects.p('hysteresis', 'loss_arcmin'):.3f} arcmin")
    print("1. truth: Q_red on [w, w', alpha_f, 1] | + z_h (RMSE N*m; the offset)")

    def ls(cols, y):
        X = np.stack(cols, 1)
        p = np.linalg.lstsq(X, y, rcond=None)[0]
        return p, y - X @ p
    for i in range(len(bags)):
        _, tr = simulate_mission(unit.params, unit.effects, fam.profiles[i % len(fam.profiles)], 1000 * a.seed + i,
                                 duration=4.0, fs=fs_sim, n_sub=max(1, int(round(40000.0 / fs_sim))),
                                 mission_index=i, operating_hours=10.0 * i)
        s = tr["internal"]
        w, wd, one = s["theta_m"] / N - s["theta_f"], s["omega_m"] / N - s["omega_f"], np.ones(len(s["theta_m"]))
        p0, r0 = ls([w, wd, s["alpha_f"], one], s["Q_red"])
        p1, r1 = ls([w, wd, s["alpha_f"], s["z_h"], one], s["Q_red"])
        print(f"   mission {i} ({fam.profiles[i % len(fam.profiles)]}): {np.std(r0):.2f} (offset {p0[3]:+.1f}) | "
              f"{np.std(r1):.2f} (z_h coef {p1[3]:+.4f}); z_h {s['z_h'].min():.0f}..{s['z_h'].max():.0f}, "
              f"mean {s['z_h'].mean():.0f}; theta_f {s['theta_f'].min():+.3f}..{s['theta_f'].max():+.3f}")
        rows = np.flatnonzero(ds0.bag == i)
        n = len(rows)
        zh[rows] = s["z_h"][: n * dec].reshape(-1, dec).mean(1)
        w_t[rows] = (s["theta_m"][: n * dec: dec] / N - s["theta_f"][: n * dec: dec])
    ho = ds0.bag == len(bags) - 1
    fit = ~ho
    y = ds0.signals["Q_red"]

    def H(cols):
        X = np.stack(cols, 1)
        p = np.linalg.lstsq(X[fit], y[fit], rcond=None)[0]
        return float(np.sqrt(np.mean((y - X @ p)[ho] ** 2))), y - X @ p

    print("2. twist error (logged - true) RMS per bag, rad:")
    for win in (0, 9, 33, 65, 129):
        d = with_smoothed_twist(ds0, win) if win else ds0
        e = d.signals["windup"] - w_t
        print(f"   {'as logged' if not win else f'{win} samples':10s} " +
              " ".join(f"{np.sqrt(np.mean(e[ds0.bag == b] ** 2)):.2e}" for b in range(len(bags))))
    print(f"3. held-out RMSE (N*m), least squares on the fit bags: model | + cubic(theta_f)")
    for win in (0, a.window):
        ds = with_smoothed_twist(ds0, win) if win else ds0
        s = ds.signals
        w, wd, af, one = s["windup"], s["windup_dot"], s["alpha_m"] / N, np.ones(ds.n)
        u = s["theta_f"] - s["theta_f"][fit].mean()
        cub = [one, u, u**2, u**3]
        print(f"   twist {'as logged' if not win else f'smoothed {win} samples'}:")

        def rep(name, cols):
            print(f"     {name:38s} {H(cols)[0]:7.2f} | {H(cols + cub)[0]:7.2f}")
        rep("[w, w', alpha_f]", [w, wd, af])
        rep("+ true z_h", [w, wd, af, zh])
        rep("true twist + true z_h", [w_t, wd, af, zh])
        for d in (1e-4, 2e-4, 5e-4):
            rep(f"+ Dahl(windup_q, d {d:.0e})", [w, wd, af, presliding_state(s["windup_q"], d, ds.bag)])
            rep(f"+ BW phi 0 (windup_q, d {d:.0e})", [w, wd, af, hysteresis_state(s["windup_q"], d, 1.0, 0.0, ds.bag)])
            rep(f"+ BW phi 0 (true twist, d {d:.0e})", [w, wd, af, hysteresis_state(w_t, d, 1.0, 0.0, ds.bag)])
    print(f"4. residual by theta_f quintile per bag (twist smoothed {a.window} samples; bag {len(bags) - 1} held out)")
    ds = with_smoothed_twist(ds0, a.window)
    s = ds.signals
    w, wd, af = s["windup"], s["windup_dot"], s["alpha_m"] / N
    for name, st in (("Dahl(windup_q, 1e-4)", presliding_state(s["windup_q"], 1e-4, ds.bag)), ("true z_h", zh)):
        r = H([w, wd, af, st])[1]
        print(f"   {name}:")
        for b in range(len(bags)):
            m = ds.bag == b
            th = s["theta_f"][m]
            q = np.quantile(th, np.linspace(0, 1, 6))
            mm = [r[m][(th >= q[k]) & (th <= q[k + 1])].mean() for k in range(5)]
            print(f"     bag {b}: mean {r[m].mean():+7.2f} RMS {np.sqrt(np.mean(r[m] ** 2)):6.2f}; by quintile " +
                  " ".join(f"{v:+7.2f}" for v in mm))
    print(f"5. leave-one-block-out CV SSE on the fit blocks, Dahl(windup_q, d {a.d_h:g}) model | + cubic(theta_f), "
          f"per block (theta_f's span in it)")
    st = presliding_state(s["windup_q"], a.d_h, ds.bag)
    u = s["theta_f"] - s["theta_f"][fit].mean()
    one = np.ones(ds.n)
    res = {}
    for name, cols in (("model", [w, wd, af, st]), ("cubic", [w, wd, af, st, one, u, u**2, u**3])):
        X = np.stack(cols, 1)
        for b in np.unique(ds.block[fit]):
            te = ds.block == b
            tr = fit & ~te
            p = np.linalg.lstsq(X[tr], y[tr], rcond=None)[0]
            res[name, b] = float(np.sum((y - X @ p)[te] ** 2))
    step = float(np.min(np.diff(np.unique(np.round(s["theta_f"], 12)))))
    moving = []
    for b in np.unique(ds.block[fit]):
        te = ds.block == b
        span = float(np.ptp(s["theta_f"][te]))
        moving.append(span > 1.5 * step)
        print(f"   block {b:2d} (bag {ds.bag[te][0]}, span {span:.4f} rad): {res['model', b]:.4g} | {res['cubic', b]:.4g}")
    blocks = np.unique(ds.block[fit])
    for b_ in range(len(bags) - 1):
        bl = [b for b in blocks if ds.bag[ds.block == b][0] == b_]
        print(f"   bag {b_}: {sum(res['model', b] for b in bl):.4g} | {sum(res['cubic', b] for b in bl):.4g}")
    mv = [b for b, m in zip(blocks, moving) if m]
    m0, m1 = sum(res["model", b] for b in mv), sum(res["cubic", b] for b in mv)
    print(f"   blocks where theta_f moves > 1.5 output counts ({len(mv)} of {len(blocks)}): gain {1 - m1 / m0:+.1%}, "
          f"better in {np.mean([res['cubic', b] < res['model', b] for b in mv]):.0%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
