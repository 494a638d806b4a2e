"""The fleet store: partitioned Parquet files (by actuator, then mission) with a DuckDB database over them.

Layout under the store directory ``S``::

    S/data/actuator_id=<A>/mission_index=<K:06d>/   one folder per analysed mission (atomic: see below)
        missions.parquet  features.parquet  residual_stats.parquet  events.parquet
    S/actuators/actuator_id=<A>/                      per-actuator results, each file replaced atomically
        calibration.parquet  rul.parquet  classification.parquet  events.parquet
    S/discovery/<type>/report.json, events.parquet   discovery per actuator type (``--discover``)
    S/fleet.duckdb                                    views over the files (absolute paths), for DuckDB / BI tools
    S/_tmp/                                           half-written missions (ignored; safe to delete)

**Atomicity.** A mission's four tables are written into a fresh folder under ``S/_tmp`` and then moved
into place with one ``os.rename`` of the folder: a reader (or a resumed run) sees either the whole
mission or nothing. If the target already exists (the same mission analysed twice: a task retried after
its worker died, a duplicate bag), the rename fails and the new copy is discarded, so no mission is ever
stored twice. Per-actuator files are replaced with ``os.replace`` of a temporary file (same filesystem).

**Tables** (all carry ``actuator_id``; mission tables also ``mission_index``):

* ``missions``: one row per mission: bag path and size, samples, duration, rate, gear ratio, operating hours,
  onboard max level and onset, reader notes, analysis time;
* ``features``: the mission observation (:func:`hd_onboard.features.mission_observation_features`);
* ``residual_stats``: twin residual statistics per channel, monitor outputs (stiffness loss, friction excess),
  and the per-mission recalibration inputs (least-squares estimates of T_C, b_visc, J_in, mu_c/mu_g);
* ``events``: flags (onboard level rises), input problems, recalibrations, suspected faults;
* ``rul``: RUL history per actuator and mission (P5/P50/P95, wear estimate, risk);
* ``classification``: fault class probabilities per actuator and mission (as of that mission);
* ``calibration``: per actuator, the ground calibration (parameters, thresholds, monitor references, JSON).
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
from pathlib import Path
from typing import Any, Iterable
from urllib.parse import quote, unquote

MISSION_TABLES = ("missions", "features", "residual_stats", "events")
ACTUATOR_TABLES = ("calibration", "rul", "classification", "events")
TABLES = ("missions", "features", "residual_stats", "events", "rul", "classification", "calibration")
DB_NAME = "fleet.duckdb"


def _aid_dir(actuator_id: str) -> str:
    return "actuator_id=" + quote(str(actuator_id), safe="")


def _mission_dir(mission_index: int) -> str:
    return f"mission_index={int(mission_index):06d}"


def _table(rows: list[dict] | dict[str, list], schema_hint: dict[str, str] | None = None):
    """A pyarrow table from row dicts (columns in first-seen order; missing values null)."""
    import pyarrow as pa

    if isinstance(rows, dict):
        return pa.table(rows)
    cols: dict[str, list] = {}
    for r in rows:
        for k in r:
            cols.setdefault(k, [])
    for k in cols:
        cols[k] = [r.get(k) for r in rows]
    if not rows and schema_hint:
        return pa.table({k: pa.array([], type=getattr(pa, t)()) for k, t in schema_hint.items()})
    return pa.table(cols)


#: columns of an empty events table (so every mission folder has all four files)
EVENT_SCHEMA = {"actuator_id": "string", "mission_index": "int64", "t_s": "float64", "kind": "string",
                "name": "string", "level": "int64", "value": "float64", "detail": "string"}


class FleetStore:
    """A store directory (created on first write). Safe for many writers (one per mission at a time)."""

    def __init__(self, root: str | os.PathLike):
        self.root = Path(root).absolute()

    # ---- paths ------------------------------------------------------------------------------------
    def mission_path(self, actuator_id: str, mission_index: int) -> Path:
        return self.root / "data" / _aid_dir(actuator_id) / _mission_dir(mission_index)

    def actuator_path(self, actuator_id: str) -> Path:
        return self.root / "actuators" / _aid_dir(actuator_id)

    # ---- what is done -----------------------------------------------------------------------------
    def has_mission(self, actuator_id: str, mission_index: int) -> bool:
        return self.mission_path(actuator_id, mission_index).is_dir()

    def done_missions(self) -> dict[str, set[int]]:
        """actuator_id -> mission indices stored (from folder names only: cheap)."""
        out: dict[str, set[int]] = {}
        d = self.root / "data"
        if not d.is_dir():
            return out
        for a in os.scandir(d):
            if not (a.is_dir() and a.name.startswith("actuator_id=")):
                continue
            aid = unquote(a.name.split("=", 1)[1])
            ks = set()
            for m in os.scandir(a.path):
                if m.is_dir() and m.name.startswith("mission_index="):
                    ks.add(int(m.name.split("=", 1)[1]))
            out[aid] = ks
        return out

    def done_bags(self) -> dict[str, tuple[str, int]]:
        """bag path -> (actuator_id, mission_index) of every stored mission (reads the ``missions`` column)."""
        import pyarrow.parquet as pq

        out = {}
        for aid, ks in self.done_missions().items():
            for k in ks:
                p = self.mission_path(aid, k) / "missions.parquet"
                try:
                    t = pq.read_table(p, columns=["bag"])
                except (OSError, ValueError):
                    continue
                for b in t.column("bag").to_pylist():
                    out[b] = (aid, k)
        return out

    # ---- writing ----------------------------------------------------------------------------------
    def _tmp(self) -> Path:
        p = self.root / "_tmp" / f"{os.getpid()}-{uuid.uuid4().hex}"
        p.mkdir(parents=True)
        return p

    def write_mission(self, actuator_id: str, mission_index: int, tables: dict[str, list[dict]]) -> bool:
        """Write one mission's tables atomically; False (and nothing written) if it is already stored."""
        import pyarrow.parquet as pq

        final = self.mission_path(actuator_id, mission_index)
        if final.is_dir():
            return False
        tmp = self._tmp()
        try:
            for name in MISSION_TABLES:
                rows = tables.get(name, [])
                pq.write_table(_table(rows, EVENT_SCHEMA if name == "events" else None), tmp / f"{name}.parquet")
            final.parent.mkdir(parents=True, exist_ok=True)
            try:
                os.rename(tmp, final)
            except OSError:
                if final.is_dir():  # another task stored the same mission first: keep theirs
                    return False
                raise
            return True
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)

    def write_actuator_table(self, actuator_id: str, name: str, rows: list[dict]) -> Path:
        """Replace one per-actuator table atomically (``os.replace`` of a temporary file)."""
        import pyarrow.parquet as pq

        if name not in ACTUATOR_TABLES:
            raise ValueError(f"fleet store: unknown per-actuator table {name!r} (one of {ACTUATOR_TABLES})")
        d = self.actuator_path(actuator_id)
        d.mkdir(parents=True, exist_ok=True)
        if not rows and name != "events":  # nothing (e.g. no classifier): no file, not a file without columns
            (d / f"{name}.parquet").unlink(missing_ok=True)
            return d / f"{name}.parquet"
        tmp = d / f".{name}.{os.getpid()}.{uuid.uuid4().hex}.tmp"
        pq.write_table(_table(rows, EVENT_SCHEMA if name == "events" else None), tmp)
        os.replace(tmp, d / f"{name}.parquet")
        return d / f"{name}.parquet"

    def read_actuator_table(self, actuator_id: str, name: str) -> list[dict] | None:
        import pyarrow.parquet as pq

        p = self.actuator_path(actuator_id) / f"{name}.parquet"
        if not p.is_file():
            return None
        return pq.read_table(p).to_pylist()

    def read_mission_rows(self, actuator_id: str, name: str) -> list[dict]:
        """All rows of one mission table for one actuator, in mission order."""
        import pyarrow.parquet as pq

        d = self.root / "data" / _aid_dir(actuator_id)
        if not d.is_dir():
            return []
        rows: list[dict] = []
        for m in sorted(os.scandir(d), key=lambda e: e.name):
            if m.is_dir() and m.name.startswith("mission_index="):
                rows += pq.read_table(Path(m.path) / f"{name}.parquet").to_pylist()
        return rows

    def clean_tmp(self) -> int:
        """Delete half-written missions left by killed processes; returns how many."""
        d = self.root / "_tmp"
        n = 0
        if d.is_dir():
            for e in os.scandir(d):
                shutil.rmtree(e.path, ignore_errors=True)
                n += 1
        return n

    # ---- SQL --------------------------------------------------------------------------------------
    def _globs(self) -> dict[str, list[str]]:
        r = self.root.as_posix()
        g = {t: [f"{r}/data/*/*/{t}.parquet"] for t in ("missions", "features", "residual_stats")}
        g["events"] = [f"{r}/data/*/*/events.parquet", f"{r}/actuators/*/events.parquet",
                       f"{r}/discovery/*/events.parquet"]
        for t in ("rul", "classification", "calibration"):
            g[t] = [f"{r}/actuators/*/{t}.parquet"]
        return g

    def view_sql(self) -> list[str]:
        import glob

        out = []
        for t, gl in self._globs().items():
            have = [x for x in gl if glob.glob(x)]
            if have:
                lst = ", ".join(f"'{x}'" for x in have)
                out.append(f"CREATE OR REPLACE VIEW {t} AS SELECT * FROM read_parquet([{lst}], union_by_name = true, hive_partitioning = false)")
            else:  # no file yet: an empty view with the key columns, so queries still parse
                out.append(f"CREATE OR REPLACE VIEW {t} AS SELECT NULL::VARCHAR AS actuator_id, "
                           "NULL::BIGINT AS mission_index WHERE false")
        return out

    def connect(self):
        """An in-memory DuckDB connection with one view per table (works while another process writes)."""
        import duckdb

        con = duckdb.connect(":memory:")
        for s in self.view_sql():
            con.execute(s)
        return con

    def write_database(self) -> Path:
        """(Re)write ``fleet.duckdb``: the same views, for tools that open the file (single writer: the client)."""
        import duckdb

        self.root.mkdir(parents=True, exist_ok=True)
        path = self.root / DB_NAME
        tmp = self.root / f".{DB_NAME}.{os.getpid()}.tmp"
        if tmp.exists():
            tmp.unlink()
        con = duckdb.connect(str(tmp))
        try:
            for s in self.view_sql():
                con.execute(s)
        finally:
            con.close()
        os.replace(tmp, path)
        return path

    def query(self, sql: str) -> tuple[list[str], list[tuple]]:
        """(column names, rows) of a SQL statement over the store's views."""
        import duckdb

        con = self.connect()
        try:
            cur = con.execute(sql)
            cols = [d[0] for d in (cur.description or [])]
            return cols, cur.fetchall()
        except duckdb.Error as e:
            raise ValueError(f"fleet store {self.root}: SQL error: {e}") from None
        finally:
            con.close()

    def snapshot(self, tables: Iterable[str] = TABLES, exclude: Iterable[str] = ("task_s", "bag", "bag_bytes")) -> dict[str, Any]:
        """Every table's rows sorted, as JSON-able lists (to compare two stores); drops timing/path columns."""
        con = self.connect()
        out = {}
        ex = set(exclude)
        try:
            for t in tables:
                cur = con.execute(f"SELECT * FROM {t}")
                cols = [d[0] for d in cur.description]
                keep = [i for i, c in enumerate(cols) if c not in ex]
                rows = [tuple(r[i] for i in keep) for r in cur.fetchall()]
                out[t] = sorted(json.dumps(r, default=str) for r in rows)
        finally:
            con.close()
        return out
