"""Diagnosis of two effects that mask each other in discover's forward selection (the twenty-fifth pass's pair step).

Runs discover on a case's fit bags (the last bag held out, as the bench) with the pair step off, keeps the first
selection's block Gram and candidates, and prints for the candidates the last forward step refused after they reached
``min_gain`` alone (inconsistent, between-block levels, unidentified): each alone against the baseline (CV gain,
blocks better, paired t, jackknife Wald against its chi^2 threshold), then every pair of them: the pair against the
baseline and each member given its partner (the tests ``core._pair_tests`` asks). Then discover with the pair step on:
its trace's pair records and the held-out RMSE both ways. Diagnosis only: nothing here feeds an estimator.

    python bench/diag_pair_masking.py CASE_DIR [SIGNAL]      (SIGNAL: Q_red (default) or tau_m)
"""

from __future__ import annotations

import glob
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_discover as B
    from hd_ground.discovery import core
    from hd_ground.discovery.core import Options, _model, _paired_t, _tcols, _wald_threshold

    args = argv if argv is not None else sys.argv[1:]
    case, target = Path(args[0]), (args[1] if len(args) > 1 else "Q_red")
    bags = sorted(glob.glob(str(case / "bags" / "*.mcap")))
    ds, ho = B.discover_dataset(bags)
    cap: dict = {}
    orig = core.select_groups

    def wrap(gram, base_idx, groups, opt, **kw):
        sel, tr = orig(gram, base_idx, groups, opt, **kw)
        if "gram" not in cap:
            cap.update(gram=gram, base=base_idx, groups=groups, trace=tr)
        return sel, tr

    core.select_groups = wrap
    try:
        res0 = core.discover_signal(ds, target, ho, opt=Options(pair_step=False))
    finally:
        core.select_groups = orig
    gram, base, groups, tr = cap["gram"], cap["base"], cap["groups"], cap["trace"]
    lab = {gi: f"{c.name}[{c.family}]" for gi, (c, _) in enumerate(groups)}
    cur = gram.cv_sse(base)
    by_label: dict[str, list[int]] = {}
    for k, v in lab.items():
        by_label.setdefault(v, []).append(k)
    # a label may name several variants of one family (e.g. the loop on the twist, on the quantised twist, tanh of
    # the twist rate): the one the step compared is the family's best alone by CV
    best_of = {v: min(ks, key=lambda g: gram.cv_sse(_model(base, groups, [g])).sum()) for v, ks in by_label.items()}
    refused = list(dict.fromkeys(
        best_of[r["candidate"]] for r in tr
        if r["step"] in ("reject (inconsistent)", "reject (between-block levels)", "reject (unidentified)")
        and r["candidate"] in best_of))

    def stats(ref, idx, g):
        e = gram.cv_sse(idx)
        w = gram.jackknife_wald(idx, _tcols(groups, g))
        return (f"gain {(ref.sum() - e.sum()) / ref.sum():+.3f}, better in {np.mean(e < ref):.0%} of blocks, t "
                f"{_paired_t(ref, e):+.2f}, Wald {w:.1f} / {_wald_threshold(len(_tcols(groups, g)), 3.0):.1f}")

    print(f"{target}: first selection without the pair step: {[t['name'] for t in res0.terms] or 'nothing'}; "
          f"held-out RMSE {res0.error_after.get('rmse', float('nan')):.5g} (baseline "
          f"{res0.error_before.get('rmse', float('nan')):.5g})")
    print("-- refused at the last step, each alone against the baseline (shapes as the step left them):")
    for g in refused:
        print(f"   {lab[g]:50s} {stats(cur, _model(base, groups, [g]), g)}")
    print("-- pairs: the pair against the baseline; each member given its partner")
    for i, a in enumerate(refused):
        for b in refused[i + 1:]:
            if groups[a][0].family == groups[b][0].family:
                continue
            joint = _model(base, groups, [a, b])
            e = gram.cv_sse(joint)
            line = (f"   {lab[a]} + {lab[b]}: gain {(cur.sum() - e.sum()) / cur.sum():+.3f}, better in "
                    f"{np.mean(e < cur):.0%}, t {_paired_t(cur, e):+.2f}")
            for g, o in ((a, b), (b, a)):
                line += f"\n      {lab[g]} given {lab[o]}: {stats(gram.cv_sse(_model(base, groups, [o])), joint, g)}"
            print(line)
    res1 = core.discover_signal(ds, target, ho, opt=Options())
    print(f"with the pair step: {[t['name'] + '(' + str(t['variable']) + ', ' + str(t['order']) + ')' for t in res1.terms]}"
          f"; held-out RMSE {res1.error_after.get('rmse', float('nan')):.5g}")
    for r in res1.cv_trace:
        if "pair_with" in r:
            print(f"   add {r['candidate']} with {r['pair_with']}: gain beside it {r['gain']:+.3f}, better in "
                  f"{r['folds_better']:.0%}, t {r['t']:+.2f}, Wald {r['wald']:.1f}; the pair {r['pair_gain']:+.3f}, "
                  f"better in {r['pair_folds_better']:.0%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
