"""CSV log -> contract bag (``hdphm import-csv``).

A *mapping* says where each contract quantity comes from, in a small YAML file
(see ``src/hd_bag/mappings/``) or as command-line flags::

    time:    {column: t_s, unit: s}
    signals:                       # /hd/joint_states, SI after conversion
      theta_f: {column: pos_deg, unit: deg}
      theta_m: {from: theta_f, times: gear_ratio}   # derived: N * theta_f
      omega_f: {column: vel_rps, unit: rev/s}
      omega_m: {from: omega_f, times: gear_ratio}
      tau_m:   {column: iq_A, unit: A}              # A -> N*m via k_t (tau_m = k_t * i_q)
      Q_red:   nan                                  # not measured
    command:     {theta_ref: {column: tgt_deg, unit: deg}}   # optional
    temperature: {gearbox: {column: T_gb, unit: degC}}       # optional
    flags:       {fault: {column: fault}}   # counted and reported, data kept
    meta: {actuator_id: ..., gear_ratio: 50, torque_constant: 0.1022, source: test_bench, ...}
    start_time: filename      # or an ISO date, or ns since epoch; default 0

Every signal not mapped is written as NaN and said so in the bag's metadata
(``csv_unmapped``). Rows with a non-numeric or NaN time are dropped (reported);
NaN or empty values stay NaN. Rows are written in file order: the reader
re-sorts, drops duplicates and marks gaps, as for any contract bag.
"""

from __future__ import annotations

import csv
import datetime as _dt
import math
import os
import re
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .errors import BagError
from .mission import JOINT_SIGNALS, TEMPERATURE_FRAMES, Mission, MissionMeta

MAPPINGS_DIR = Path(__file__).with_name("mappings")

#: unit -> (quantity kind, factor to SI, offset added after scaling)
UNITS: dict[str, tuple[str, float, float]] = {
    # time
    "s": ("time", 1.0, 0.0), "ms": ("time", 1e-3, 0.0), "us": ("time", 1e-6, 0.0), "ns": ("time", 1e-9, 0.0),
    # angle
    "rad": ("angle", 1.0, 0.0), "mrad": ("angle", 1e-3, 0.0), "deg": ("angle", math.pi / 180, 0.0),
    "rev": ("angle", 2 * math.pi, 0.0), "turn": ("angle", 2 * math.pi, 0.0),
    "arcmin": ("angle", math.pi / 180 / 60, 0.0), "arcsec": ("angle", math.pi / 180 / 3600, 0.0),
    # angular velocity
    "rad/s": ("speed", 1.0, 0.0), "deg/s": ("speed", math.pi / 180, 0.0), "rev/s": ("speed", 2 * math.pi, 0.0),
    "rps": ("speed", 2 * math.pi, 0.0), "rpm": ("speed", 2 * math.pi / 60, 0.0),
    # torque
    "N*m": ("torque", 1.0, 0.0), "Nm": ("torque", 1.0, 0.0), "N.m": ("torque", 1.0, 0.0),
    "mN*m": ("torque", 1e-3, 0.0), "mNm": ("torque", 1e-3, 0.0), "kN*m": ("torque", 1e3, 0.0),
    "kNm": ("torque", 1e3, 0.0),
    # current (only for tau_m: tau_m = k_t * i_q)
    "A": ("current", 1.0, 0.0), "mA": ("current", 1e-3, 0.0),
    # temperature (degC out)
    "degC": ("temperature", 1.0, 0.0), "C": ("temperature", 1.0, 0.0), "K": ("temperature", 1.0, -273.15),
    "degF": ("temperature", 5.0 / 9.0, -32.0 * 5.0 / 9.0),
}
_KINDS = {"theta_m": ("angle",), "theta_f": ("angle",), "theta_ref": ("angle",), "omega_m": ("speed",),
          "omega_f": ("speed",), "tau_m": ("torque", "current"), "Q_red": ("torque",)}


