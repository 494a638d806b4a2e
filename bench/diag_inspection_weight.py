"""Why overhaul readings move a unit's latent wear estimate so little (issue 12; diagnosis, scoring code).

For every failed unit of a simulated fleet the life model is fitted leave-one-unit-out as ``hdphm bench prognostics``
fits it (its defaults, point estimate: no parameter draws) on the other units' HI histories, failure missions and
overhaul readings (the bench's shop: ``--inspect-every K``, the quantity's gauge sd), and the held-out unit's latent
state is estimated at the missions where it was inspected, four ways: from its HI records *and* readings (the model),
from its HI records alone, from its readings so far alone through the fold's path ``L = r (E / E_ref)^b`` (least
squares for ``r``, flat prior) and from the latest reading alone (the fitted map ``v = alpha + beta L`` inverted). Next to them, the truth in the same units: the unit's wear over the training units' median failure wear
(``h / median h_fail``; reads ``fleet_truth.json``, nothing here feeds a fit). It also prints each unit's HI map
against its true wear (least squares ``HI = a + g h / median h_fail``, offset and gain), the scatter of those maps
over the fleet, and what the fitted model assumes for it (``s_a`` over ``c``, ``s_g``).

    python bench/diag_inspection_weight.py FLEET_DIR [--every 10] [--quantity lost_motion] [--cache DIR]
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("fleet")
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--quantity", default="lost_motion")
    ap.add_argument("--exposure", default="load", choices=("missions", "hours", "load"))
    ap.add_argument("--cache", default=None, help="feature cache folder of this fleet (the bench's OUT/cache/NAME)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_prognostics as B
    from hd_prognostic.evaluate import load_fleet
    from hd_prognostic.lifemodel import LifeModel, UnitEvents, attach_events
    from hd_prognostic.pipeline import unit_history

    truth = json.loads((Path(a.fleet) / "fleet_truth.json").read_text())
    ev = {x["actuator_id"]: UnitEvents(failure=float(x["eol_mission"])) for x in truth["actuators"]
          if x.get("eol_mission") is not None}
    ev = B.shop_inspections(truth, ev, a.every, a.quantity, None, False, a.seed)
    fleet = load_fleet(a.fleet, cache_dir=Path(a.cache) if a.cache else None, progress=False, workers=1)
    units = [unit_history(f, "HF_MTW_IF", a.exposure) for f in fleet]
    attach_events(units, ev)
    tr = {x["actuator_id"]: x for x in truth["actuators"]}
    hmed_all = float(np.median([x["params"]["h_fail"] for x in truth["actuators"]]))

    print("HI maps against the true wear (L = h / median h_fail of the fleet): HI = a + g L")
    maps = {}
    for u in units:
        h = {int(m["mission_index"]): m["h"] for m in tr[u.unit]["missions"]}
        L = np.array([h.get(int(t), np.nan) for t in u.t]) / hmed_all
        y = np.asarray(u.y, float)
        ok = np.isfinite(L) & np.isfinite(y)
        g, a0 = np.polyfit(L[ok], y[ok], 1)
        maps[u.unit] = (a0, g, float(np.std(y[ok] - a0 - g * L[ok])))
        print(f"  {u.unit}: a {a0:.3e}  g {g:.3e}  residual sd {maps[u.unit][2]:.2e}")
    av = np.array([m[0] for m in maps.values()])
    gv = np.array([m[1] for m in maps.values()])
    print(f"  scatter over the fleet: sd(a) / mean(g) = {np.std(av, ddof=1) / np.mean(gv):.3f} (in L), "
          f"sd(g) / mean(g) = {np.std(gv, ddof=1) / np.mean(gv):.3f}")

    rows = []
    for i, u in enumerate(units):
        if u.events.failure is None:
            continue
        train = [v for j, v in enumerate(units) if j != i]
        m = LifeModel.fit(train, exposure=a.exposure, feature="HF_MTW_IF", time_unit="mission", n_draws=0,
                          seed=a.seed, threshold=B.THRESHOLD[0], path=B.PATH[0], failure_at=B.FAILURE_AT[0],
                          exposure_rate=B.RATE[0], exposure_spread=B.SPREAD[0], noise=B.NOISE[0],
                          hi_gain=B.GAIN[0])
        if m.threshold != "latent" or a.quantity not in m.inspections:
            print(f"{u.unit}: fold kept the {m.threshold} threshold / no {a.quantity} map: skipped")
            continue
        qm = m.inspections[a.quantity]
        hmed = float(np.median([tr[v.unit]["params"]["h_fail"] for v in train]))
        h = {int(x["mission_index"]): x["h"] for x in tr[u.unit]["missions"]}
        test = copy.deepcopy(u)
        test.events = UnitEvents(inspections=list(u.events.inspections))
        hi_only = copy.deepcopy(u)
        hi_only.events = UnitEvents()
        ts = [t for t, q, _ in test.events.inspections if q == a.quantity]
        if not ts:
            continue
        X = np.array([(u.exposure_at(t) / m.E_ref) ** m.b for t in ts])
        z1, w1 = m.posterior(test, ts)
        z2, w2 = m.posterior(hi_only, ts)
        vr = np.array([val for _, q, val in test.events.inspections if q == a.quantity])
        sa_L = math.exp(m.theta["log_sa"]) / abs(m.theta["c"])
        sg = math.exp(m.theta["log_sg"]) if "log_sg" in m.theta else 0.0
        print(f"{u.unit} (EOL {u.events.failure:g}; fold: b {m.b:.3f}, s_a/c {sa_L:.3f} in L, s_g {sg:.3f}, "
              f"reading sd tau/beta {math.exp(qm['log_tau']) / qm['beta']:.3f} in L)")
        for k, t in enumerate(ts):
            q1 = m.latent_quantiles(z1[k], w1[k], X[k])
            q2 = m.latent_quantiles(z2[k], w2[k], X[k])
            # the readings so far through the fold's path L = r X (least squares for r, flat prior, no HI)
            xs, vs = X[:k + 1], vr[:k + 1]
            r_hat = float(np.sum((vs - qm["alpha"]) * xs) / (qm["beta"] * np.sum(xs ** 2)))
            sd_r = math.exp(qm["log_tau"]) / (abs(qm["beta"]) * math.sqrt(np.sum(xs ** 2)))
            q3 = (r_hat * X[k] - 1.645 * sd_r * X[k], r_hat * X[k], r_hat * X[k] + 1.645 * sd_r * X[k])
            v = [val for tt, q, val in test.events.inspections if q == a.quantity and tt == t][-1]
            Lr = (v - qm["alpha"]) / qm["beta"]
            Lt = h[int(t)] / hmed
            rows.append((q1[1] - Lt, q2[1] - Lt, Lr - Lt, (q1[2] - q1[0]) / 3.29, q3[1] - Lt, (q2[2] - q2[0]) / 3.29,
                         (q3[2] - q3[0]) / 3.29))
            print(f"  mission {t:4g}: true {Lt:.3f} | model {q1[1]:.3f} [{q1[0]:.3f}, {q1[2]:.3f}] | HI alone "
                  f"{q2[1]:.3f} | readings alone {q3[1]:.3f} | latest reading alone {Lr:.3f}")
    if rows:
        r = np.array(rows)
        print("RMS error against the true wear (L units), over every unit and reading: model "
              f"{np.sqrt(np.mean(r[:, 0] ** 2)):.3f}, HI alone {np.sqrt(np.mean(r[:, 1] ** 2)):.3f}, reading alone "
              f"{np.sqrt(np.mean(r[:, 2] ** 2)):.3f}, readings alone through the path "
              f"{np.sqrt(np.mean(r[:, 4] ** 2)):.3f}; posterior sd (mean; from the 90 % interval): model "
              f"{np.mean(r[:, 3]):.3f}, HI alone {np.mean(r[:, 5]):.3f}, readings alone {np.mean(r[:, 6]):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
