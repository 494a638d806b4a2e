"""Diagnosis: the within-block levels check of discovery's selection (``core.select_groups``), block by block.

``python bench/diag_within_levels.py WORLD EFFECT BAGS_DIR OUT_DIR``  (bags as the bench writes them:
BAGS_DIR/*.mcap, the last one held out; e.g. /tmp/s8/b700/hysteretic-robot/kinematic_error_harmonic/bags)

Runs the bench's case (``bench_discover.evaluate_world_case``: discover and greedy on the bags) with
``core.within_block_sse`` wrapped, and for every position group the check judged prints: the per-block
leave-one-block-out CV SSE of the current and the trial model, pooled and with a level of the group's factor per
block free, the block's still flag, and the check's statistics: sums (gain, paired t), median block gain, within-block
jackknife Wald and the Hausman statistic (``core.within_block_coefficients``). Docs: docs/DISCOVERY_PASSES.md,
eighteenth pass (seed 700's kinematic error, decided by one fast block).
"""

import argparse
import glob
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_discover as B  # noqa: E402
from hd_ground.discovery import core  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("world")
    ap.add_argument("effect")
    ap.add_argument("bags")
    ap.add_argument("out")
    a = ap.parse_args(argv)
    bags = sorted(glob.glob(str(Path(a.bags) / "*.mcap")))
    if len(bags) < 2:
        raise SystemExit(f"{a.bags}: needs at least 2 .mcap bags (fit + held out), found {len(bags)}")
    names: dict = {}
    seen: set = set()
    orig_sel, orig_w = core.select_groups, core.within_block_sse

    def sel(gram, base_idx, groups, opt, **kw):
        names.clear()
        names.update({j: f"{c.name}[{c.family}]" for c, cols in groups for j in cols})
        return orig_sel(gram, base_idx, groups, opt, **kw)

    def wb(gram, cur_idx, trial_idx, carrier, still=None):
        cw, ew, info = orig_w(gram, cur_idx, trial_idx, carrier, still)
        key = (tuple(cur_idx), tuple(trial_idx))
        if key not in seen:
            seen.add(key)
            pc, pe = gram.cv_sse(list(cur_idx)), gram.cv_sse(list(trial_idx))
            ww, hz, k = core.within_block_coefficients(gram, cur_idx, trial_idx, carrier, still)
            thr = core._wald_threshold(k, core.Options().wald_sigmas) if k else float("inf")
            new = sorted({names.get(j, str(j)) for j in trial_idx if j not in cur_idx})
            print(f"\n{new} given {sorted(set(names.get(j, 'baseline') for j in cur_idx))}")
            print("  block  pooled cur -> trial   within cur -> trial   still")
            for i in range(len(cw)):
                print(f"  {i:5d}  {pc[i]:10.4g} -> {pe[i]:10.4g}  {cw[i]:10.4g} -> {ew[i]:10.4g}  {not info[i]}")
            c, e = cw[info], ew[info]
            print(f"  pooled gain {1 - pe.sum() / pc.sum():+.3f} t {core._paired_t(pc, pe):+.2f} | within gain "
                  f"{1 - e.sum() / max(c.sum(), 1e-300):+.3f} t {core._paired_t(c, e):+.2f} median "
                  f"{np.median(1 - e / np.maximum(c, 1e-300)):+.3f} | Wald {ww:.1f} Hausman {hz:.2f} "
                  f"(threshold {thr:.1f})")
        return cw, ew, info

    core.select_groups, core.within_block_sse = sel, wb
    try:
        exp = (B.FAMILY_EFFECTS[a.effect][1],) if a.effect != "clean" else ()
        r = B.evaluate_world_case(a.world, a.effect, bags, exp, None, Path(a.out),
                                  signals=(["tau_m", "Q_red"] if a.effect == "clean" else None))
    finally:
        core.select_groups, core.within_block_sse = orig_sel, orig_w
    print(json.dumps({k: r.get(k) for k in ("after", "greedy_after", "paired_z", "found", "clean_max_explained")}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
