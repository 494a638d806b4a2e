"""``hdphm ground fleet``, ``hdphm fleet status``, ``hdphm fleet query``, ``hdphm fleet train-classifier``."""

from __future__ import annotations

import argparse
import json
import math
import sys


def _fmt(v, spec: str = ".3g") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return format(v, spec) if isinstance(v, (int, float)) else str(v)


def _ground_fleet(args: argparse.Namespace) -> int:
    from hd_ground.fleet.run import run_fleet
    from hd_ground.fleet.tasks import FleetOptions

    onboard = {}
    for kv in args.onboard or ():
        k, sep, v = kv.partition("=")
        try:
            onboard[k.strip()] = float(v)
        except ValueError:
            print(f"hdphm ground fleet: --onboard expects KEY=NUMBER, got {kv!r}", file=sys.stderr)
            return 2
    opts = FleetOptions(healthy_missions=args.healthy_missions, model_dir=args.twin or "", onboard=onboard,
                        obs_model=args.obs_model or "", n_particles=args.particles, classifier=args.classifier or "",
                        seed=args.seed, discover=args.discover)
    s = run_fleet(args.paths, args.store, args.scheduler, opts, progress=not args.quiet, refresh=args.refresh)
    for e in s["errors"]:
        print(f"error: {e}", file=sys.stderr)
    rate = s["missions_stored"] / s["wall_s"] if s["wall_s"] > 0 else float("nan")
    print(f"stored {s['missions_stored']} new mission(s) of {s['actuators']} actuator(s) "
          f"({s['missions_skipped']} already stored) in {s['wall_s']:.1f} s ({rate:.2f} missions/s, "
          f"{s['workers']} worker(s)); store {s['store']}")
    if args.summary:
        with open(args.summary, "w") as f:
            json.dump(s, f, indent=1, default=str)
    return 1 if s["errors"] else 0


def _status(args: argparse.Namespace) -> int:
    from hd_ground.fleet.run import fleet_status

    rows = fleet_status(args.store)
    if args.json:
        print(json.dumps(rows, default=str, indent=1))
        return 0
    print(f"{'actuator':14s} {'missions':>8s} {'last':>5s} {'level':>5s} {'flags':12s} {'h [um]':>7s} "
          f"{'RUL P5':>7s} {'P50':>6s} {'P95':>6s}  suspected fault (p)")
    for r in rows:
        lab = r.get("label")
        p = r.get(f"p_{lab}") if lab else None
        h = r.get("h_mean")
        print(f"{r['actuator_id']:14s} {r['missions']:8d} {_fmt(r['last_mission'], 'd'):>5s} "
              f"{_fmt(r['last_level'], 'd'):>5s} {(r.get('last_flags') or '-')[:12]:12s} "
              f"{_fmt(h * 1e6 if h is not None else None, '.1f'):>7s} {_fmt(r['rul_p5'], '.0f'):>7s} "
              f"{_fmt(r['rul_p50'], '.0f'):>6s} {_fmt(r['rul_p95'], '.0f'):>6s}  "
              f"{lab or '-'}{'' if p is None else f' ({p:.2f})'}")
    return 0


def _query(args: argparse.Namespace) -> int:
    from hd_ground.fleet.store import FleetStore

    st = FleetStore(args.store)
    if not st.root.is_dir():
        raise FileNotFoundError(f"{st.root}: fleet store not found")
    cols, rows = st.query(args.sql)
    if args.format == "json":
        print(json.dumps([dict(zip(cols, r)) for r in rows], default=str, indent=1))
    elif args.format == "csv":
        import csv

        w = csv.writer(sys.stdout)
        w.writerow(cols)
        w.writerows(rows)
    else:
        if cols:
            print("\t".join(cols))
        for r in rows:
            print("\t".join(_fmt(v, ".6g") if isinstance(v, float) else str(v) for v in r))
    return 0