def _unit(path: str, name: str, unit: str, allowed: tuple[str, ...]) -> tuple[str, float, float]:
    u = UNITS.get(str(unit).strip())
    if u is None:
        raise BagError(path, f"{name}: unknown unit {unit!r} (known: {', '.join(UNITS)})")
    if u[0] not in allowed:
        raise BagError(path, f"{name}: unit {unit!r} is a {u[0]}, need {' or '.join(allowed)}")
    return u


def load_mapping(mapping: str | os.PathLike | Mapping[str, Any]) -> dict[str, Any]:
    """A mapping dict from a dict, a YAML path, or the name of a shipped mapping (``harivin_friction_sweep``)."""
    if isinstance(mapping, Mapping):
        return dict(mapping)
    import yaml

    p = Path(mapping)
    if not p.exists():
        cand = MAPPINGS_DIR / f"{mapping}.yaml"
        if cand.exists():
            p = cand
        else:
            shipped = sorted(x.stem for x in MAPPINGS_DIR.glob("*.yaml"))
            raise FileNotFoundError(f"{mapping}: no such mapping file (shipped mappings: {shipped})")
    with open(p) as f:
        d = yaml.safe_load(f)
    if not isinstance(d, dict):
        raise BagError(str(p), "mapping YAML must be a mapping at top level")
    return d


def _read_csv(path: str) -> dict[str, list[str]]:
    try:
        with open(path, newline="") as f:
            rd = csv.reader(f)
            try:
                header = next(rd)
            except StopIteration:
                raise BagError(path, "empty CSV (no header row)") from None
            header = [h.strip() for h in header]
            cols: list[list[str]] = [[] for _ in header]
            for lineno, row in enumerate(rd, start=2):
                if not row:
                    continue
                if len(row) != len(header):
                    raise BagError(path, f"line {lineno}: {len(row)} fields, header has {len(header)}")
                for c, v in zip(cols, row):
                    c.append(v)
    except UnicodeDecodeError as e:
        raise BagError(path, f"not a text CSV file ({e})") from None
    return dict(zip(header, cols))


def _numeric(path: str, cols: dict[str, list[str]], col: str) -> np.ndarray:
    if col not in cols:
        raise BagError(path, f"column {col!r} not in the CSV (columns: {list(cols)})")
    raw = cols[col]
    try:
        return np.array([v.strip() or "nan" for v in raw], dtype=np.float64)
    except ValueError:
        out = np.empty(len(raw))
        bad = 0
        for i, v in enumerate(raw):
            try:
                out[i] = float(v)
            except ValueError:
                out[i] = np.nan
                bad += 1
        return out


def _start_ns(path: str, spec: Any) -> tuple[int, str]:
    if spec in (None, 0, "0"):
        return 0, "unknown (stamps start at 0)"
    if spec == "filename":
        m = re.search(r"(\d{8})_(\d{6})", Path(path).stem)
        if not m:
            return 0, "unknown (no YYYYMMDD_HHMMSS in the file name; stamps start at 0)"
        t = _dt.datetime.strptime(m.group(1) + m.group(2), "%Y%m%d%H%M%S").replace(tzinfo=_dt.timezone.utc)
        return int(t.timestamp()) * 1_000_000_000, f"{t.isoformat()} from the file name (time zone unknown, taken as UTC)"
    if isinstance(spec, (int, float)):
        return int(spec), "given"
    t = _dt.datetime.fromisoformat(str(spec))
    if t.tzinfo is None:
        t = t.replace(tzinfo=_dt.timezone.utc)
    return int(t.timestamp() * 1e9), f"{t.isoformat()} (given)"


def _coerce_meta(meta: Mapping[str, Any]) -> dict[str, Any]:
    return {str(k): v for k, v in meta.items()}


