"""Diagnosis of a group that gains on the fit blocks' CV but fails the jackknife Wald rule while one block carries
much of its information (issue 10, disc30's pass; seed 3700 smooth-cubic kinematic error: the cubic torsion law w^3
gains 44 % of the CV error, jackknife Wald 8.35 against 9).

Two parts, diagnosis only (nothing here feeds an estimator):

``python bench/diag_block_leverage.py CASE_DIR [--twist W] [--test w3|keK|pdsK|ksK] [--model ke2,...]``
    Rebuilds the model (baseline K w + c w' + alpha_f, the ``--model`` groups, default ke2, and the tested group,
    default w3; keK: sin/cos K theta_m, pdsK: w times them, ksK: w^2 times them, the library's ``:stiff`` variant) on
    the case's fit blocks with theta_f smoothed over W samples (discover's window, default 17) and prints, per block:
    its bag, its share of the tested coefficient's partial information (the first column of the group), the largest
    eigenvalue of its hat matrix H_bb, q99 |w|, the coefficient estimated from that block alone with the others pooled
    (FWL), the same with every coefficient the block's own, the leave-one-block-out estimate and the block's CV SSE;
    then the group's identification by each test: jackknife Wald (discover's rule,
    ``core._BlockGram.jackknife_wald``), cluster sandwich CR0 / CR1, the leverage-corrected CR2 (Bell & McCaffrey
    2002) with its Bell-McCaffrey degrees of freedom and their 3-sigma t^2 quantile (one tested column), CR3 (the
    jackknife's linearisation), the restricted-score block sign-flip test (wild-cluster-restricted in randomization
    form) and the block sign-flip test on the blocks' own estimates (Canay, Romano & Shaikh 2017: exact under
    independent blocks with symmetric estimates).

``python bench/diag_block_leverage.py --synthetic [N]``
    Monte Carlo of the same tests on a synthetic Q_red-like plant with a known answer (15 blocks, y = 3 w + k3 w^3 +
    a ripple + per-block coloured disturbances + noise; one block's load ``lev`` times the others'): the share of N
    seeds (default 1000 under the null k3 = 0, N / 10 at k3 = 0.3) each test admits w^3 at the 3-sigma level, for
    lev 1.0 (balanced), 1.6 and 2.2 (one high-leverage block). Under the null this is each rule's false-admission
    rate (nominal 0.27 %); at k3 = 0.3 its power. About 5 min per 1000 seeds on one loaded core.
"""

from __future__ import annotations

import glob
import sys
from pathlib import Path

import numpy as np
from scipy.stats import chi2, norm
from scipy.stats import t as tdist

ALPHA = 2.0 * norm.sf(3.0)  # the 3-sigma level of discover's Wald rule


def _sub(g, idx):
    ix = np.asarray(idx)
    return g.G[:, ix][:, :, ix], g.g[:, ix]