def _train(args: argparse.Namespace) -> int:
    """Train the fault classifier on a store and a labels CSV (actuator_id, mission_index, label)."""
    import csv

    import numpy as np

    from hd_ground.fleet.classify import CLASSES, GaussianFaultClassifier, fit_across_plants, snapshot_features
    from hd_ground.fleet.store import FleetStore

    st = FleetStore(args.store)
    labels: dict[tuple[str, int], str] = {}
    plant_of: dict[str, str] = {}
    with open(args.labels) as f:
        for i, r in enumerate(csv.DictReader(f)):
            if r.get("label") not in CLASSES:
                raise ValueError(f"{args.labels} row {i + 2}: label {r.get('label')!r} not one of {CLASSES}")
            labels[(r["actuator_id"], int(r["mission_index"]))] = r["label"]
            pl = (r.get("plant") or "").strip()
            if plant_of.setdefault(r["actuator_id"], pl) != pl:
                raise ValueError(f"{args.labels} row {i + 2}: {r['actuator_id']} is plant {pl!r} here and "
                                 f"{plant_of[r['actuator_id']]!r} above (one plant type per actuator)")
    X, y, g = [], [], []
    for aid in sorted({a for a, _ in labels}):
        stats, feats = st.read_mission_rows(aid, "residual_stats"), st.read_mission_rows(aid, "features")
        for (a, k), lab in labels.items():
            if a != aid:
                continue
            x = snapshot_features(stats, feats, k, args.healthy_missions)
            if x is not None:
                X.append(x)
                y.append(lab)
                g.append(plant_of.get(aid, ""))
    if not X:
        raise ValueError(f"{args.labels}: no labelled mission after the reference missions is in {st.root}")
    plants = sorted(set(g) - {""})
    if plants and "" in g:
        raise ValueError(f"{args.labels}: the plant column is empty for some actuators; give every actuator its "
                         "plant type or none")
    if len(plants) >= 2:  # several plant types: choose the structure that transfers to one left out
        m = fit_across_plants(np.array(X), y, g)
        how = f"covariance {m.covariance} by leave-one-plant-out over {', '.join(plants)}"
    else:
        m = GaussianFaultClassifier().fit(np.array(X), y)
        how = "one plant type: pooled covariance (give a plant column with >= 2 types to choose it)"
    m.save(args.out)
    print(f"wrote {args.out}: {len(X)} training snapshots, classes {m.counts}; {how}")
    return 0


def register(subparsers) -> None:
    g = subparsers.add_parser("ground", help="ground-segment analytics over many missions (fleet on Dask)")
    gs = g.add_subparsers(dest="ground_command", metavar="GROUNDCOMMAND")
    g.set_defaults(func=lambda a: (g.print_help(), 2)[1])
    p = gs.add_parser("fleet", help="analyse mission bags on Dask into a Parquet + DuckDB fleet store",
                      description="Per mission: onboard features and observation, twin residual statistics, monitor "
                                  "outputs, recalibration inputs; per actuator: ground calibration (recalibration, "
                                  "adaptive thresholds, monitor references), RUL update, fault classes. Runs on an "
                                  "embedded Dask LocalCluster or on a running scheduler; a rerun skips stored missions. "
                                  "See docs/FLEET.md.")
    p.add_argument("paths", nargs="+", metavar="PATH_OR_GLOB", help="bags, directories of bags, or glob patterns")
    p.add_argument("--store", required=True, help="fleet store directory (created if absent)")
    p.add_argument("--scheduler", default="local", help="local (default: one worker per core), local:N, or tcp://HOST:PORT")
    p.add_argument("--healthy-missions", type=int, default=3, help="first missions of each actuator taken as its reference")
    p.add_argument("--twin", default=None, metavar="MODEL_DIR", help="twin the onboard node runs (default: physics stand-in)")
    p.add_argument("--onboard", action="append", metavar="KEY=VALUE", help="onboard configuration override (repeatable)")
    p.add_argument("--obs-model", default=None, help="prognostic observation model JSON (default: the package's)")
    p.add_argument("--classifier", default=None, help="fault classifier JSON (default: the package's)")
    p.add_argument("--particles", type=int, default=500, help="particles of the RUL filter (default 500)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--discover", action="store_true",
                   help="also run discovery (hdphm discover) once per actuator type (gear ratio) on the first "
                        "reference mission of up to 4 of its actuators; ~10 s per type; stored under STORE/discovery")
    p.add_argument("--summary", default=None, metavar="JSON", help="write the run summary here")
    p.add_argument("--refresh", action="store_true",
                   help="recompute every actuator's RUL and fault classes (after changing --classifier / --obs-model)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_ground_fleet)

    f = subparsers.add_parser("fleet", help="read the fleet store: status per actuator, SQL queries, train the classifier")
    fs = f.add_subparsers(dest="fleet_command", metavar="FLEETCOMMAND")
    f.set_defaults(func=lambda a: (f.print_help(), 2)[1])
    s = fs.add_parser("status", help="one line per actuator: missions, last flags, health, RUL P5/P50/P95, suspected fault")
    s.add_argument("--store", required=True)
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_status)
    q = fs.add_parser("query", help="run SQL (DuckDB) over the store's tables: missions, features, residual_stats, "
                                    "events, rul, classification, calibration")
    q.add_argument("--store", required=True)
    q.add_argument("sql")
    q.add_argument("--format", choices=("tsv", "csv", "json"), default="tsv")
    q.set_defaults(func=_query)
    t = fs.add_parser("train-classifier", help="fit the fault classifier on a store and labels (CSV: actuator_id, "
                                               "mission_index, label[, plant])",
                      description="Labels CSV: actuator_id, mission_index, label (healthy, tooth_wear, "
                                  "lubrication_loss, flexspline_stiffness_loss) and optionally plant (the actuator's "
                                  "plant type): with >= 2 plant types the class densities' covariance structure (pooled, "
                                  "per class, diagonal) is chosen by leave-one-plant-out cross-validation.")
    t.add_argument("--store", required=True)
    t.add_argument("--labels", required=True)
    t.add_argument("--out", required=True)
    t.add_argument("--healthy-missions", type=int, default=3)
    t.set_defaults(func=_train)