def mission_from_csv(csv_path: str | os.PathLike, mapping: str | os.PathLike | Mapping[str, Any],
                     meta_overrides: Mapping[str, Any] | None = None) -> Mission:
    """Build a :class:`Mission` from one CSV log and a mapping (see the module docstring)."""
    path = os.fspath(csv_path)
    mp = load_mapping(mapping)
    cols = _read_csv(path)
    meta_d = _coerce_meta(mp.get("meta") or {})
    meta_d.update(_coerce_meta(meta_overrides or {}))
    for k in ("actuator_id", "gear_ratio", "torque_constant"):
        if k not in meta_d:
            raise BagError(path, f"metadata {k!r} not given (mapping 'meta:' or --meta {k}=VALUE)")
    try:
        N = float(meta_d["gear_ratio"])
        k_t = float(meta_d["torque_constant"])
        meta = MissionMeta(actuator_id=str(meta_d["actuator_id"]), mission_index=int(meta_d.get("mission_index", 0)),
                           operating_hours=float(meta_d.get("operating_hours", 0.0)), gear_ratio=N,
                           torque_constant=k_t, source=str(meta_d.get("source", "test_bench")))
    except (TypeError, ValueError) as e:
        raise BagError(path, f"bad metadata value: {e}") from None
    known = {"actuator_id", "mission_index", "operating_hours", "gear_ratio", "torque_constant", "source",
             "contract"}
    extra = {k: str(v) for k, v in meta_d.items() if k not in known}

    tspec = mp.get("time") or {}
    if "column" not in tspec:
        raise BagError(path, "mapping has no 'time: {column: ..., unit: ...}'")
    _, tf, _ = _unit(path, "time", tspec.get("unit", "s"), ("time",))
    t = _numeric(path, cols, tspec["column"]) * tf
    good = np.isfinite(t)
    n_bad_t = int((~good).sum())
    notes = []
    if n_bad_t:
        notes.append(f"dropped {n_bad_t} rows without a valid time")
    t = t[good]
    n_back = int((np.diff(t) < 0).sum())
    if n_back:
        notes.append(f"{n_back} rows go back in time (written sorted by time; the CSV order is lost)")
    if len(t) < 2:
        raise BagError(path, f"only {len(t)} rows with a valid time")
    t0_ns, t0_note = _start_ns(path, mp.get("start_time"))

    def column_signal(name: str, spec: Any, allowed_kinds) -> np.ndarray | None:
        if spec is None:
            return None
        if isinstance(spec, str) and spec.strip().lower() == "nan" or (isinstance(spec, float) and math.isnan(spec)):
            return np.full(len(t), np.nan)
        if isinstance(spec, (int, float)):
            return np.full(len(t), float(spec))
        if not isinstance(spec, Mapping) or "column" not in spec:
            raise BagError(path, f"{name}: mapping must be nan, a number, {{column, unit}} or {{from, times}}")
        kind, f, off = _unit(path, name, spec.get("unit", "rad"), allowed_kinds)
        v = _numeric(path, cols, spec["column"])[good] * f * float(spec.get("scale", 1.0)) + off
        if kind == "current":
            v = v * k_t
        return v

    sig_spec = dict(mp.get("signals") or {})
    vals: dict[str, np.ndarray] = {}
    derived = []
    for name, spec in sig_spec.items():
        if name not in JOINT_SIGNALS:
            raise BagError(path, f"mapping signal {name!r} is not one of {JOINT_SIGNALS}")
        if isinstance(spec, Mapping) and "from" in spec:
            derived.append((name, spec))
            continue
        vals[name] = column_signal(name, spec, _KINDS[name])
    for name, spec in derived:
        src = spec["from"]
        if src not in vals:
            raise BagError(path, f"{name}: derived from {src!r}, which is not mapped to a column")
        times = spec.get("times", 1.0)
        fac = N if times == "gear_ratio" else (1.0 / N if times == "1/gear_ratio" else float(times))
        vals[name] = vals[src] * fac
    unmapped = [k for k in JOINT_SIGNALS if k not in vals]
    for k in unmapped:
        vals[k] = np.full(len(t), np.nan)
    if unmapped:
        extra["csv_unmapped"] = ",".join(unmapped)
    if derived:
        extra["csv_derived"] = ",".join(f"{n}={s['from']}*{s.get('times', 1)}" for n, s in derived)
    extra["csv_file"] = Path(path).name
    extra["csv_start_time"] = t0_note

    cmd = (mp.get("command") or {}).get("theta_ref")
    if cmd is not None:
        theta_ref = column_signal("theta_ref", cmd, _KINDS["theta_ref"])
        t_cmd = t.copy()
    else:
        theta_ref = np.zeros(0)
        t_cmd = np.zeros(0)
    temps = {}
    for frame, spec in (mp.get("temperature") or {}).items():
        if frame not in TEMPERATURE_FRAMES:
            raise BagError(path, f"temperature frame {frame!r} is not one of {TEMPERATURE_FRAMES}")
        _, f, off = _unit(path, f"temperature[{frame}]", spec.get("unit", "degC"), ("temperature",))
        temps[frame] = (t.copy(), _numeric(path, cols, spec["column"])[good] * f + off)
    for fname, spec in (mp.get("flags") or {}).items():
        fv = _numeric(path, cols, spec["column"])[good]
        nz = np.isfinite(fv) & (fv != 0)
        codes = sorted({int(x) for x in np.unique(fv[nz])}) if nz.any() else []
        extra[f"csv_{fname}_nonzero_samples"] = str(int(nz.sum()))
        if codes:
            extra[f"csv_{fname}_codes"] = ",".join(map(str, codes))
        if spec.get("nan_if_nonzero"):
            for k in JOINT_SIGNALS:
                vals[k] = np.where(nz, np.nan, vals[k])
            notes.append(f"set {int(nz.sum())} samples with {fname} != 0 to NaN")
    if notes:
        extra["csv_notes"] = "; ".join(notes)
    meta.extra = extra
    return Mission(meta=meta, t=t, **{k: vals[k] for k in JOINT_SIGNALS}, t_cmd=t_cmd, theta_ref=theta_ref,
                   temperatures=temps, t0_ns=t0_ns)


