"""The robustness matrix of ``docs/ROBUSTNESS.md``: every foreign variant x every per-bag command.

    .venv/bin/python -m tests.robustness.matrix OUT_DIR [MODEL_DIR]

writes the variants under ``OUT_DIR/bags`` (``foreign.write_all``), trains a
tiny twin on three other foreign bags when no ``MODEL_DIR`` is given, runs
``validate``, ``inspect``, ``twin eval``, ``discover`` and ``onboard eval`` on
each bag in this process (``hdphm.cli.main``) and prints a Markdown table:
exit status plus the key figure or the first words of the error / note.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
from pathlib import Path

from hdphm.cli import main
from tests.robustness import foreign as FB


def _run(argv: list[str]) -> tuple[int, str, str]:
    o, e = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
        try:
            rc = main(argv)
        except Exception as ex:  # a traceback would be a finding: record it instead of stopping
            return 99, "", f"UNCAUGHT {type(ex).__name__}: {ex}"
    return rc, o.getvalue(), e.getvalue()


def _short(s: str, n: int = 70) -> str:
    s = " ".join(s.split()).replace("|", "/")
    return s if len(s) <= n else s[: n - 1] + "…"


def _last_error(err: str) -> str:
    lines = [ln for ln in err.splitlines() if "error" in ln.lower()]
    return _short(lines[-1].split("error:", 1)[-1] if lines else err.strip().splitlines()[-1] if err.strip() else "")


def cell_validate(p: str) -> str:
    rc, out, _ = _run(["validate", p])
    errs = [ln for ln in out.splitlines() if ": error:" in ln]
    if errs:
        return f"rc {rc}: {_short(errs[0].split(': error: ', 1)[1], 60)}"
    sus = [ln for ln in out.splitlines() if ": warning:" in ln and "anti-correlated" in ln]  # suspect, a warning
    return f"rc {rc}" + (f", warning: {_short(sus[0].split(': warning: ', 1)[1], 50)}" if sus else "")


def cell_eval(model: str, p: str) -> str:
    rc, out, err = _run(["twin", "eval", model, p])
    if rc != 0:
        return f"rc {rc}: {_last_error(err)}"
    m = json.loads(out)
    note = ""
    if m.get("out_of_range"):
        note = "; out of range: " + ",".join(m["out_of_range"])
    if any("gear ratio" in s for s in m.get("notes", [])):
        note += "; note: other N"
    if any("suspect data" in s for s in m.get("notes", [])):
        note += "; note: suspect data"
    for s in m.get("notes", []):
        if "not available" in s:
            note += "; note: no " + s.split("[", 1)[1].split("]", 1)[0].replace("'", "")
    return f"rc 0, R² {m['r2']:.2f}{note}"


def cell_discover(p: str, out: Path) -> str:
    rc, _, err = _run(["discover", p, "--out", str(out), "--no-plots"])
    if rc != 0:
        return f"rc {rc}: {_last_error(err)}"
    rep = json.loads((out / "report.json").read_text())
    conf = sum(1 for e in rep.get("effects", []) if e.get("confirmed", True))
    unc = len(rep.get("effects", [])) - conf
    ident = [s["signal"] for s in rep["signals"] if s["identifiable"]]
    return f"rc 0, {conf} found" + (f", {unc} unconfirmed" if unc else "") + \
        (f" ({'/'.join(ident)})" if ident else " (too little data)")


def cell_onboard(p: str) -> str:
    rc, out, err = _run(["onboard", "eval", p, "--quiet"])
    if rc != 0:
        return f"rc {rc}: {_last_error(err)}"
    line = next((ln for ln in out.splitlines() if ln.startswith(p)), "")
    return "rc 0, " + _short(line.split(":", 1)[-1], 50)


def matrix(out_dir: str | Path, model: str | None = None) -> str:
    out_dir = Path(out_dir)
    bags = FB.write_all(out_dir / "bags")
    if model is None:
        d = out_dir / "train"
        for k, (name, seed) in enumerate((("rosbags", 1), ("lz4", 2), ("unchunked", 3))):
            FB.write_variant(d, FB.replace(FB.VARIANTS[name], name=f"t{k}"), seed=seed, mission_index=k)
        model = str(out_dir / "model")
        rc, _, err = _run(["train", "--preset", "tiny", "--bags", str(d), "--epochs", "3", "--threads", "1",
                           "--out", model])
        if rc != 0:
            raise SystemExit(f"training failed: {err}")
    rows = ["| variant | what | validate | twin eval (tiny twin, 1 kHz, N = 101) | discover | onboard eval |",
            "|---|---|---|---|---|---|"]
    for i, (name, p) in enumerate(bags.items()):
        print(f"  {i + 1}/{len(bags)} {name}", file=sys.stderr, flush=True)
        v = FB.VARIANTS[name]
        rows.append(f"| `{name}` | {v.doc} | {cell_validate(str(p))} | {cell_eval(model, str(p))} | "
                    f"{cell_discover(str(p), out_dir / 'disc' / name)} | {cell_onboard(str(p))} |")
    return "\n".join(rows)


if __name__ == "__main__":  # pragma: no cover
    import torch

    torch.set_num_threads(1)
    print(matrix(sys.argv[1] if len(sys.argv) > 1 else "runs/robustness", sys.argv[2] if len(sys.argv) > 2 else None))
