"""The calibration report: JSON data and a self-contained HTML page (inline SVG, nothing fetched).

Lengths in mm and micrometres as labelled, angles in degrees, tips and residual vectors
(predicted minus measured) in the table frame.
"""

from __future__ import annotations

import html
import json
from typing import Any

import numpy as np

from .fit import OUTLIER_ALPHA, Calibration
from .measurements import Measurements
from .model import PARAMETERS, SCALE, to_interface, unit


def report_data(calibration: Calibration, measurements: Measurements, machine_source: str) -> dict[str, Any]:
    """Everything the report shows, as JSON-ready data (mm, degrees)."""
    c = calibration
    summary = c.summary()
    open_names = {name for d in c.directions if d.weak for name in d.combination}
    parameters = []
    for k, name in enumerate(PARAMETERS):
        nominal, fitted = to_interface(name, c.nominal[k]), to_interface(name, c.fitted[k])
        std = to_interface(name, c.std[k]) if np.isfinite(c.std[k]) else None
        parameters.append({"name": name, "unit": unit(name), "status": c.status[name], "nominal": nominal,
                           "fitted": fitted, "change": fitted - nominal, "std": std,
                           "reason": "fixed by --fix" if c.status[name] == "fixed" else (
                               "in a direction the measurements leave open (above): std mostly the prior's"
                               if name in open_names else None)})
    poses = []
    for k, line in enumerate(measurements.lines):
        poses.append({"line": int(line), "tool_length": float(measurements.poses.tool_length[k]),
                      "measured": measurements.poses.tip[k].tolist(),
                      "residual_before": c.residual_before[k].tolist(), "residual_after": c.residual_after[k].tolist(),
                      "norm_before": float(np.linalg.norm(c.residual_before[k])),
                      "norm_after": float(np.linalg.norm(c.residual_after[k])),
                      "score": float(c.score[k]), "outlier": bool(c.outlier[k]), "used": bool(c.used[k])})
    return {
        "measurements": measurements.source,
        "machine": machine_source,
        "poses_measured": len(measurements.lines),
        "poses_used": int(c.used.sum()),
        "rejected_lines": [int(x) for x in measurements.lines[~c.used]],
        "summary_mm": {**summary, "noise_estimate": c.sigma},
        "fit": {"evaluations": c.evaluations, "message": c.message, "robust": c.robust},
        "not_determined": c.notes,
        "parameters": parameters,
        "identifiability": [{"relative_singular_value": d.relative, "std_in_typical_errors": d.std,
                             "open": d.weak, "combination": d.combination} for d in c.directions],
        "typical_errors": {n: to_interface(n, float(SCALE[k])) for k, n in enumerate(PARAMETERS)},
        "outlier_rule": (f"tip residual of the robust (soft-L1) fit, leverage corrected, above {c.threshold:.2f} noise "
                         "standard deviations (the median pose sets the noise): a clean data set has a pose above it "
                         f"with probability {OUTLIER_ALPHA:g}"),
        "outliers": [{"line": p["line"], "norm_after": p["norm_after"], "score": p["score"],
                      "rejected": not p["used"]} for p in poses if p["outlier"]],
        "poses": poses,
    }


def _number(value: float | None, digits: int = 4) -> str:
    return "" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def _vector_plot(data: dict[str, Any], key: str, title: str, width: int = 460, height: int = 400) -> str:
    """SVG: measured tips in the table's x-y plane with their residual vectors, the longest
    arrow of this panel's unflagged poses 15 % of the plot (the scale is written on it)."""
    poses = data["poses"]
    xy = np.array([p["measured"][:2] for p in poses])
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    span = max(float(np.max(hi - lo)), 1.0)
    pad = 40.0
    scale_xy = (min(width, height) - 2 * pad) / span
    # Scaled to the poses that do not stand out; an outlier's arrow is cut at twice the bar.
    lengths = [float(np.hypot(*p[key][:2])) for p in poses]
    typical = [length for length, p in zip(lengths, poses, strict=True) if not p["outlier"]] or lengths
    longest = max(max(typical), 1e-9)
    arrow_scale = 0.15 * span / longest
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
             f'viewBox="0 0 {width} {height}" role="img"><title>{html.escape(title)}</title>',
             f'<rect width="{width}" height="{height}" fill="#fff" stroke="#ccc"/>',
             f'<text x="8" y="16" font-size="13">{html.escape(title)}</text>']
    for p in poses:
        x0 = pad + (p["measured"][0] - lo[0]) * scale_xy
        y0 = height - pad - (p["measured"][1] - lo[1]) * scale_xy
        cut = min(1.0, 2.0 * longest / max(float(np.hypot(*p[key][:2])), 1e-12))
        dx, dy = (p[key][0] * cut * arrow_scale * scale_xy, p[key][1] * cut * arrow_scale * scale_xy)
        colour = "#c00" if p["outlier"] else ("#888" if not p["used"] else "#1f5fa8")
        parts.append(f'<circle cx="{x0:.1f}" cy="{y0:.1f}" r="2" fill="{colour}"><title>line {p["line"]}: '
                     f'{p[key.replace("residual", "norm")] * 1000:.1f} um</title></circle>')
        parts.append(f'<line x1="{x0:.1f}" y1="{y0:.1f}" x2="{x0 + dx:.1f}" y2="{y0 - dy:.1f}" stroke="{colour}" '
                     'stroke-width="1.2"/>')
    bar = 0.15 * span * scale_xy
    parts.append(f'<line x1="{width - 12 - bar:.1f}" y1="28" x2="{width - 12:.1f}" y2="28" stroke="#000" '
                 f'stroke-width="2"/><text x="{width - 12:.1f}" y="44" font-size="11" text-anchor="end">'
                 f'arrow scale: this bar = {longest * 1000:.3g} um</text>')
    parts.append(f'<text x="8" y="{height - 8}" font-size="11">table x (right), y (up), mm; arrows: predicted - '
                 'measured in x-y</text></svg>')
    return "".join(parts)


