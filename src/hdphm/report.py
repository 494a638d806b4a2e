"""``hdphm report``: one self-contained HTML page of a run (demo folder, discovery output or fleet store).

The page needs no network: Plotly's JavaScript is embedded once, every figure is a Plotly div (interactive
where it helps: life plots, flags) and the PNG figures the run already made (twin Figs. 4-7, discovery
plots) are embedded as base64 images. Sections:

- fleet table: actuator, role (training / held out), missions, health, RUL P5/P50/P95, risk, flags,
  suspected fault;
- per actuator with a prognosis: health indicator and RUL over life, the alpha-lambda cone where the
  end of life is known (simulated fleets: ``fleet_truth.json``, or an events file's failures), flags
  timeline, recalibration history (the ground node's reports, read from the recorded stack MCAPs);
- twin fit (the model folder's figures and validation metrics);
- discovery reports found under the run (residual before/after, order spectrum, found terms, error table);
- the run's settings and the package versions.

Everything is read from files the commands already write; a missing part is said on the page, never
an error (a fleet store without twin figures is still a fleet page).

The page sets ``data-hdphm-plots`` on ``<body>`` to the number of Plotly figures that rendered and
``data-hdphm-errors`` to the JavaScript errors seen, so a headless browser can check it
(``tests/hdphm/test_report_browser.py``).
"""

from __future__ import annotations

import base64
import html
import json
import math
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

# Size caps: a report is for people, not an archive (a hostile or huge run folder cannot make it unbounded).
MAX_JSON_BYTES = 64 * 1024 * 1024
MAX_PNG_BYTES = 8 * 1024 * 1024
MAX_ACTUATORS_DETAILED = 50


# --------------------------------------------------------------------------
# reading a run folder
# --------------------------------------------------------------------------
def _read_json(path: Path) -> Any | None:
    """JSON content or None when absent; a file too big or not JSON raises ValueError naming it."""
    if not path.is_file():
        return None
    from hd_bag.files import read_json

    return read_json(path, "a report input", max_bytes=MAX_JSON_BYTES)


def _finite(x) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


@dataclass
class ActuatorView:
    actuator_id: str
    role: str = ""
    missions: int = 0
    eol_mission: float | None = None
    rul_history: dict | None = None
    health_history: list[dict] = field(default_factory=list)
    last_health: dict = field(default_factory=dict)
    flags: list[dict] = field(default_factory=list)
    recalibrations: list[dict] = field(default_factory=list)
    suspected_fault: str = ""
    fault_probabilities: dict = field(default_factory=dict)