def sandwich(g, idx, cols):
    """(CR0 Wald, CR2 Wald, CR3 Wald, Bell-McCaffrey df of the first tested coefficient, per-block info share).

    Per block b (X_b = U S V' from the block's Gram matrix alone): e_b the full fit's residuals, H_bb = X_b M X_b'
    (M = (X'X)^-1); CR_p uses M X_b' (I - H_bb)^-p/2 e_b, p = 0, 1, 2 (CR3 = the jackknife's linearisation). The
    Bell-McCaffrey df (working model: independent homoskedastic rows) for the contrast c: the eigenvalues of the
    blocks' G'G, (G'G)_bb = c'M X_b'X_b M c, (G'G)_bd = -(X_b'A_bX_b M c)' M (X_d'A_dX_d M c)."""
    G, gv = _sub(g, idx)
    pos = [list(idx).index(c) for c in cols]
    Gt, gt = G.sum(0), gv.sum(0)
    M = np.linalg.inv(Gt + 1e-9 * np.trace(Gt) / len(idx) * np.eye(len(idx)))
    beta = M @ gt
    c = np.zeros(len(idx))
    c[pos[0]] = 1.0
    Mc = M @ c
    infl = {0: [], 1: [], 2: []}
    q, dg = [], []
    for Gb, gb in zip(G, gv):
        xe = gb - Gb @ beta
        lam2, V = np.linalg.eigh(Gb)
        keep = lam2 > 1e-12 * max(float(lam2.max()), 1e-300)
        V, sv = V[:, keep], np.sqrt(lam2[keep])
        ue = (V.T @ xe) / sv
        lk, W = np.linalg.eigh((sv[:, None] * (V.T @ M @ V)) * sv[None, :])
        for pw in (0, 1, 2):
            a = np.clip(1.0 - lk, 1e-9, None) ** (-pw / 2.0)
            infl[pw].append(M @ (V @ (sv * (W @ (a * (W.T @ ue))))))
        a2 = np.clip(1.0 - lk, 1e-9, None) ** -0.5
        XAX = V @ np.diag(sv) @ W @ np.diag(a2) @ W.T @ np.diag(sv) @ V.T
        q.append(XAX @ Mc)
        dg.append(float(Mc @ Gb @ Mc))
    q = np.array(q)
    GG = -q @ M @ q.T
    np.fill_diagonal(GG, dg)
    ev = np.linalg.eigvalsh(GG)
    nu = float(ev.sum() ** 2 / (ev**2).sum())
    b = beta[pos]

    def wald(pw):
        U = np.array(infl[pw])[:, pos]
        return float(b @ np.linalg.solve(U.T @ U, b))
    return wald(0), wald(1), wald(2), nu, np.array(dg) / sum(dg)


def restricted_signflip_p(g, idx, cols):
    """Block sign-flip score test with the null model's residuals: s_b = Z_b' e~_b (Z the group's columns with the
    others projected out over all blocks), T = S' (sum s_b s_b')^-1 S over all 2^n sign vectors. Not exact: the null
    fit's error, dominated by a high-leverage block, enters every block's score alike."""
    G, gv = _sub(g, idx)
    t = [list(idx).index(c) for c in cols]
    o = [i for i in range(len(idx)) if i not in t]
    Gt, gt = G.sum(0), gv.sum(0)
    bo = np.linalg.solve(Gt[np.ix_(o, o)], gt[o])
    Gam = np.linalg.solve(Gt[np.ix_(o, o)], Gt[np.ix_(o, t)])
    xe = gv - np.einsum("bij,j->bi", G[:, :, o], bo)
    return _signflip(xe[:, t] - xe[:, o] @ Gam)


def own_estimates(g, idx, cols):
    """Each block's own least-squares estimate of the group (every coefficient the block's own); blocks whose Gram
    matrix is singular (the model not identified within them) are left out. Rows: blocks kept."""
    G, gv = _sub(g, idx)
    t = [list(idx).index(c) for c in cols]
    out = []
    for Gb, gb in zip(G, gv):
        ev = np.linalg.eigvalsh(Gb)
        if ev.min() > 1e-9 * ev.max():
            out.append(np.linalg.solve(Gb, gb)[t] / g.scale[np.asarray(idx)[t]])
    return np.array(out)


def _signflip(s):
    """p of T = S' (sum s_b s_b')^-1 S (S = sum s_b) over all 2^n sign flips of the rows of ``s`` (exact when the
    rows are independent and symmetric about zero)."""
    nb = s.shape[0]
    Vi = np.linalg.inv(s.T @ s)
    S = s.sum(0)
    T = float(S @ Vi @ S)
    E = 1.0 - 2.0 * ((np.arange(1 << nb)[:, None] >> np.arange(nb)[None, :]) & 1)
    SE = E @ s
    return float(np.mean(np.einsum("ij,jk,ik->i", SE, Vi, SE) >= T * (1.0 - 1e-9)))