def _write_raw(out: str, m: Mission) -> None:
    """Write the mission; chunks cut every second of stamp time."""
    from . import cdr
    from .mission import TOPIC_COMMAND, TOPIC_JOINT_STATES, TOPIC_TEMPERATURE
    from .writer import CMD_LAYOUT, JS_LAYOUT, MissionWriter

    s = m.t0_ns + np.round(m.t * 1e9).astype(np.int64)
    if (s < 0).any():
        raise BagError(out, "negative stamps (time column before the start time)")
    per_topic = [(TOPIC_JOINT_STATES, s, cdr.encode_jointstate(
        JS_LAYOUT, s, np.stack([m.theta_m, m.theta_f], 1), np.stack([m.omega_m, m.omega_f], 1),
        np.stack([m.tau_m, m.Q_red], 1)))]
    if len(m.t_cmd):
        sc = m.t0_ns + np.round(m.t_cmd * 1e9).astype(np.int64)
        per_topic.append((TOPIC_COMMAND, sc, cdr.encode_jointstate(CMD_LAYOUT, sc, m.theta_ref[:, None])))
    for fr, (tt, vv) in m.temperatures.items():
        st = m.t0_ns + np.round(tt * 1e9).astype(np.int64)
        per_topic.append((TOPIC_TEMPERATURE, st, cdr.encode_temperature(fr, st, vv)))
    lo, hi = int(s.min()), int(s.max())
    edges = lo + 1_000_000_000 * np.arange(1, (hi - lo) // 1_000_000_000 + 1, dtype=np.int64)
    with MissionWriter(out, m.meta) as w:
        w.write_windowed(per_topic, edges)


def import_csv(csv_path: str | os.PathLike, mapping: str | os.PathLike | Mapping[str, Any],
               out: str | os.PathLike, meta_overrides: Mapping[str, Any] | None = None) -> str:
    """Convert one CSV log into a contract bag at ``out`` (a file, or a directory: ``<stem>.mcap``)."""
    out = os.fspath(out)
    if os.path.isdir(out):
        out = os.path.join(out, Path(csv_path).stem + ".mcap")
    m = mission_from_csv(csv_path, mapping, meta_overrides)
    _write_raw(out, m)
    return out