@dataclass
class RunView:
    """Everything the page shows, gathered from a run folder (or a fleet store)."""

    root: Path
    kind: str
    settings: dict = field(default_factory=dict)
    actuators: dict[str, ActuatorView] = field(default_factory=dict)
    twin_dirs: list[Path] = field(default_factory=list)
    discoveries: list[tuple[Path, dict]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    scores: dict = field(default_factory=dict)


def _actuator(view: RunView, aid: str) -> ActuatorView:
    if aid not in view.actuators:
        view.actuators[aid] = ActuatorView(aid)
    return view.actuators[aid]


def _ground_reports(stack_dir: Path, limit: int = 2000) -> list[dict]:
    """The ground node's JSON reports from the recorded stack MCAPs (std_msgs/String on /hd/ground/report),
    decoded by the bag layer's reader (its size caps and fixed type table apply)."""
    from hd_bag.reader import iter_messages

    out: list[dict] = []
    for p in sorted(stack_dir.glob("*.mcap")):
        try:
            for _topic, _stamp, _log, msg in iter_messages(p, topics=["/hd/ground/report"], ros=False):
                try:
                    out.append(json.loads(msg.data))
                except (AttributeError, TypeError, json.JSONDecodeError):
                    continue
                if len(out) >= limit:
                    return out
        except Exception as e:  # noqa: BLE001 - a damaged recording loses its reports on the page, not the page
            out.append({"_error": f"{p.name}: {type(e).__name__}: {e}"})
    return out


def _recalibrations_from(reports: list[dict]) -> dict[str, list[dict]]:
    """Per actuator, one row per ground analysis that recalibrated: the report's ``recalibration``
    (one least-squares fit over the healthy missions of every actuator in that analysis: estimates,
    rms before/after) attributed to each actuator the analysis covered."""
    per: dict[str, list[dict]] = {}
    for i, rep in enumerate(reports):
        if not isinstance(rep, dict):
            continue
        acts = rep.get("actuators")
        rec = rep.get("recalibration")
        if not isinstance(acts, dict) or not isinstance(rec, dict) or "estimates" not in rec:
            continue
        row: dict[str, Any] = {"analysis": i}
        est = rec.get("estimates")
        if isinstance(est, dict):
            for k, v in est.items():
                fv = _finite(v)
                if fv is not None:
                    row[k] = fv
        for k in ("rms_before", "rms_after"):
            fv = _finite(rec.get(k))
            if fv is not None:
                row[k] = fv
        for aid, a in acts.items():
            per.setdefault(str(aid), []).append({**row, "missions": len(a.get("missions") or [])
                                                 if isinstance(a, dict) else 0})
    return per


def _find_discoveries(root: Path) -> list[tuple[Path, dict]]:
    found = []
    for p in sorted(root.rglob("report.json"))[:20]:
        try:
            d = _read_json(p)
        except ValueError:
            continue
        if isinstance(d, dict) and ("effects" in d or "candidates" in d) and "held_out_actuator" not in d:
            found.append((p.parent, d))
    return found


def _suspected_from_flags(flags: list[dict]) -> str:
    if not flags:
        return "none flagged"
    reasons = " ".join(str(f.get("reason", "")) for f in flags).lower()
    for key, name in (("friction", "lubrication loss?"), ("stiff", "flexspline stiffness loss?"),
                      ("twist", "stiffness / lost motion?"), ("q_red", "torque path anomaly?")):
        if key in reasons:
            return name
    return "unknown"


def load_demo_run(root: Path) -> RunView:
    rep = _read_json(root / "report.json") or {}
    view = RunView(root=root, kind="demo run")
    view.settings = {k: rep.get(k) for k in ("held_out_actuator", "training_actuators", "wall_s") if k in rep}
    view.settings.update(rep.get("settings") or {})
    view.scores = rep.get("rul_score") or {}
    truth = _read_json(root / "fleet" / "fleet_truth.json") or {}
    for a in truth.get("actuators", []) if isinstance(truth, dict) else []:
        av = _actuator(view, str(a.get("actuator_id")))
        av.eol_mission = _finite(a.get("eol_mission"))
        av.missions = len(a.get("missions") or [])
    fleet = root / "fleet"
    if fleet.is_dir():
        for d in sorted(p for p in fleet.iterdir() if p.is_dir()):
            av = _actuator(view, d.name)
            av.missions = max(av.missions, len(list(d.glob("*.mcap"))))
    held = rep.get("held_out_actuator")
    for aid in rep.get("training_actuators") or []:
        _actuator(view, str(aid)).role = "training"
    if held:
        _actuator(view, str(held)).role = "held out"
    for p in sorted(root.glob("rul_history_*.json")):
        aid = p.stem[len("rul_history_"):]
        _actuator(view, aid).rul_history = _read_json(p)
    summ = _read_json(root / "stack_summary.json") or {}
    for f in summ.get("flags") or []:
        _actuator(view, str(f.get("actuator", held or "unknown"))).flags.append(f)
    for aid, rows in (summ.get("health_history") or {}).items():
        _actuator(view, str(aid)).health_history = [r for r in rows if isinstance(r, dict)]
    for src in ((rep.get("stack") or {}).get("health") or {}, summ.get("health") or {}):
        for aid, h in src.items():
            if isinstance(h, dict):
                _actuator(view, str(aid)).last_health.update(h)
    if not summ:
        view.notes.append("no stack_summary.json in this run (written by hdphm demo since this version): "
                          "flags timeline and node health history are not shown")
    for sd in sorted(root.glob("stack_*")):
        if sd.is_dir():
            for aid, rows in _recalibrations_from(_ground_reports(sd)).items():
                _actuator(view, aid).recalibrations.extend(rows)
    for av in view.actuators.values():
        av.suspected_fault = _suspected_from_flags(av.flags) if av.role == "held out" else ""
    if (root / "twin" / "config.json").is_file():
        view.twin_dirs.append(root / "twin")
    view.discoveries = _find_discoveries(root)
    return view


def load_store(root: Path) -> RunView:
    """A fleet store (``hdphm ground fleet --store``), read through its DuckDB views."""
    view = RunView(root=root, kind="fleet store")
    try:
        from hd_ground.fleet.run import fleet_status
        from hd_ground.fleet.store import FleetStore
    except ImportError as e:  # duckdb / pyarrow missing
        view.notes.append(f"the fleet store cannot be read here ({e})")
        return view
    classes = ("healthy", "tooth_wear", "lubrication_loss", "flexspline_stiffness_loss", "unknown")
    for row in fleet_status(str(root)):
        av = _actuator(view, str(row.get("actuator_id")))
        av.missions = int(row.get("missions") or 0)
        av.last_health = {"h_mean": row.get("h_mean"), "rul_p5": row.get("rul_p5"), "rul_p50": row.get("rul_p50"),
                          "rul_p95": row.get("rul_p95")}
        probs = {c: row.get(f"p_{c}") for c in classes if _finite(row.get(f"p_{c}")) is not None}
        av.fault_probabilities = probs
        av.suspected_fault = str(row.get("label") or "")
    store = FleetStore(root)
    try:
        cols, rows = store.query("SELECT actuator_id, mission_index, rul_p5, rul_p50, rul_p95, h_mean FROM rul "
                                 "ORDER BY actuator_id, mission_index")
    except ValueError as e:  # no RUL computed yet in this store
        rows = []
        view.notes.append(f"no RUL history in the store yet ({str(e)[:200]})")
    per: dict[str, list[tuple]] = {}
    for r in rows:
        per.setdefault(str(r[0]), []).append(r)
    for aid, rs in per.items():
        av = _actuator(view, aid)
        av.rul_history = {"rul_t": [r[1] for r in rs], "p5": [r[2] for r in rs], "p50": [r[3] for r in rs],
                          "p95": [r[4] for r in rs], "t": [r[1] for r in rs], "time_unit": "missions"}
        av.health_history = [{"mission_index": r[1], "h_mean": r[5]} for r in rs]
    try:
        cols, rows = store.query("SELECT actuator_id, mission_index, name, level FROM events WHERE kind = 'flag' "
                                 "ORDER BY actuator_id, mission_index LIMIT 100000")
        for aid, mi, name, level in rows:
            _actuator(view, str(aid)).flags.append({"stamp_s": mi, "level": int(level or 1),
                                                   "reason": f"mission {mi}: {name}"})
    except Exception as e:  # noqa: BLE001 - an older store without flag events: the page says so
        view.notes.append(f"flags not read from the store: {e}")
    view.settings = {"store": str(root)}
    return view


def load_run(path: str | Path) -> RunView:
    root = Path(path)
    if not root.exists():
        raise FileNotFoundError(f"{root}: no such run folder or fleet store")
    if root.is_file():
        raise ValueError(f"{root}: expected a run folder (hdphm demo --out), a discovery output or a fleet store, "
                         "got a file")
    if (root / "fleet.duckdb").exists() or ((root / "data").is_dir() and not (root / "report.json").exists()):
        return load_store(root)
    if (root / "report.json").is_file() and "held_out_actuator" in (_read_json(root / "report.json") or {}):
        return load_demo_run(root)
    view = RunView(root=root, kind="folder")
    view.discoveries = _find_discoveries(root)
    for p in sorted(root.glob("rul_history_*.json")):
        _actuator(view, p.stem[len("rul_history_"):]).rul_history = _read_json(p)
    if (root / "config.json").is_file() and (root / "model.onnx").is_file():
        view.twin_dirs.append(root)
    if not (view.discoveries or view.actuators or view.twin_dirs):
        raise ValueError(f"{root}: nothing to report (no demo report.json, discovery report, RUL history, "
                         "twin model folder or fleet store found)")
    return view


# --------------------------------------------------------------------------
# rendering
# --------------------------------------------------------------------------
def _esc(x) -> str:
    return html.escape(str(x), quote=True)


def _num(x, fmt="{:.3g}") -> str:
    v = _finite(x)
    return fmt.format(v) if v is not None else "–"


def _png_tag(path: Path, alt: str) -> str:
    try:
        size = path.stat().st_size
    except OSError:
        return ""
    if size > MAX_PNG_BYTES:
        return f"<p class=note>{_esc(path.name)}: {size} bytes, not embedded (cap {MAX_PNG_BYTES})</p>"
    b64 = base64.b64encode(path.read_bytes()).decode("ascii")
    return (f'<figure><img alt="{_esc(alt)}" src="data:image/png;base64,{b64}">'
            f"<figcaption>{_esc(path.name)}</figcaption></figure>")


class _Figs:
    """Collects Plotly figures as divs (no JS inside); the page embeds plotly.js once."""

    def __init__(self):
        self.n = 0

    def div(self, fig) -> str:
        self.n += 1
        return fig.to_html(full_html=False, include_plotlyjs=False, div_id=f"hdphm-fig-{self.n}",
                           config={"displaylogo": False, "responsive": True})


def _life_figure(av: ActuatorView, alpha: float = 0.2):
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    rh = av.rul_history or {}
    hh = av.health_history
    fig = make_subplots(rows=1, cols=2, subplot_titles=("health indicator and estimated state over life", "RUL over life"),
                        specs=[[{"secondary_y": True}, {}]])
    t = [_finite(x) for x in rh.get("t") or []]
    z = [_finite(x) for x in rh.get("z") or []]
    if t and z:
        fig.add_trace(go.Scatter(x=t, y=z, mode="markers", name="observation (HI)", marker={"size": 4}), 1, 1)
    if rh.get("state_mean"):
        sm = rh["state_mean"]
        col0 = [(_finite(r[0]) if isinstance(r, list) else _finite(r)) for r in sm]
        fig.add_trace(go.Scatter(x=t, y=col0, mode="lines", name="filtered state (mean, right axis)"), 1, 1,
                      secondary_y=True)
    if hh:
        x = [_finite(r.get("mission_index")) for r in hh]
        y = [_finite(r.get("h_mean")) for r in hh]
        fig.add_trace(go.Scatter(x=x, y=y, mode="lines", name="node: h_mean (right axis)", line={"dash": "dot"}), 1, 1,
                      secondary_y=True)
    rt = [_finite(x) for x in rh.get("rul_t") or []]
    if rt:
        p5 = [_finite(x) for x in rh.get("p5") or []]
        p50 = [_finite(x) for x in rh.get("p50") or []]
        p95 = [_finite(x) for x in rh.get("p95") or []]
        fig.add_trace(go.Scatter(x=rt, y=p95, mode="lines", line={"width": 0}, showlegend=False, name="P95"), 1, 2)
        fig.add_trace(go.Scatter(x=rt, y=p5, mode="lines", line={"width": 0}, fill="tonexty",
                                 fillcolor="rgba(31,119,180,0.25)", name="P5-P95"), 1, 2)
        fig.add_trace(go.Scatter(x=rt, y=p50, mode="lines+markers", name="RUL P50", marker={"size": 4}), 1, 2)
        if av.eol_mission is not None:
            eol = av.eol_mission
            xs = [x for x in rt if x is not None and x <= eol]
            if xs:
                true = [eol - x for x in xs]
                fig.add_trace(go.Scatter(x=xs, y=true, mode="lines", name="true RUL", line={"color": "black"}), 1, 2)
                fig.add_trace(go.Scatter(x=xs, y=[(1 + alpha) * r for r in true], mode="lines",
                                         line={"color": "gray", "dash": "dash"}, name=f"alpha = {alpha} cone"), 1, 2)
                fig.add_trace(go.Scatter(x=xs, y=[(1 - alpha) * r for r in true], mode="lines",
                                         line={"color": "gray", "dash": "dash"}, showlegend=False), 1, 2)
    unit = rh.get("time_unit") or "missions"
    fig.update_xaxes(title_text=f"time ({unit})")
    fig.update_yaxes(title_text="health indicator", row=1, col=1, secondary_y=False)
    fig.update_yaxes(title_text="state", row=1, col=1, secondary_y=True)
    fig.update_yaxes(title_text=f"RUL ({unit})", row=1, col=2)
    fig.update_layout(height=380, margin={"l": 50, "r": 20, "t": 40, "b": 40}, legend={"orientation": "h"})
    return fig


def _flags_figure(av: ActuatorView):
    import plotly.graph_objects as go

    xs = [_finite(f.get("stamp_s")) for f in av.flags]
    ys = [int(f.get("level", 0)) for f in av.flags]
    txt = [str(f.get("reason", ""))[:200] for f in av.flags]
    fig = go.Figure(go.Scatter(x=xs, y=ys, mode="markers", text=txt, hoverinfo="x+y+text",
                               marker={"size": 9, "color": ys, "colorscale": [[0, "orange"], [1, "red"]],
                                       "cmin": 1, "cmax": 2}))
    fig.update_layout(height=220, margin={"l": 50, "r": 20, "t": 30, "b": 40}, title="fault flags (1 WARN, 2 ERROR)",
                      xaxis_title="sample time (s)", yaxis={"tickvals": [1, 2], "ticktext": ["WARN", "ERROR"],
                                                            "range": [0.5, 2.5]})
    return fig


def _recal_figure(av: ActuatorView):
    import plotly.graph_objects as go

    keys = sorted({k for r in av.recalibrations for k in r if k not in ("analysis", "missions")})[:8]
    fig = go.Figure()
    for k in keys:
        fig.add_trace(go.Scatter(x=[r["analysis"] for r in av.recalibrations if k in r],
                                 y=[r[k] for r in av.recalibrations if k in r], mode="lines+markers", name=k))
    fig.update_layout(height=260, margin={"l": 50, "r": 20, "t": 30, "b": 40},
                      title="recalibration history (each ground analysis: one fit over the analysed actuators)",
                      xaxis_title="ground analysis #")
    return fig


def _discovery_figure(d: dict):
    import plotly.graph_objects as go

    rows = []
    for e in d.get("effects") or []:
        if isinstance(e, dict):
            rows.append((str(e.get("name", "?")), _finite(e.get("explained")) or 0.0))
    if not rows:
        return None
    fig = go.Figure(go.Bar(x=[r[0] for r in rows], y=[r[1] for r in rows]))
    fig.update_layout(height=260, margin={"l": 50, "r": 20, "t": 30, "b": 60},
                      title="found effects: share of held-out residual explained", yaxis_title="explained")
    return fig


def _fleet_table(view: RunView) -> str:
    head = ("<tr><th>actuator</th><th>role</th><th>missions</th><th>health</th><th>RUL P5</th><th>RUL P50</th>"
            "<th>RUL P95</th><th>risk</th><th>flags</th><th>suspected fault</th></tr>")
    rows = []
    for aid in sorted(view.actuators):
        av = view.actuators[aid]
        h = dict(av.last_health)
        rh = av.rul_history or {}
        if rh.get("p50"):
            h.setdefault("rul_p5", rh["p5"][-1])
            h.setdefault("rul_p50", rh["p50"][-1])
            h.setdefault("rul_p95", rh["p95"][-1])
        health = h.get("health_index", h.get("h_mean", h.get("health")))
        fault = av.suspected_fault
        if av.fault_probabilities:
            best = max(av.fault_probabilities.items(), key=lambda kv: _finite(kv[1]) or 0.0)
            fault = f"{best[0]} ({_num(best[1], '{:.2f}')})"
        rows.append(f"<tr><td><a href='#act-{_esc(aid)}'>{_esc(aid)}</a></td><td>{_esc(av.role)}</td>"
                    f"<td>{av.missions}</td><td>{_num(health)}</td><td>{_num(h.get('rul_p5'), '{:.1f}')}</td>"
                    f"<td>{_num(h.get('rul_p50'), '{:.1f}')}</td><td>{_num(h.get('rul_p95'), '{:.1f}')}</td>"
                    f"<td>{_num(h.get('risk'), '{:.2f}')}</td><td>{len(av.flags)}</td><td>{_esc(fault)}</td></tr>")
    return f"<table class=fleet>{head}{''.join(rows)}</table>"


def _versions() -> dict:
    out = {"python": platform.python_version(), "platform": platform.platform()}
    from importlib import metadata

    for pkg in ("hdphm", "numpy", "torch", "onnxruntime", "mcap", "plotly"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            pass
    return out


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:24px;color:#222;max-width:1400px}
h1{font-size:1.5em}h2{border-bottom:1px solid #ccc;padding-bottom:4px;margin-top:32px}
table{border-collapse:collapse;margin:8px 0}td,th{border:1px solid #ddd;padding:4px 8px;text-align:right}
th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}
figure{display:inline-block;margin:6px}figure img{max-width:640px;border:1px solid #eee}
.note{color:#8a5a00}.kv td{text-align:left}pre{background:#f7f7f7;padding:8px;overflow:auto;max-height:300px}
"""

_CHECK_JS = """
window.__hdphmErrors = window.__hdphmErrors || [];
window.addEventListener('error', function (e) { window.__hdphmErrors.push(String(e.message)); });
window.addEventListener('load', function () {
  var divs = document.querySelectorAll('div[id^="hdphm-fig-"]');
  var ok = 0;
  divs.forEach(function (d) { if (d.querySelector('svg.main-svg')) ok += 1; });
  document.body.setAttribute('data-hdphm-plots', ok + '/' + divs.length);
  document.body.setAttribute('data-hdphm-errors', String(window.__hdphmErrors.length));
  var s = document.getElementById('hdphm-status');
  if (s) s.textContent = ok + ' of ' + divs.length + ' plots rendered; ' + window.__hdphmErrors.length + ' script errors';
});
"""


def render(view: RunView, *, title: str | None = None) -> str:
    import plotly.offline

    figs = _Figs()
    parts: list[str] = []
    title = title or f"hdphm report: {view.root.name} ({view.kind})"
    parts.append(f"<h1>{_esc(title)}</h1><p>generated {_esc(time.strftime('%Y-%m-%d %H:%M:%S %Z'))} from "
                 f"<code>{_esc(view.root)}</code>. <span id=hdphm-status></span></p>")
    for n in view.notes:
        parts.append(f"<p class=note>{_esc(n)}</p>")
    if view.actuators:
        parts.append("<h2>Fleet</h2>" + _fleet_table(view))
    sc = view.scores
    if sc and "eol_mission" in sc:
        keys = [k for k in sorted(sc) if isinstance(sc[k], (int, float)) and not isinstance(sc[k], bool)]
        parts.append("<h3>RUL scores of the held-out actuator (against the simulator's truth; scoring only)</h3>"
                     "<table class=kv>" + "".join(f"<tr><td>{_esc(k)}</td><td>{_num(sc[k])}</td></tr>" for k in keys)
                     + "</table>")
    detailed = [av for av in view.actuators.values() if av.rul_history or av.flags or av.health_history
                or av.recalibrations][:MAX_ACTUATORS_DETAILED]
    for av in detailed:
        parts.append(f"<h2 id='act-{_esc(av.actuator_id)}'>Actuator {_esc(av.actuator_id)} "
                     f"<small>{_esc(av.role)}</small></h2>")
        if av.eol_mission is not None:
            parts.append(f"<p>end of life (truth, for scoring): mission {av.eol_mission:.0f}</p>")
        if av.rul_history or av.health_history:
            parts.append(figs.div(_life_figure(av)))
        if av.flags:
            parts.append(figs.div(_flags_figure(av)))
        else:
            parts.append("<p>no fault flags over this life (onboard flags are for abrupt faults; gradual wear is "
                         "the health and RUL above)</p>")
        if av.recalibrations:
            parts.append(figs.div(_recal_figure(av)))
    for td in view.twin_dirs:
        parts.append(f"<h2>Twin fit: <code>{_esc(td)}</code></h2>")
        met = _read_json(td / "metrics.json") or {}
        val = met.get("validation") if isinstance(met, dict) else None
        if isinstance(val, dict):
            parts.append("<table class=kv>" + "".join(
                f"<tr><td>{_esc(k)}</td><td>{_num(v)}</td></tr>" for k, v in val.items()
                if isinstance(v, (int, float))) + "</table>")
        for png in sorted(td.glob("*.png"))[:12]:
            parts.append(_png_tag(png, f"twin figure {png.stem}"))
    for ddir, d in view.discoveries:
        parts.append(f"<h2>Discovery: <code>{_esc(ddir)}</code></h2>")
        eff = [e for e in d.get("effects") or [] if isinstance(e, dict)]
        if eff:
            parts.append("<table><tr><th>effect</th><th>signal</th><th>explained (held out)</th><th>params</th></tr>"
                         + "".join(f"<tr><td>{_esc(e.get('name'))}</td><td>{_esc(e.get('signal', ''))}</td>"
                                   f"<td>{_num(e.get('explained'))}</td>"
                                   f"<td>{_esc(json.dumps(e.get('params', e.get('coefficients', {})), default=str)[:300])}"
                                   "</td></tr>" for e in eff) + "</table>")
        else:
            parts.append("<p>no effect found</p>")
        f = _discovery_figure(d)
        if f is not None:
            parts.append(figs.div(f))
        errs = d.get("errors") or d.get("error_table") or d.get("comparisons")
        if errs:
            parts.append("<pre>" + _esc(json.dumps(errs, indent=1, default=str)[:20000]) + "</pre>")
        for png in sorted(ddir.glob("*.png"))[:12]:
            parts.append(_png_tag(png, f"discovery figure {png.stem}"))
    settings = dict(view.settings)
    parts.append("<h2>Settings and versions</h2><table class=kv>"
                  + "".join(f"<tr><td>{_esc(k)}</td><td>{_esc(json.dumps(v, default=str)[:500])}</td></tr>"
                            for k, v in {**settings, **_versions()}.items()) + "</table>")
    js = plotly.offline.get_plotlyjs()
    return ("<!DOCTYPE html><html><head><meta charset='utf-8'>"
            f"<title>{_esc(title)}</title><style>{_CSS}</style>"
            f"<script>{_CHECK_JS}</script><script type='text/javascript'>{js}</script></head>"
            f"<body>{''.join(parts)}</body></html>")


def write_report(run: str | Path, out: str | Path, *, title: str | None = None) -> Path:
    view = load_run(run)
    page = render(view, title=title)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(out.suffix + ".tmp")
    tmp.write_text(page, encoding="utf-8")
    tmp.replace(out)
    return out
