"""``hdphm validate``, ``hdphm import-csv`` and ``hdphm inspect``."""

from __future__ import annotations

import argparse
import sys


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="check bags against the contract; exit 1 on any error",
                       description="Check MCAP bags against ../shared/CONTRACT.md. Prints every violation "
                                   "as FILE TOPIC [INDEX]: severity: problem. Exit status 1 when any bag has an "
                                   "error (or a warning with --strict).")
    p.add_argument("bags", nargs="+", metavar="BAG", help="MCAP files or directories of them")
    p.add_argument("--strict", action="store_true", help="warnings fail too")
    p.add_argument("--max-per-problem", type=int, default=0, metavar="K",
                   help="print at most K sample-level lines per problem (0 = all), then a count")
    p.add_argument("-q", "--quiet", action="store_true", help="print errors only, no warnings or OK lines")
    p.set_defaults(func=_validate)

    p = sub.add_parser("import-csv", help="CSV log -> contract bag",
                       description="Convert CSV logs into contract bags. The mapping comes from --mapping "
                                   "(a YAML file or a shipped name: harivin_friction_sweep, "
                                   "harivin_breakaway_ramp) and/or flags.")
    p.add_argument("csv", nargs="+", metavar="CSV")
    p.add_argument("--mapping", metavar="YAML|NAME")
    p.add_argument("--time", metavar="COLUMN[:UNIT]", help="time column (default unit s)")
    p.add_argument("--col", action="append", default=[], metavar="NAME=COLUMN[:UNIT]",
                   help="map a contract signal (theta_m, theta_f, omega_m, omega_f, tau_m, Q_red, theta_ref, "
                        "temperature.gearbox, temperature.motor_winding) to a column; NAME=N*OTHER derives "
                        "it as gear ratio times another signal; NAME=nan writes NaN")
    p.add_argument("--unit", action="append", default=[], metavar="NAME=UNIT", help="unit of a mapped column")
    p.add_argument("--meta", action="append", default=[], metavar="KEY=VALUE", help="hd_mission metadata")
    p.add_argument("--start-time", metavar="filename|ISO|NS", help="absolute time of t = 0")
    p.add_argument("--out", required=True, metavar="BAG_OR_DIR")
    p.set_defaults(func=_import_csv)

    p = sub.add_parser("bag", help="bag file tools (recover: finalise a recording cut short)")
    bsub = p.add_subparsers(dest="bag_command", metavar="BAGCOMMAND")
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])
    pr = bsub.add_parser("recover", help="finalised copy of an MCAP without summary/footer (recorder killed)",
                         description="Copy every complete chunk of an MCAP file that ends without its summary and "
                                     "footer (a recorder killed by SIGKILL or a power cut) into a new, finalised "
                                     "file that any MCAP reader opens. Damaged records are skipped and reported.")
    pr.add_argument("bag", metavar="BAG")
    pr.add_argument("--out", default=None, help="output file (default: BAG with .recovered.mcap)")
    pr.set_defaults(func=_recover)

    p = sub.add_parser("inspect", help="topics, counts, rates, duration, metadata and read report of a bag")
    p.add_argument("bags", nargs="+", metavar="BAG")
    p.set_defaults(func=_inspect)


def _expand(paths: list[str]) -> list[str]:
    import glob
    import os

    out = []
    for p in paths:
        if os.path.isdir(p):
            out += sorted(glob.glob(os.path.join(p, "**", "*.mcap"), recursive=True))
        else:
            out.append(p)
    return out


def _validate(args) -> int:
    from hd_bag import validate_bag

    bags = _expand(args.bags)
    if not bags:
        print("no bags found", file=sys.stderr)
        return 2
    n_bad = 0
    failed: set[str] = set()
    for b in bags:
        vs = validate_bag(b)
        errs = [v for v in vs if v.severity == "error"]
        fail = bool(errs) or (args.strict and vs)
        n_bad += bool(fail)
        if fail:
            failed.add(b)
        shown: dict[tuple, int] = {}
        hidden: dict[tuple, int] = {}
        for v in vs:
            if args.quiet and v.severity != "error":
                continue
            key = (v.topic, v.problem, v.severity)
            if v.index is not None and args.max_per_problem:
                if shown.get(key, 0) >= args.max_per_problem:
                    hidden[key] = hidden.get(key, 0) + 1
                    continue
                shown[key] = shown.get(key, 0) + 1
            print(v)
        for (topic, problem, sev), k in hidden.items():
            print(f"{b} {topic}: {sev}: ... {k} more samples: {problem}")
        if not fail and not args.quiet:
            print(f"{b}: OK ({len(vs)} warnings)" if vs else f"{b}: OK")
    if len(bags) > 1:  # across bags: hours per actuator never decrease, mission indices do not repeat
        seq = _mission_sequence(bags)
        for v in seq:
            print(v)
        n_bad += len({v.file for v in seq} - failed)
    if len(bags) > 1 and not args.quiet:
        print(f"{max(len(bags) - n_bad, 0)}/{len(bags)} bags pass")
    return 1 if n_bad else 0


