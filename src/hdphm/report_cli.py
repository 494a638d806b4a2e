"""``hdphm report``: a self-contained HTML page of a run folder, discovery output or fleet store."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def _run(args) -> int:
    from hdphm.report import write_report

    out = Path(args.out) if args.out else Path(args.run) / "report.html"
    path = write_report(args.run, out, title=args.title)
    size = path.stat().st_size
    if args.json:
        print(json.dumps({"report": str(path), "bytes": size}))
    elif not args.quiet:
        print(f"hdphm report: wrote {path} ({size / 1e6:.1f} MB, self-contained: open it in any browser, offline)")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="one self-contained HTML page of a run (demo folder, discovery output, fleet store)")
    p.add_argument("run", help="a run folder (hdphm demo --out), a discovery output folder or a fleet store")
    p.add_argument("--out", default=None, help="HTML file to write (default RUN/report.html)")
    p.add_argument("--title", default=None, help="page title")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.add_argument("--json", action="store_true", help="print the result as one JSON line (for scripts)")
    p.set_defaults(func=_run)
