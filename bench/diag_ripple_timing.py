"""Diagnosis: the phase of a position harmonic on Q_red at speed (issue 10; seed 700 hysteretic-robot kinematic error).

``python bench/diag_ripple_timing.py BAGS_DIR [--order 2] [--truth FAMILY EFFECT SEED]``
(bags as the bench writes them: BAGS_DIR/*.mcap, the last one held out and not used here; e.g.
/tmp/s8/b700/hysteretic-robot/kinematic_error_harmonic/bags).

Part 1 (the logged rows only, what discovery sees): the fit bags' rows with discovery's own signal table
(``hd_ground.discovery.data``: retimed speeds, windup, alpha_f, 5 time blocks per bag). Per block: the motor
speed, the order-k phase advance per log row (k |theta_m[i+1] - theta_m[i]|; pi is the log's Nyquist), and the
best phase and in-block SSE gain of the harmonic on Q_red given a plain baseline (1, windup, windup_dot,
alpha_f), with the harmonic taken as
  row     sin/cos(k theta_m[i])                     (as logged),
  next    sin/cos(k theta_m[i+1])                   (one row later),
  mid     sin/cos(k (theta_m[i] + theta_m[i+1])/2)  (the row's centre),
  mean    the row's mean of sin/cos(k theta) over theta_m[i] -> theta_m[i+1] (a logger averaging torque over
          the period: centre AND sinc attenuation),
  timing  row + its time derivative (k omega cos, -k omega sin): the implied shift tau of the harmonic [ms].
Phase: the ripple written R sin(k theta_m + phi); phi in degrees.

Part 2 (``--truth``, diagnosis only: the simulator, never an input of discovery): re-simulates the first fit
bag's mission exactly as ``bench_discover.make_family_bags`` made it (checked equal to the bag), once more with
the effect off (same seed: the difference is the ripple's whole effect on the true Q_red, dynamics and
hysteresis included) and both again with the hysteresis off. Per block: the phase of that ripple against
theta_m at the same instant (the plant's own lag), and after the bench's acquisition (torque = mean of the
row's sub-samples, angle = its first sub-sample) with the angle as logged and at the row's centre.
Docs: docs/DISCOVERY_PASSES.md, "Diagnosis: the kinematic-error ripple's phase at speed".
"""

import argparse
import glob
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

BLOCKS = 5


def _phase_fit(y, base, cols):
    """In-block least squares of y on base + cols; (coefficients of cols, SSE gain over base alone)."""
    X0 = base
    r0 = y - X0 @ np.linalg.lstsq(X0, y, rcond=None)[0]
    X = np.column_stack([base] + list(cols))
    c = np.linalg.lstsq(X, y, rcond=None)[0]
    r = y - X @ c
    return c[base.shape[1]:], 1.0 - float(r @ r) / max(float(r0 @ r0), 1e-300)


def _phi(a, b):
    """a sin(x) + b cos(x) = R sin(x + phi): phi in degrees, R."""
    return math.degrees(math.atan2(b, a)), math.hypot(a, b)


def _row_mean(th0, th1, k):
    """Mean of sin(k theta), cos(k theta) over theta moving linearly from th0 to th1."""
    d = k * (th1 - th0)
    small = np.abs(d) < 1e-6
    ds = np.where(small, 1.0, d)
    s = np.where(small, np.sin(k * th0), (np.cos(k * th0) - np.cos(k * th1)) / ds)
    c = np.where(small, np.cos(k * th0), (np.sin(k * th1) - np.sin(k * th0)) / ds)
    return s, c