def _recover(args) -> int:
    import os

    from hd_bag.mcapio import McapFormatError, recover_mcap

    out = args.out or (os.path.splitext(args.bag)[0] + ".recovered.mcap")
    try:
        r = recover_mcap(args.bag, out)
    except (McapFormatError, ValueError, OSError) as e:
        print(f"hdphm bag recover: {args.bag}: {e}", file=sys.stderr)
        return 2
    for i in r["issues"]:
        print(f"{args.bag}: {i}", file=sys.stderr)
    print(f"{args.bag} -> {out}: {r['messages']} messages in {r['chunks']} chunks"
          + (" (the input was already complete)" if r["complete_before"] else ""))
    return 0


def _mission_sequence(bags: list[str]):
    """check_mission_sequence over the bags whose hd_mission metadata parses."""
    import math
    from types import SimpleNamespace

    from hd_bag import BagError, read_metadata
    from hd_bag.reader import check_mission_sequence

    metas = []
    for b in bags:
        try:
            md = read_metadata(b).get("hd_mission") or {}
            m = SimpleNamespace(actuator_id=md["actuator_id"], mission_index=int(md["mission_index"]),
                                operating_hours=float(md["operating_hours"]))
        except (BagError, ValueError, KeyError, OSError):
            continue  # the per-bag validation already reported it
        if math.isfinite(m.operating_hours):
            metas.append((b, m))
    return check_mission_sequence(metas)


def _split_kv(s: str, what: str) -> tuple[str, str]:
    if "=" not in s:
        raise SystemExit(f"{what} {s!r}: expected KEY=VALUE")
    k, v = s.split("=", 1)
    return k.strip(), v.strip()


def build_mapping(args) -> dict:
    """Mapping dict from --mapping plus flag overrides."""
    from hd_bag.csv_import import load_mapping

    mp = load_mapping(args.mapping) if args.mapping else {}
    mp = {k: (dict(v) if isinstance(v, dict) else v) for k, v in mp.items()}
    units = dict(_split_kv(u, "--unit") for u in args.unit)
    if args.time:
        col, _, unit = args.time.partition(":")
        mp["time"] = {"column": col, "unit": unit or "s"}
    for c in args.col:
        name, spec = _split_kv(c, "--col")
        if spec.lower() == "nan":
            entry = "nan"
        elif spec.startswith("N*"):
            entry = {"from": spec[2:], "times": "gear_ratio"}
        else:
            col, _, unit = spec.partition(":")
            entry = {"column": col}
            if unit or name in units:
                entry["unit"] = unit or units[name]
        if name == "theta_ref":
            mp.setdefault("command", {})["theta_ref"] = entry
        elif name.startswith("temperature."):
            mp.setdefault("temperature", {})[name.split(".", 1)[1]] = entry
        else:
            mp.setdefault("signals", {})[name] = entry
    for name, unit in units.items():
        for sect in ("signals", "command", "temperature"):
            key = name.split(".", 1)[1] if name.startswith("temperature.") else name
            e = (mp.get(sect) or {}).get(key)
            if isinstance(e, dict) and "column" in e:
                e["unit"] = unit
    if args.start_time:
        mp["start_time"] = int(args.start_time) if args.start_time.isdigit() else args.start_time
    return mp


def _import_csv(args) -> int:
    import os

    from hd_bag import BagError, read_mission
    from hd_bag.csv_import import import_csv

    mp = build_mapping(args)
    meta = dict(_split_kv(m, "--meta") for m in args.meta)
    if len(args.csv) > 1 and not os.path.isdir(args.out):
        os.makedirs(args.out, exist_ok=True)
    rc = 0
    for path in args.csv:
        try:
            out = import_csv(path, mp, args.out, meta)
            m = read_mission(out)
        except (BagError, FileNotFoundError) as e:
            print(f"error: {e}", file=sys.stderr)
            rc = 1
            continue
        print(f"{path} -> {out}: {m.n} samples, {m.duration:.2f} s at {m.fs:.4g} Hz, "
              f"{len(m.report.gaps)} gaps")
    return rc


def _inspect(args) -> int:
    from hd_bag import BagError, bag_summary, read_mission

    rc = 0
    for b in _expand(args.bags):
        try:
            s = bag_summary(b)
        except BagError as e:
            print(f"error: {e}", file=sys.stderr)
            rc = 1
            continue
        print(f"{b}  (profile {s['profile']!r}, written by {s['library']!r}"
              f"{'' if s['complete'] else ', INCOMPLETE'})")
        for topic, d in s["topics"].items():
            print(f"  {topic:22s} {d['type']:30s} {d['count']:8d} msgs  {d['rate_hz']:10.2f} Hz  "
                  f"{d['duration_s']:9.3f} s")
        for name, md in s["metadata"].items():
            print(f"  metadata {name}:")
            for k, v in md.items():
                lines = str(v).splitlines() or [""]
                # a foreign tool's record may hold a whole document (rosbags: 'rosbag2' YAML): first line only
                print(f"    {k} = {lines[0]}" + (f"  ... ({len(lines)} lines)" if len(lines) > 1 else ""))
        for i in s["issues"]:
            print(f"  issue: {i}")
        try:
            m = read_mission(b)
            print("  " + m.report.summary().replace("\n", "\n  "))
        except BagError as e:
            print(f"  not readable as a mission: {e.problem}")
            rc = 1
    return rc