def _norm_bars(data: dict[str, Any], width: int = 940, height: int = 220) -> str:
    """SVG: residual norm of each pose before (grey) and after (blue), log scale in um."""
    poses = data["poses"]
    before = np.array([p["norm_before"] for p in poses]) * 1000
    after = np.array([p["norm_after"] for p in poses]) * 1000
    lo = np.log10(max(min(after.min(), before.min()), 0.01))
    hi = np.log10(max(before.max(), after.max(), 1.0)) + 0.1
    bar = (width - 60) / max(len(poses), 1)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" role="img">'
             '<title>Residual norm per pose</title>',
             f'<rect width="{width}" height="{height}" fill="#fff" stroke="#ccc"/>']

    def y_of(value: float) -> float:
        return height - 20 - (np.log10(max(value, 10**lo)) - lo) / (hi - lo) * (height - 40)

    for decade in range(int(np.floor(lo)), int(np.ceil(hi)) + 1):
        if lo <= decade <= hi:
            y = y_of(10.0**decade)
            parts.append(f'<line x1="50" x2="{width}" y1="{y:.1f}" y2="{y:.1f}" stroke="#eee"/>'
                         f'<text x="4" y="{y + 4:.1f}" font-size="10">{10.0**decade:g} um</text>')
    for k, p in enumerate(poses):
        x = 55 + k * bar
        for value, colour, offset in ((before[k], "#bbb", 0.0), (after[k], "#c00" if p["outlier"] else "#1f5fa8",
                                                                   bar / 2)):
            y = y_of(value)
            parts.append(f'<rect x="{x + offset:.1f}" y="{y:.1f}" width="{max(bar / 2 - 0.5, 0.5):.1f}" '
                         f'height="{height - 20 - y:.1f}" fill="{colour}"><title>line {p["line"]}: {value:.1f} um'
                         '</title></rect>')
    parts.append("</svg>")
    return "".join(parts)


def report_html(data: dict[str, Any]) -> str:
    """A self-contained HTML page of :func:`report_data` (inline SVG and CSS only)."""
    s = data["summary_mm"]
    rows = []
    for p in data["parameters"]:
        rows.append("<tr>" + "".join(f"<td>{html.escape(str(v))}</td>" for v in (
            p["name"], p["unit"], p["status"], _number(p["nominal"], 6), _number(p["fitted"], 6),
            _number(p["change"], 6), _number(p["std"], 6), p["reason"] or "")) + "</tr>")
    ident = []
    for d in data["identifiability"]:
        combination = ", ".join(f"{v:+.2f} {n}" for n, v in d["combination"].items())
        ident.append(f"<tr><td>{d['relative_singular_value']:.3g}</td><td>{_number(d['std_in_typical_errors'], 4)}"
                     f"</td><td>{html.escape(combination)}</td></tr>")
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in data["not_determined"]) or "<li>nothing: every " \
        "direction is determined by the measurements</li>"
    outliers = "".join(f"<li>line {o['line']}: {o['norm_after'] * 1000:.1f} um, {o['score']:.1f} standard deviations"
                       f"{' (rejected)' if o['rejected'] else ''}</li>" for o in data["outliers"]) or "<li>none</li>"
    robust = (" The values come from the robust (soft-L1) fit, which gives the flagged poses little weight."
              if data["fit"]["robust"] else "")
    title = f"Calibration of {data['machine']} from {data['measurements']}"
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{font-family:sans-serif;margin:1.5em;max-width:980px}}table{{border-collapse:collapse;font-size:13px}}
td,th{{border:1px solid #ccc;padding:2px 6px;text-align:right}}td:last-child{{text-align:left}}
.plots svg{{margin-right:10px}}</style></head><body>
<h1>{html.escape(title)}</h1>
<p>{data['poses_used']} of {data['poses_measured']} poses used. Tool-tip residual (predicted - measured, table frame):
RMS {s['rms_before'] * 1000:.1f} um, max {s['max_before'] * 1000:.1f} um with the input machine file;
RMS {s['rms_after'] * 1000:.2f} um, max {s['max_after'] * 1000:.2f} um calibrated
(noise estimate {s['noise_estimate'] * 1000:.2f} um).{robust} {html.escape(data['fit']['message'])}</p>
<h2>Residual vectors</h2><div class="plots">{_vector_plot(data, 'residual_before', 'before')}
{_vector_plot(data, 'residual_after', 'after (its own arrow scale)')}</div>
{_norm_bars(data)}
<h2>What the measurements leave open</h2><ul>{notes}</ul>
<h2>Parameters</h2><table><tr><th>name</th><th>unit</th><th>status</th><th>nominal</th><th>fitted</th>
<th>change</th><th>std</th><th>note</th></tr>{''.join(rows)}</table>
<h2>Outliers</h2><p>{html.escape(data['outlier_rule'])}</p><ul>{outliers}</ul>
<h2>Identifiability</h2><p>Singular directions of the scaled identification Jacobian, weakest last; std after the fit
in typical errors (1 mm for lengths and slider zeros, 1 mrad for table angles: the prior toward the machine file).</p>
<table><tr><th>relative singular value</th><th>std</th><th>combination</th></tr>{''.join(ident)}</table>
</body></html>
"""


def report_json(data: dict[str, Any]) -> str:
    from ..output.tables import _json_ready

    return json.dumps(_json_ready(data), indent=2, allow_nan=False) + "\n"


__all__ = ["report_data", "report_html", "report_json"]