def tests(g, idx, cols):
    """Every test's statistic on the group ``cols`` of the model ``idx`` (a dict)."""
    k = len(cols)
    cr0, cr2, cr3, nu, share = sandwich(g, idx, cols)
    nb = g.G.shape[0]
    return {"jackknife": g.jackknife_wald(list(idx), list(cols)), "chi2_threshold": float(chi2.isf(ALPHA, k)),
            "CR0": cr0, "CR1": cr0 * (nb - 1) / nb, "CR2": cr2, "CR3": cr3, "bm_df": nu,
            "bm_threshold": float(tdist.isf(ALPHA / 2, nu) ** 2) if k == 1 else float("nan"),
            "restricted_signflip_p": restricted_signflip_p(g, idx, cols),
            "own_signflip_p": _signflip(own_estimates(g, idx, cols)), "share": share}


def case_main(args: list[str]) -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_discover as B
    from hd_ground.discovery.core import _BlockGram
    from hd_ground.discovery.data import with_smoothed_twist

    def opt(name, default):
        if name in args:
            i = args.index(name)
            v = args[i + 1]
            del args[i:i + 2]
            return v
        return default
    tw = int(opt("--twist", "17"))
    test = opt("--test", "w3")
    model = [m for m in opt("--model", "ke2").split(",") if m]
    case = Path(args[0])
    ds0, ho = B.discover_dataset(sorted(glob.glob(str(case / "bags" / "*.mcap"))))
    ds = with_smoothed_twist(ds0, tw) if tw else ds0
    sig, fit, blk = ds.signals, ~ho, ds.block
    w, th = sig["windup"], sig["theta_m"]

    def group(name):
        if name == "w3":
            return [w**3]
        k = int(name.lstrip("kepds"))
        s2 = [np.sin(k * th), np.cos(k * th)]
        if name.startswith("ks"):  # the ripple through the torsion law's local stiffness (library's ":stiff")
            return [c * w**2 for c in s2]
        return s2 if name.startswith("ke") else [c * w for c in s2]
    cols = [w, sig["windup_dot"], sig["alpha_f"]] + [c for m in model for c in group(m)]
    tcols = list(range(len(cols), len(cols) + len(group(test))))
    X = np.column_stack(cols + group(test))
    Xf, yf, bf = X[fit], sig["Q_red"][fit], blk[fit]
    g = _BlockGram(Xf, yf, bf)
    idx = list(range(X.shape[1]))
    r = tests(g, idx, tcols)
    others = [j for j in idx if j not in tcols]
    Zo = Xf[:, others]
    xr = Xf[:, tcols[0]] - Zo @ np.linalg.lstsq(Zo, Xf[:, tcols[0]], rcond=None)[0]
    yr = yf - Zo @ np.linalg.lstsq(Zo, yf, rcond=None)[0]
    own = own_estimates(g, idx, tcols[:1])[:, 0]
    full = np.linalg.lstsq(Xf, yf, rcond=None)[0][tcols[0]]
    cv = g.cv_sse(idx)
    print(f"case {case}: twist window {tw}, model baseline + {model} + tested {test}; fit rows {fit.sum()} in "
          f"{len(g.blocks)} blocks; tested coefficient (first column) on all fit blocks {full:.4g}")
    print(f"{'block':>5} {'bag':>3} {'info %':>7} {'max h_bb':>8} {'q99|w|':>9} {'FWL own':>10} {'all own':>10} "
          f"{'leave out':>10} {'CV SSE':>10}")
    for i, b in enumerate(g.blocks):
        m = bf == b
        keep = ~m
        loo = np.linalg.lstsq(Xf[keep], yf[keep], rcond=None)[0][tcols[0]]
        Xs = g._Xs  # the gram's scaled columns (the hat matrix does not depend on the scale)
        hmax = float(np.linalg.svd(Xs[m] @ np.linalg.cholesky(np.linalg.inv(Xs.T @ Xs)), compute_uv=False)[0] ** 2)
        print(f"{int(b):5d} {int(ds.bag[blk == b][0]):3d} {r['share'][i] * 100:7.1f} {hmax:8.3f} "
              f"{np.quantile(np.abs(w[fit][m]), 0.99):9.2e} {(xr[m] @ yr[m]) / (xr[m] @ xr[m]):10.3e} "
              f"{own[i] if len(own) == len(g.blocks) else float('nan'):10.3e} {loo:10.3e} {cv[i]:10.4g}")
    print(f"Wald against zero (3 sigma: chi^2({len(tcols)}) quantile {r['chi2_threshold']:.2f}): jackknife "
          f"{r['jackknife']:.2f}; CR0 {r['CR0']:.2f}, CR1 {r['CR1']:.2f}, CR2 {r['CR2']:.2f}, CR3 {r['CR3']:.2f}")
    if len(tcols) == 1:
        print(f"CR2's Bell-McCaffrey df {r['bm_df']:.2f}: its 3-sigma t^2 quantile {r['bm_threshold']:.2f} (balanced "
              f"blocks, df {len(g.blocks) - 1}: {tdist.isf(ALPHA / 2, len(g.blocks) - 1) ** 2:.2f})")
    print(f"block sign-flip p (3 sigma: {ALPHA:.4f}): restricted scores {r['restricted_signflip_p']:.3g}, the blocks' "
          f"own estimates {r['own_signflip_p']:.3g}")
    return 0