def logged_part(bags, k):
    from hd_bag import read_mission
    from hd_ground.discovery import data

    ms = [read_mission(b) for b in bags]
    lags, _ = data.speed_timing(ms)
    T = float(np.median(np.diff(ms[0].t)))
    print(f"log period {T * 1e3:.3f} ms ({1 / T:.0f} Hz); order {k}; fit bags {len(ms)}; speed lags {lags}")
    print("blk |w_m| mean/p95/max rad/s | adv/row mean/p95/max rad (Nyquist pi) | acq. phase (bench: torque mean of D = 20 sub-samples, angle the first) "
          "(D-1)/(2D)*adv = 0.475*adv mean/p95 deg | sinc(adv/2) p95 | phase deg: row next mid mean | gain %: row next mid mean "
          "timing | tau ms")
    out = []
    K_all = []
    for bi, m in enumerate(ms):
        s, _ = data.signals_of_mission(m, speed_lags=lags)
        n = m.n
        th = s["theta_m"]
        frac = (m.t - m.t[0]) / max(m.t[-1] - m.t[0], 1e-12)
        blk = np.minimum((frac * BLOCKS).astype(int), BLOCKS - 1)
        for j in range(BLOCKS):
            i = np.flatnonzero((blk == j) & (np.arange(n) < n - 1))
            cols = ("Q_red", "windup", "windup_dot", "alpha_f", "omega_m")
            ok = i[np.all([np.isfinite(s[c][i]) for c in cols], axis=0)]
            y = s["Q_red"][ok]
            base = np.column_stack([np.ones(len(ok)), s["windup"][ok], s["windup_dot"][ok], s["alpha_f"][ok]])
            t0, t1 = th[ok], th[ok + 1]
            adv = k * np.abs(t1 - t0)
            w = np.abs(s["omega_m"][ok])
            res = {}
            for name, ang in (("row", t0), ("next", t1), ("mid", 0.5 * (t0 + t1))):
                c, g = _phase_fit(y, base, (np.sin(k * ang), np.cos(k * ang)))
                res[name] = (*_phi(*c), g)
            sm, cm = _row_mean(t0, t1, k)
            c, g = _phase_fit(y, base, (sm, cm))
            res["mean"] = (*_phi(*c), g)
            om = k * (t1 - t0) / T  # the harmonic's angular rate over the row (forward difference)
            sn, cs = np.sin(k * t0), np.cos(k * t0)
            c, g = _phase_fit(y, base, (sn, cs, om * cs, -om * sn))
            a, b, p, q = c
            tau = (a * p + b * q) / max(a * a + b * b, 1e-300)
            res["timing"] = (None, None, g)
            K_all.append(np.linalg.lstsq(base, y, rcond=None)[0][1])
            gid = bi * BLOCKS + j
            moving = np.percentile(adv, 95) > 0.05
            print(f"{gid:3d} {w.mean():6.1f} {np.percentile(w, 95):6.1f} {w.max():6.1f} | {adv.mean():5.2f} "
                  f"{np.percentile(adv, 95):5.2f} {adv.max():5.2f} | {math.degrees(0.475 * adv.mean()):5.1f} "
                  f"{math.degrees(0.475 * np.percentile(adv, 95)):5.1f} | {np.sinc(np.percentile(adv, 95) / 2 / np.pi):4.2f} | "
                  + " ".join(f"{res[v][0]:6.1f}" for v in ("row", "next", "mid", "mean")) + " | "
                  + " ".join(f"{100 * res[v][2]:5.1f}" for v in ("row", "next", "mid", "mean", "timing"))
                  + f" | {tau * 1e3:6.2f}" + ("" if moving else "   (parked: phase meaningless)"))
            out.append(dict(block=gid, res=res, tau=tau, moving=moving))
    return out, float(np.median(K_all)), T


