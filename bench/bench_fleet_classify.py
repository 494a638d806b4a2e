"""Fault classification across missions on held-out units of three plant families (``hdphm bench fleet_classify``).

1. Simulates (once; cached under ``--root``, default ``bags/fleet_classify``) a training fleet of the default
   plant A (24 units, seed 11) and held-out fleets (9 units each) of A (seed 21), of two local variants B
   and C of it (seeds 22, 23) and of the three structurally different ``hd_sim.families`` smooth-cubic,
   deadzone-lugre (500 Hz, N 50/80) and hysteretic-robot (N 160, 200 Hz-2 kHz, stamp jitter) (seeds
   31-33): 3 s missions, faults (lubrication loss, flexspline stiffness loss) injected mid-life, tooth
   wear in all (``bench/fleet_sim.py``).
2. Runs the fleet analysis (``hd_ground.fleet.run.run_fleet``, the code of ``hdphm ground fleet``) on each
   into its own store (onboard warm-up 1 s: the missions are 3 s).
3. Labels every mission after the reference from the simulator's truth (scoring only): the injected fault
   once its severity reaches ``--min-severity`` (0.15), else tooth wear when the wear reached half of
   h_fail, healthy below 0.3 h_fail; the band in between is not scored.
4. Trains :class:`hd_ground.fleet.classify.GaussianFaultClassifier` on the training fleet only and scores it on
   the held-out units, with the nearest-centroid baseline in the same run. Prints the confusion matrices
   (markdown), accuracy and macro recall per family.
5. Leave one plant out (:func:`across_plants`): per plant, the classifier trained on every other plant's fleets,
   its covariance structure chosen by leave-one-plant-out among those plants only, scored on the plant's
   held-out fleet beside the nearest-centroid baseline trained on the same rows.
6. Writes the classifier fitted on every fleet of the six plants (covariance by leave-one-plant-out over all six;
   ``--out``, default ``ROOT/classifier.json``): the package default (``default_classifier.json``) is this file.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

FLEETS = (("train_A", "A", 11, 24), ("test_A", "A", 21, 9), ("test_B", "B", 22, 9), ("test_C", "C", 23, 9),
          ("test_smooth-cubic", "smooth-cubic", 31, 9), ("test_deadzone-lugre", "deadzone-lugre", 32, 9),
          ("test_hysteretic-robot", "hysteretic-robot", 33, 9))


def labels_from_truth(truth: dict, min_severity: float = 0.15, wear_hi: float = 0.5, wear_lo: float = 0.3):
    out = {}
    for a in truth["actuators"]:
        fault = a["plan"]["fault"]
        key = {"lubrication_loss": "lube_loss", "flexspline_stiffness_loss": "fs_loss"}.get(fault)
        hf = a["h_fail"]
        for r in a["missions"]:
            k = int(r["mission_index"])
            if key and r.get(key, 0.0) >= min_severity:
                out[(a["actuator_id"], k)] = fault
            elif key and r.get(key, 0.0) > 0:
                continue  # fault present but below the scoring severity
            elif r["h"] >= wear_hi * hf:
                out[(a["actuator_id"], k)] = "tooth_wear"
            elif r["h"] < wear_lo * hf:
                out[(a["actuator_id"], k)] = "healthy"
    return out


def snapshots(store_dir, labels, healthy_missions):
    from hd_ground.fleet.classify import snapshot_features
    from hd_ground.fleet.store import FleetStore

    st = FleetStore(store_dir)
    X, y, who = [], [], []
    for aid in sorted({a for a, _ in labels}):
        stats, feats = st.read_mission_rows(aid, "residual_stats"), st.read_mission_rows(aid, "features")
        for (a, k), lab in sorted(labels.items()):
            if a != aid:
                continue
            x = snapshot_features(stats, feats, k, healthy_missions)
            if x is not None:
                X.append(x)
                y.append(lab)
                who.append((a, k))
    return np.array(X), y, who


def confusion_md(y_true, y_pred, title):
    from hd_ground.fleet.classify import CLASSES, LABELS

    short = {"healthy": "healthy", "tooth_wear": "wear", "lubrication_loss": "lube", "flexspline_stiffness_loss": "flexspline",
             "unknown": "unknown"}
    M = np.zeros((len(CLASSES), len(LABELS)), int)
    for t, p in zip(y_true, y_pred):
        M[CLASSES.index(t), LABELS.index(p)] += 1
    lines = [f"{title}", "", "| true \\ predicted | " + " | ".join(short[c] for c in LABELS) + " | recall |",
             "|---" * (len(LABELS) + 2) + "|"]
    rec = []
    for i, c in enumerate(CLASSES):
        n = M[i].sum()
        r = M[i, i] / n if n else float("nan")
        if n:
            rec.append(r)
        lines.append(f"| {short[c]} | " + " | ".join(str(v) for v in M[i]) + f" | {r:.2f} |" if n else
                     f"| {short[c]} | " + " | ".join(str(v) for v in M[i]) + " | - |")
    acc = float(np.trace(M[:, : len(CLASSES)]) / max(M.sum(), 1))
    return "\n".join(lines), acc, float(np.mean(rec)) if rec else float("nan")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="hdphm bench fleet_classify")
    ap.add_argument("--root", default="bags/fleet_classify")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=None, help="write the trained classifier JSON here (default ROOT/classifier.json)")
    ap.add_argument("--min-severity", type=float, default=0.15)
    ap.add_argument("--healthy-missions", type=int, default=3)
    a = ap.parse_args(argv)
    from distributed import Client, LocalCluster

    from fleet_sim import simulate_fault_fleet
    from hd_ground.fleet.classify import GaussianFaultClassifier, NearestCentroid
    from hd_ground.fleet.run import run_fleet
    from hd_ground.fleet.tasks import FleetOptions

    root = Path(a.root)
    t0 = time.perf_counter()
    truths = {}
    for name, fam, seed, n in FLEETS:
        truths[name] = simulate_fault_fleet(root / name, fam, n, seed=seed, workers=a.workers)
    print(f"fleets ready ({time.perf_counter() - t0:.0f} s)", flush=True)
    # the stores' own classification columns use the package default classifier (if any); scored below is
    # the one trained here on train_A only
    opts = FleetOptions(healthy_missions=a.healthy_missions, onboard={"warmup_s": 1.0}, n_particles=200)
    with LocalCluster(n_workers=a.workers, threads_per_worker=1, dashboard_address=":0", silence_logs=50) as cl, \
            Client(cl) as client:
        for name, *_ in FLEETS:
            s = run_fleet([str(root / name)], str(root / f"store_{name}"), opts=opts, progress=False, client=client,
                          log=lambda s: None)
            print(f"{name}: {s['missions_stored']} new missions stored, {s['missions_skipped']} already, "
                  f"{s['wall_s']:.0f} s, errors {len(s['errors'])}", flush=True)
    data = {}
    for name, *_ in FLEETS:
        lab = labels_from_truth(truths[name], a.min_severity)
        data[name] = snapshots(root / f"store_{name}", lab, a.healthy_missions)
    Xtr, ytr, _ = data["train_A"]
    qda = GaussianFaultClassifier().fit(Xtr, ytr)  # pooled covariance (LDA); see classify.py
    nc = NearestCentroid().fit(Xtr, ytr)
    print(f"trained on {len(ytr)} snapshots of train_A ({qda.counts})")
    summary = {}
    for name, *_ in FLEETS[1:]:
        X, y, _ = data[name]
        for mname, m in (("gaussian", qda), ("nearest_centroid", nc)):
            md, acc, mrec = confusion_md(y, m.predict(X), f"**{name}** ({mname}, {len(y)} snapshots)")
            summary[(name, mname)] = (acc, mrec)
            print()
            print(md)
            print(f"\naccuracy {acc:.2f}, macro recall {mrec:.2f}")
    Xall = np.concatenate([data[n][0] for n, *_ in FLEETS[1:]])
    yall = sum((data[n][1] for n, *_ in FLEETS[1:]), [])
    for mname, m in (("gaussian", qda), ("nearest_centroid", nc)):
        md, acc, mrec = confusion_md(yall, m.predict(Xall), f"**all held-out units, all families** ({mname}, {len(yall)} snapshots)")
        print()
        print(md)
        print(f"\naccuracy {acc:.2f}, macro recall {mrec:.2f}")
    print("\n| held-out fleet | gaussian acc / macro recall | nearest-centroid acc / macro recall |\n|---|---|---|")
    for name, *_ in FLEETS[1:]:
        g, b = summary[(name, "gaussian")], summary[(name, "nearest_centroid")]
        print(f"| {name} | {g[0]:.2f} / {g[1]:.2f} | {b[0]:.2f} / {b[1]:.2f} |")
    # recall of the faults by severity at the snapshot (how early a fault is recognised)
    sev = {}
    for name, *_ in FLEETS[1:]:
        for a_ in truths[name]["actuators"]:
            key = {"lubrication_loss": "lube_loss", "flexspline_stiffness_loss": "fs_loss"}.get(a_["plan"]["fault"])
            for r in a_["missions"]:
                sev[(a_["actuator_id"], int(r["mission_index"]))] = r.get(key, 0.0) if key else 0.0
    who_all = sum((data[n][2] for n, *_ in FLEETS[1:]), [])
    pred = qda.predict(Xall)
    print("\n| fault | severity at snapshot | snapshots | recall (gaussian) |\n|---|---|---|---|")
    for f in ("lubrication_loss", "flexspline_stiffness_loss"):
        for lo, hi in ((0.15, 0.35), (0.35, 0.65), (0.65, 1.0)):
            idx = [i for i, (w, t) in enumerate(zip(who_all, yall)) if t == f and lo <= sev[w] < hi]
            if idx:
                rr = np.mean([pred[i] == f for i in idx])
                print(f"| {f} | {lo:.2f}-{hi:.2f} | {len(idx)} | {rr:.2f} |")
    P = qda.predict_proba(Xall)
    print(f"\nmean p(unknown) on held-out snapshots {P[:, -1].mean():.3f}")
    across_plants(data)
    # the classifier to ship: every fleet of every plant, its structure chosen by leave-one-plant-out over all six
    from hd_ground.fleet.classify import fit_across_plants

    plant = {name: fam for name, fam, *_ in FLEETS}
    Xa = np.concatenate([data[n][0] for n, *_ in FLEETS])
    ya = sum((data[n][1] for n, *_ in FLEETS), [])
    ga = sum(([plant[n]] * len(data[n][1]) for n, *_ in FLEETS), [])
    m = fit_across_plants(Xa, ya, ga)
    out = Path(a.out) if a.out else root / "classifier.json"
    m.save(out)
    ch = m.info["covariance_choice"]
    print(f"\nclassifier on all {len(ya)} snapshots of the six plants ({m.counts}), covariance "
          f"{m.covariance} (leave-one-plant-out macro recall "
          f"{ch['mean_macro_recall'][ch['chosen']]:.2f}) -> {out}")
    print(f"wall {time.perf_counter() - t0:.0f} s")
    return 0


def across_plants(data: dict) -> dict:
    """Leave-one-plant-out: for each plant, the classifier is trained on every fleet of the *other* plants (its
    covariance structure chosen by leave-one-plant-out among those training plants only: nested, the scored plant is
    never seen) and scored on that plant's held-out fleet; the nearest-centroid baseline and the Gaussian classifier
    with the train_A protocol's fixed structure (pooled) are trained on the same rows. Returns the rows it prints."""
    from hd_ground.fleet.classify import GaussianFaultClassifier, NearestCentroid, fit_across_plants, macro_recall

    plant = {name: fam for name, fam, *_ in FLEETS}
    rows = {}
    print("\n**Leave one plant out** (trained on every other plant's fleets; structure chosen by leave-one-plant-out"
          " on the training plants only)\n")
    print("| held-out plant (snapshots) | chosen covariance (inner macro recall) | gaussian, chosen: acc / macro recall |"
          " called unknown | gaussian, pooled: acc / macro recall | nearest-centroid: acc / macro recall |\n"
          "|---|---|---|---|---|---|")
    all_t, all_p = [], {"chosen": [], "pooled": [], "nc": []}
    for name, fam, *_ in FLEETS[1:]:
        train = [n for n in data if plant[n] != fam]
        Xtr = np.concatenate([data[n][0] for n in train])
        ytr = sum((data[n][1] for n in train), [])
        gtr = sum(([plant[n]] * len(data[n][1]) for n in train), [])
        X, y, _ = data[name]
        m = fit_across_plants(Xtr, ytr, gtr)
        preds = {"chosen": m.predict(X), "pooled": GaussianFaultClassifier().fit(Xtr, ytr).predict(X),
                 "nc": NearestCentroid().fit(Xtr, ytr).predict(X)}
        sc = {k: (float(np.mean(np.array(v) == np.array(y))), macro_recall(y, v)) for k, v in preds.items()}
        ch = m.info["covariance_choice"]
        name_m = m.covariance
        unk = float(np.mean(np.array(preds["chosen"]) == "unknown"))
        rows[fam] = {"covariance": name_m, "inner": ch["mean_macro_recall"], "unknown": unk, **sc}
        all_t += y
        for k in preds:
            all_p[k] += preds[k]
        print(f"| {fam} ({len(y)}) | {name_m} ({ch['mean_macro_recall'][name_m]:.2f}) | "
              f"{sc['chosen'][0]:.2f} / {sc['chosen'][1]:.2f} | {unk:.2f} | {sc['pooled'][0]:.2f} / {sc['pooled'][1]:.2f} | "
              f"{sc['nc'][0]:.2f} / {sc['nc'][1]:.2f} |")
    tot = {k: (float(np.mean(np.array(v) == np.array(all_t))), macro_recall(all_t, v)) for k, v in all_p.items()}
    unk = float(np.mean(np.array(all_p["chosen"]) == "unknown"))
    print(f"| all ({len(all_t)}) | - | {tot['chosen'][0]:.2f} / {tot['chosen'][1]:.2f} | {unk:.2f} | {tot['pooled'][0]:.2f} / "
          f"{tot['pooled'][1]:.2f} | {tot['nc'][0]:.2f} / {tot['nc'][1]:.2f} |")
    rows["all"] = tot
    return rows


if __name__ == "__main__":
    sys.exit(main())
