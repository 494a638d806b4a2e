"""The fleet analysis driver: expand bag paths, build the task graph, run it on Dask, report progress.

``run_fleet(paths, store, scheduler="local")`` is what ``hdphm ground fleet`` calls. The scheduler is
``local`` (an embedded :class:`distributed.LocalCluster` with one single-threaded worker process per
core), ``local:N`` (N worker processes) or the address of a running scheduler (``tcp://HOST:PORT``):
the same graph runs unchanged on it. Only bag *paths* go to the workers (they must see the same files:
shared storage, see docs/FLEET.md); the client reads no bag.

A rerun skips the stored missions; a run killed at any point (client or workers) resumes with no
duplicate and no lost row: each mission is committed atomically by its task, and the per-actuator
results of an actuator are recomputed whenever its stored missions changed.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections import defaultdict
from typing import Any, Callable, Iterable

from hd_ground.fleet.store import FleetStore
from hd_ground.fleet.tasks import (FleetOptions, actuator_task, calibrate_task, discover_task, mission_task,
                                   probe_task)


def expand_bags(specs: Iterable[str]) -> list[str]:
    """Bag files from paths, directories (searched recursively for ``*.mcap``) and glob patterns."""
    from hd_bag.files import find_bags

    found = find_bags(specs, patterns=True, files_only=True, sort_key=str, empty_error=False, error=FileNotFoundError)
    out = [str(p.absolute()) for p in found]
    seen: set[str] = set()
    return [p for p in out if not (p in seen or seen.add(p))]


def make_client(scheduler: str = "local"):
    """(client, cluster or None) for ``local``, ``local:N`` or a scheduler address."""
    from distributed import Client, LocalCluster

    if scheduler.startswith("local"):
        _, _, n = scheduler.partition(":")
        try:
            nw = int(n) if n else (os.cpu_count() or 1)
        except ValueError:
            raise ValueError(f"--scheduler {scheduler!r}: expected local, local:N or tcp://HOST:PORT") from None
        if not 1 <= nw <= 1024:
            raise ValueError(f"--scheduler {scheduler!r}: worker count must be in 1..1024")
        cluster = LocalCluster(n_workers=nw, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=50)
        return Client(cluster), cluster
    if "://" not in scheduler:
        raise ValueError(f"--scheduler {scheduler!r}: expected local, local:N or tcp://HOST:PORT")
    try:
        return Client(scheduler, timeout=20), None
    except (OSError, TimeoutError) as e:
        raise ValueError(f"--scheduler {scheduler}: cannot connect ({e})") from None


def _stored_calibration(store: FleetStore, aid: str, ref_missions: list[int], opts: FleetOptions) -> dict | None:
    rows = store.read_actuator_table(aid, "calibration")
    if not rows:
        return None
    r = rows[0]
    try:
        keys = ("healthy_missions", "model_dir", "onboard")  # what the calibration depends on
        old = json.loads(r["options"])
        if json.loads(r["reference_missions"]) != ref_missions or any(old.get(k) != getattr(opts, k) for k in keys):
            return None
        return {k: json.loads(r[k]) for k in ("reference_missions", "params", "thresholds", "references",
                                               "recalibration", "options")}
    except (KeyError, TypeError, json.JSONDecodeError):
        return None


def run_fleet(bags: Iterable[str], store_dir: str, scheduler: str = "local", opts: FleetOptions | None = None,
              progress: bool = True, log: Callable[[str], None] = print, client=None,
              refresh: bool = False) -> dict[str, Any]:
    """Analyse every bag not yet in the store; returns a summary (counts, errors, wall time).

    ``refresh``: recompute every actuator's RUL history and fault classes even when none of its missions
    is new (after changing the classifier or the observation model)."""
    from distributed import as_completed

    opts = opts or FleetOptions()
    opts.onboard_config()  # bad options fail here, on the client, not in every task
    if opts.healthy_missions < 1:
        raise ValueError(f"healthy_missions = {opts.healthy_missions} must be >= 1")
    t0 = time.perf_counter()
    paths = expand_bags(bags)
    if not paths:
        raise FileNotFoundError("no .mcap bags found in the given paths")
    store = FleetStore(store_dir)
    store.root.mkdir(parents=True, exist_ok=True)
    own = client is None
    cluster = None
    if own:
        client, cluster = make_client(scheduler)
    summary: dict[str, Any] = {"bags": len(paths), "store": str(store.root), "scheduler": scheduler, "errors": []}
    try:
        summary["workers"] = len(client.scheduler_info().get("workers", {}))
        probes = []
        for i in range(0, len(paths), 5000):  # batches: a bounded number of futures on the client
            batch = paths[i: i + 5000]
            probes += client.gather(client.map(probe_task, batch, key=[f"probe-{i + j}-{hash(p)}"
                                                                       for j, p in enumerate(batch)]))
        by_act: dict[str, dict[int, str]] = defaultdict(dict)
        ratio: dict[str, float] = {}
        for pr in probes:
            if "error" in pr:
                summary["errors"].append(pr["error"])
                continue
            k = pr["mission_index"]
            have = by_act[pr["actuator_id"]]
            if k in have:
                summary["errors"].append(f"{pr['bag']}: duplicate of {have[k]} (actuator {pr['actuator_id']}, "
                                         f"mission {k}); ignored")
                continue
            have[k] = pr["bag"]
            ratio.setdefault(pr["actuator_id"], pr.get("gear_ratio", float("nan")))
        done = store.done_missions()
        tok = format(abs(hash(str(store.root))) % 16**8, "08x")  # task keys per store: a shared cluster never mixes runs
        # plan (cheap, client side): per actuator the missions to run and whether its results are stale
        plans = []
        n_todo = n_skip = 0
        for aid in sorted(by_act):
            ms = dict(sorted(by_act[aid].items()))
            stored = done.get(aid, set())
            todo = [k for k in ms if k not in stored]
            n_skip += len(ms) - len(todo)
            n_todo += len(todo)
            rul = store.read_actuator_table(aid, "rul")
            n_all = len(stored | set(todo))
            need_act = bool(refresh or todo or not rul or rul[-1].get("n_missions") != n_all)
            if todo or need_act:
                plans.append((aid, ms, todo, need_act, n_all))
        disc = []
        if opts.discover:  # one discovery per actuator type (gear ratio), on reference missions, if not stored
            types: dict[str, list[str]] = defaultdict(list)
            for aid in sorted(by_act):
                g = ratio.get(aid, float("nan"))
                key = f"gear_ratio={g:g}" if g == g else "gear_ratio=unknown"
                if len(types[key]) < opts.discover_units:
                    types[key].append(by_act[aid][min(by_act[aid])])
            disc = [(key, ps) for key, ps in types.items() if not (store.root / "discovery" / key).is_dir()]
        n_tasks = n_todo + sum(p[3] for p in plans) + len(disc)
        summary.update(actuators=len(by_act), missions_todo=n_todo, missions_skipped=n_skip, discovery_types=len(disc))
        log(f"fleet: {len(paths)} bags, {len(by_act)} actuators, {n_todo} missions to analyse, {n_skip} already "
            f"stored, on {summary['workers']} worker(s) ({scheduler})")

        def submissions():
            """Tasks submitted lazily, actuator after actuator, so the client holds a bounded window of
            futures (an actuator's mission futures until its actuator task is submitted), not one per task."""
            for key, ps in disc:
                yield client.submit(discover_task, ps, str(store.root), key, opts, key=f"discover-{tok}-{key}")
            for aid, ms, todo, need_act, n_all in plans:
                ref_idx = list(ms)[: opts.healthy_missions]
                calib = _stored_calibration(store, aid, ref_idx, opts)
                if calib is None:
                    calib = client.submit(calibrate_task, [ms[k] for k in ref_idx], opts,
                                          key=f"calibrate-{tok}-{aid}-{hash(tuple(ref_idx))}")
                mf = []
                for k in todo:
                    f = client.submit(mission_task, ms[k], str(store.root), calib, opts, key=f"mission-{tok}-{aid}-{k}",
                                      retries=2)
                    mf.append(f)
                    yield f
                if need_act:
                    yield client.submit(actuator_task, str(store.root), aid, calib, opts, *mf,
                                        key=f"actuator-{tok}-{aid}-{n_all}-{time.time_ns()}", retries=1)

        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=n_tasks, unit="task", desc="fleet", file=sys.stderr)
        window = max(64, 8 * max(summary["workers"], 1))
        gen = submissions()
        ac = as_completed()
        pending = 0

        def fill() -> None:
            nonlocal pending
            while pending < window:
                f = next(gen, None)
                if f is None:
                    return
                ac.add(f)
                pending += 1

        fill()
        n_stored = 0
        task_s = act_s = 0.0
        samples = nbytes = 0
        for f in ac:
            pending -= 1
            fill()
            if bar:
                bar.update(1)
            try:
                r = f.result()
            except Exception as e:  # noqa: BLE001 - one bad bag must not stop the fleet
                summary["errors"].append(f"{f.key}: {type(e).__name__}: {e}")
                continue
            if "missions" in r and "task_s" in r:  # an actuator task
                act_s += r["task_s"]
            if r.get("stored") and "mission_index" in r:
                n_stored += 1
                task_s += r.get("task_s", 0.0)
                samples += r.get("samples", 0)
                nbytes += r.get("bytes", 0)
        if bar:
            bar.close()
        summary.update(missions_stored=n_stored, mission_task_s=task_s, actuator_task_s=act_s, samples=samples, bag_bytes=nbytes)
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    store.write_database()
    summary["wall_s"] = time.perf_counter() - t0
    return summary


