"""Cost of the life model's path families: one leave-one-out fold fitted with ``path="power"`` (the baseline) and
``path="auto"`` (power law and crack-growth path, lowest AIC kept), same units, same run; prints CPU and wall
seconds and the ratio auto / power (the criterion for the default of ``hdphm prognostic fit --path``). The
failure-time likelihood is the CLI's default, ``failure_at="auto"`` (both datasets: the recorded crossing).

    hdphm bench lifemodel --extra --virkler DATA/virkler [--nasa DATA/nasa_battery] [--draws 20] [--fold 0]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time


def _fold(name, hi, ev, level, args):
    from hd_prognostic.lifemodel import LifeModel, attach_events, read_events, read_hi_csv

    units = read_hi_csv(hi)
    attach_events(units, read_events(ev), str(ev))
    train = [u for j, u in enumerate(units) if j != args.fold]
    row = {}
    for path in ("power", "auto"):
        c0, t0 = time.process_time(), time.perf_counter()
        m = LifeModel.fit(train, exposure="csv exposure", feature="hi", time_unit="step", n_draws=args.draws,
                          seed=0, threshold="auto", failure_level=level, path=path, failure_at="auto")
        row[path] = (time.process_time() - c0, time.perf_counter() - t0, m.path, m.threshold,
                     m.fit_info["log_likelihood"])
    (cp, wp, *_), (ca, wa, fam, thr, ll) = row["power"], row["auto"]
    print(f"| {name} (fold {args.fold}: {len(train)} units, {sum(len(u.t) for u in train)} records) | "
          f"{cp:.1f} / {wp:.1f} | {ca:.1f} / {wa:.1f} ({fam} {thr} kept) | {ca / cp:.1f}x / {wa / wp:.1f}x |",
          flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench lifemodel", description=__doc__.split("\n")[0])
    ap.add_argument("--virkler", default=None, help="folder with the Virkler CSV files")
    ap.add_argument("--nasa", default=None, help="folder with B0005.csv ... (NASA cells)")
    ap.add_argument("--draws", type=int, default=20, help="posterior parameter draws per fit (the bench's default)")
    ap.add_argument("--fold", type=int, default=0, help="index of the unit left out")
    args = ap.parse_args(argv)
    if not (args.virkler or args.nasa):
        print("bench lifemodel: give --virkler DIR and/or --nasa DIR", file=sys.stderr)
        return 2
    print("| dataset | power: CPU / wall s | auto: CPU / wall s | auto / power: CPU / wall |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        if args.virkler:
            from hd_prognostic.realdata import VIRKLER_LENGTHS_MM, virkler_records

            hi, ev = virkler_records(args.virkler, tmp)
            _fold("Virkler", hi, ev, VIRKLER_LENGTHS_MM[-1] * 1e-3, args)
        if args.nasa:
            from hd_prognostic.realdata import RATED_AH, battery_records

            hi, ev = battery_records(args.nasa, tmp, eol_frac=0.8)
            _fold("NASA", hi, ev, 0.8 * RATED_AH, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