def truth_part(bags, family, effect, seed, k, T, K):
    import bench_discover as B
    from hd_bag import read_mission
    from hd_sim.effects import EffectSet
    from hd_sim.families import family_unit, get_family
    from hd_sim.params import sample_population
    from hd_sim.plant import simulate_mission

    fam = get_family(family)
    unit = family_unit(family, sample_population(1, seed, id_prefix=f"FAM{seed}")[0], EffectSet.preset("baseline"),
                       seed)
    params = B.FAMILY_EFFECTS[effect][0]
    dec = max(B.DECIM, int(math.ceil(B.FS_SIM / float(unit.fs) - 1e-9)))
    fs_sim = dec * float(unit.fs)
    n_sub = max(1, int(round(40000.0 / fs_sim)))
    bag0 = read_mission(bags[0])
    dur = round((bag0.n) / float(unit.fs), 3)

    def sim(on_effect, hyst):
        eff = unit.effects.with_on(effect) if on_effect else unit.effects
        if on_effect and params:
            eff = eff.with_params(**params)
        if not hyst:
            eff = eff.with_off("hysteresis")
        m, tr = simulate_mission(unit.params, eff, fam.profiles[0], 1000 * int(seed), duration=dur, fs=fs_sim,
                                 n_sub=n_sub, mission_index=0, operating_hours=0.0)
        return m, tr

    m1, tr1 = sim(True, True)
    md = B._decimate(m1, dec)
    same = (md.n == bag0.n and np.array_equal(md.Q_red, bag0.Q_red) and np.array_equal(md.theta_m, bag0.theta_m))
    p = tr1["effects"]["params"]
    print(f"\n--truth: re-simulated {bags[0]} at {fs_sim:.0f} Hz, {dec} sub-samples per row "
          f"(identical to the bag: {same}); torque centred {(dec - 1) / 2:.1f} sub-samples = "
          f"{(dec - 1) / 2 / fs_sim * 1e3:.3f} ms after the logged angle ({(dec - 1) / (2 * dec):.3f} of a row); "
          f"KE psi{k} = {math.degrees(p.get(f'psi{k}', 0.0)):.1f} deg (theta_KE = A sin({k} theta_m + psi))")
    print(f"J_CS {p['J_CS']:.3g} J_L {p['J_L']:.3g} K_aero {p['K_aero_mission']:.4g} N*m/rad; "
          f"windup coefficient used for the seen ripple K = {K:.4g} N*m/rad (median of part 1's block baselines)")
    J_m = float(p["J_WG"]) * float(p["N"]) ** 2
    J_o = float(p["J_CS"]) + float(p["J_L"])
    w_r = math.sqrt(K * (1.0 / J_o + 1.0 / J_m) + float(p["K_aero_mission"]) / J_o)
    print(f"two-mass torsional resonance with that K: motor side J_WG N^2 = {J_m:.3g}, output J_CS + J_L = {J_o:.3g} "
          f"kg*m^2 -> {w_r:.0f} rad/s ({w_r / 2 / math.pi:.1f} Hz); the order-{k} ripple is at it for |omega_m| = "
          f"{w_r / k:.0f} rad/s, a phase advance of {w_r * T:.2f} rad per row")
    print("hyst blk | adv/row mean p95 | true ripple dQ at the same instant: phase deg (amp N*m) | dQ - K dwindup same "
          "instant | K dwindup same instant | logged (mean torque, first-sample angle): row mid mean | same, dQ - K dwindup: row mid\n"
          "  (then the whole mission's rows by phase advance per row)")
    for hyst in (True, False):
        a_on = tr1 if hyst else sim(True, False)[1]
        a_off = sim(False, hyst)[1]
        I1, I0 = a_on["internal"], a_off["internal"]
        th = I1["theta_m"]
        dQ = I1["Q_red"] - I0["Q_red"]
        N = float(p["N"])
        dwu = (I1["theta_m"] - I0["theta_m"]) / N - (I1["theta_f"] - I0["theta_f"])
        n = (len(th) // dec) * dec
        rows = n // dec
        blk_row = np.minimum((np.arange(rows) / max(rows - 1, 1) * BLOCKS).astype(int), BLOCKS - 1)
        th_r = th[:n:dec]
        dQ_r = dQ[:n].reshape(-1, dec).mean(1)
        dwu_r = dwu[:n].reshape(-1, dec).mean(1)
        adv_all = k * np.abs(np.diff(th_r))
        groups = [(f"{j:3d}", np.flatnonzero((blk_row == j) & (np.arange(rows) < rows - 1))) for j in range(BLOCKS)]
        groups += [("adv>=1.5", np.flatnonzero(adv_all >= 1.5)),
                   ("0.3<=adv<1.5", np.flatnonzero((adv_all >= 0.3) & (adv_all < 1.5))),
                   ("0.05<adv<0.3", np.flatnonzero((adv_all > 0.05) & (adv_all < 0.3)))]
        for j, r in groups:
            fine = (r[:, None] * dec + np.arange(dec)[None, :]).ravel()
            one = np.ones((len(fine), 1))
            x = th[fine]
            c, _ = _phase_fit(dQ[fine], one, (np.sin(k * x), np.cos(k * x)))
            ph_q, amp_q = _phi(*c)
            c, _ = _phase_fit(dQ[fine] - K * dwu[fine], one, (np.sin(k * x), np.cos(k * x)))
            ph_s, amp_s = _phi(*c)
            c, _ = _phase_fit(K * dwu[fine], one, (np.sin(k * x), np.cos(k * x)))
            ph_w, amp_w = _phi(*c)
            t0, t1 = th_r[r], th_r[r + 1]
            adv = k * np.abs(t1 - t0)
            o = np.ones((len(r), 1))
            mids = 0.5 * (t0 + t1)
            lg = []
            for yv, variants in ((dQ_r[r], ("row", "mid", "mean")), (dQ_r[r] - K * dwu_r[r], ("row", "mid"))):
                for v in variants:
                    ang = t0 if v == "row" else mids
                    cols = _row_mean(t0, t1, k) if v == "mean" else (np.sin(k * ang), np.cos(k * ang))
                    lg.append(_phi(*_phase_fit(yv, o, cols)[0])[0])
            print(f"{'on ' if hyst else 'off'}  {j:>3s} | {adv.mean():5.2f} {np.percentile(adv, 95):5.2f} | "
                  f"{ph_q:7.1f} ({amp_q:7.3g}) | {ph_s:7.1f} ({amp_s:7.3g}) | {ph_w:7.1f} ({amp_w:7.3g}) | "
                  f"{lg[0]:7.1f} {lg[1]:7.1f} {lg[2]:7.1f} | {lg[3]:7.1f} {lg[4]:7.1f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bags")
    ap.add_argument("--order", type=int, default=2)
    ap.add_argument("--truth", nargs=3, metavar=("FAMILY", "EFFECT", "SEED"))
    a = ap.parse_args(argv)
    bags = sorted(glob.glob(str(Path(a.bags) / "*.mcap")))
    if len(bags) < 2:
        raise SystemExit(f"{a.bags}: needs at least 2 .mcap bags (fit + held out), found {len(bags)}")
    fit = bags[:-1]
    _, K, T = logged_part(fit, a.order)
    if a.truth:
        truth_part(fit, a.truth[0], a.truth[1], int(a.truth[2]), a.order, T, K)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