def fleet_status(store_dir: str) -> list[dict[str, Any]]:
    """One row per actuator: missions, last flags, health, RUL P5/P50/P95, suspected fault."""
    st = FleetStore(store_dir)
    if not (st.root / "data").is_dir():
        raise FileNotFoundError(f"{st.root}: not a fleet store (no data/ folder); run 'hdphm ground fleet' first")
    sql = """
    WITH m AS (SELECT actuator_id, count(*) AS missions, max(mission_index) AS last_mission FROM missions GROUP BY 1),
    lf AS (SELECT actuator_id, max_level AS last_level FROM missions
           QUALIFY row_number() OVER (PARTITION BY actuator_id ORDER BY mission_index DESC) = 1),
    fl AS (SELECT actuator_id, string_agg(DISTINCT name, ',') AS last_flags FROM events
           WHERE kind = 'flag' AND (actuator_id, mission_index) IN (SELECT actuator_id, last_mission FROM m) GROUP BY 1),
    r AS (SELECT * FROM rul QUALIFY row_number() OVER (PARTITION BY actuator_id ORDER BY mission_index DESC) = 1),
    c AS (SELECT * FROM classification QUALIFY row_number() OVER (PARTITION BY actuator_id ORDER BY mission_index DESC) = 1)
    SELECT m.actuator_id, m.missions, m.last_mission, lf.last_level, fl.last_flags, r.h_mean, r.h_fail,
           r.rul_p5, r.rul_p50, r.rul_p95, c.label, c.p_healthy, c.p_tooth_wear, c.p_lubrication_loss,
           c.p_flexspline_stiffness_loss, c.p_unknown
    FROM m LEFT JOIN lf USING (actuator_id) LEFT JOIN fl USING (actuator_id) LEFT JOIN r USING (actuator_id)
           LEFT JOIN c USING (actuator_id) ORDER BY m.actuator_id
    """
    con = st.connect()
    try:
        have = {t: {r[0] for r in con.execute(f"DESCRIBE {t}").fetchall()} for t in ("rul", "classification")}
        if "rul_p50" not in have["rul"]:
            con.execute("CREATE OR REPLACE VIEW rul AS SELECT NULL::VARCHAR actuator_id, NULL::BIGINT mission_index, "
                        "NULL::DOUBLE h_mean, NULL::DOUBLE h_fail, NULL::DOUBLE rul_p5, NULL::DOUBLE rul_p50, "
                        "NULL::DOUBLE rul_p95 WHERE false")
        if "p_unknown" not in have["classification"]:
            con.execute("CREATE OR REPLACE VIEW classification AS SELECT NULL::VARCHAR actuator_id, "
                        "NULL::BIGINT mission_index, NULL::VARCHAR label, " + ", ".join(
                            f"NULL::DOUBLE p_{c}" for c in ("healthy", "tooth_wear", "lubrication_loss",
                                                             "flexspline_stiffness_loss", "unknown")) + " WHERE false")
        cur = con.execute(sql)
        cols = [d[0] for d in cur.description]
        return [dict(zip(cols, r)) for r in cur.fetchall()]
    finally:
        con.close()