def synthetic_case(seed: int, k3: float, lev: float, nb: int = 15, per: int = 800):
    """(X, y, block) of the synthetic plant; columns w, sin 2 theta, cos 2 theta, w^3 (the tested one)."""
    rng = np.random.default_rng(seed)
    block = np.repeat(np.arange(nb), per)
    t = np.tile(np.linspace(0, 1, per), nb)
    th = 2 * np.pi * (3 + block % 4) * t + rng.uniform(0, 6.3, nb)[block]
    load = rng.uniform(0.6, 1.0, nb)
    load[-1] = lev
    w = load[block] * np.sin(2 * np.pi * (1 + 0.2 * (block % 3)) * t + block) + 0.05 * np.sin(2 * np.pi * 9 * t)
    y = (3.0 * w + k3 * w**3 + 0.5 * np.sin(2 * th + 0.4) + 0.1 * rng.normal(size=len(t))
         + 0.3 * rng.normal(size=nb)[block] * np.sin(2 * np.pi * rng.uniform(0.5, 3, nb)[block] * t
                                                     + rng.uniform(0, 6.3, nb)[block]))
    return np.column_stack([w, np.sin(2 * th), np.cos(2 * th), w**3]), y, block


def synthetic_main(n: int) -> int:
    from hd_ground.discovery.core import _BlockGram

    names = ["jackknife", "CR2 chi^2", "CR2 Bell-McCaffrey", "restricted sign-flip", "own sign-flip",
             "jackknife or (CR2 chi^2 and restricted sign-flip)"]
    print(f"share of seeds admitting w^3 at 3 sigma (nominal {ALPHA:.4f}); 15 blocks, block 14's load lev x")
    print(f"{'k3':>4} {'lev':>4} {'seeds':>5} " + " ".join(f"{h:>14.14s}" for h in names))
    for k3, m in ((0.0, n), (0.3, max(n // 10, 10))):
        for lev in (1.0, 1.6, 2.2):
            hits = np.zeros(len(names))
            for seed in range(m):
                X, y, b = synthetic_case(seed, k3, lev)
                r = tests(_BlockGram(X, y, b), [0, 1, 2, 3], [3])
                j = r["jackknife"] >= r["chi2_threshold"]
                c2 = r["CR2"] >= r["chi2_threshold"]
                rs = r["restricted_signflip_p"] <= ALPHA
                hits += [j, c2, r["CR2"] >= r["bm_threshold"], rs, r["own_signflip_p"] <= ALPHA, j or (c2 and rs)]
            print(f"{k3:4.1f} {lev:4.1f} {m:5d} " + " ".join(f"{h / m:14.4f}" for h in hits))
    return 0


def main(argv: list[str] | None = None) -> int:
    args = list(argv if argv is not None else sys.argv[1:])
    if args and args[0] == "--synthetic":
        return synthetic_main(int(args[1]) if len(args) > 1 else 1000)
    return case_main(args)


if __name__ == "__main__":
    raise SystemExit(main())
