"""A self-contained HTML report of one postprocessed job (``--report PART.html``).

One file that opens offline in any browser: styles, data and a small hand-written canvas
script inline, no network fetches. It holds the job summary (CL file, machine, tools with their
lengths and Delta, work offset and how it was chosen, cycle time, violations and warnings
linked to the CL lines they name); joint positions, velocities and accelerations over time
against their limits; the planned tool-tip feed against the programmed one; the singularity and
rod-clearance margins and the smallest headroom along the program; the time budget per tool;
workspace maps with the program's tool tips; and, when the caller gives one, a 3D view of the
machine's bodies, the setup and the tool path with its collisions and near misses (``scene3d``).

Plots are drawn from decimated copies of the data (per display column the smallest and the
largest value, so no peak is lost): a 100,000-point job stays responsive. The checks never see
these copies. When every plot is drawn the script adds ``<div id="plots-drawn">N</div>`` to
the page; a script error adds ``<div id="script-error">``; tests read both from the DOM.
"""

from __future__ import annotations

import base64
import html
import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..api import JOINT_NAMES, joint_bounds
from ..checks.headroom import headroom, smallest
from ..machine import Machine
from ..options import PostOptions
from ..output.atomic import atomic_write
from ..output.trajectory import samples, tip_speed
from ..pipeline import PostResult
from ..placement.workspace import boundary_labels, workspace
from ..planning.schedule import Schedule, time_budget
from ..planning.stage import feed_speed
from ..planning.timing import Limits
from .scene3d import SCENE_SCRIPT, SCENE_STYLE, scene_lines, scene_section
from .series import COLUMNS, envelope, rounded

#: Trajectory samples taken over the whole cycle.
SAMPLES = 40_000
#: CL lines shown around each line a message names, and messages listed at most.
CONTEXT = 3
MAX_MESSAGES = 200
_LINE = re.compile(r":(\d+): ")
_UNITS = ("mm", "mm", "mm", "deg", "deg")


def _series(x: np.ndarray, columns: dict[str, np.ndarray], lines: np.ndarray) -> dict[str, Any]:
    """Each column decimated on its own, and a CL line lookup over x (for the tooltips)."""
    step = max(1, len(x) // (4 * COLUMNS))
    return {"series": {name: envelope(x, values) for name, values in columns.items()},
            "line_x": rounded(x[::step], 7), "line": [int(v) for v in lines[::step]]}


def _trajectory(machine: Machine, result: PostResult) -> dict[str, Any] | None:
    """Decimated joint positions, velocities, accelerations and tip feeds over time."""
    schedule = result.schedule
    if schedule is None or schedule.total <= 0:
        return None
    blocks = result.blocks
    lengths = result.poses.tool_length[blocks.pose]
    programmed = feed_speed(result.poses, blocks, result.duration) * 60.0
    programmed = np.where(result.rapid | (programmed > 1e8), np.nan, programmed)
    chunks: list[tuple[np.ndarray, ...]] = []
    for t, q, qd, qdd, block, rapid in samples(schedule, schedule.total / SAMPLES):
        # Rapids have no programmed feed: they would only squash the feed plot's scale.
        feed = np.full(len(t), np.nan) if rapid else tip_speed(machine, q, qd, lengths[block]) * 60.0
        chunks.append((t, q, qd, qdd, feed, np.full(len(t), np.nan) if rapid else programmed[block], block))
    t, q, qd, qdd, feed, wanted, block = (np.concatenate(parts) for parts in zip(*chunks, strict=True))
    scale = np.array([1.0, 1.0, 1.0, 180 / np.pi, 180 / np.pi])
    columns = {}
    for j, name in enumerate(JOINT_NAMES):
        columns[name] = q[:, j] * scale[j]
        columns[f"v_{name}"] = qd[:, j] * scale[j]
        columns[f"a_{name}"] = qdd[:, j] * scale[j]
    columns["feed"] = feed
    columns["programmed"] = wanted
    return {**_series(t, columns, result.poses.line[blocks.pose][block]), "between": _between(schedule)}


_BETWEEN_NOTE = ("<p class=\"note\"><span style=\"background:#fde7c4\">&nbsp;Shaded&nbsp;</span>: the machine "
                 "moves between cuts (rapids on the CAM's line, retracts, reorientations, approaches, tool changes "
                 "and home), at the joint limits.</p>")

#: Intervals of moves between cuts drawn at most (closer ones are merged).
BETWEEN_INTERVALS = 2000


def _between(schedule: Schedule) -> list[list[float]]:
    """The time intervals (s) of the moves between cuts (rapids, retracts, reorientations, tool
    changes), merged where they touch or lie closer than the drawing can show."""
    spans = sorted((s.start, s.start + s.plan.total) for s in schedule.segments if s.rapid)
    gap = schedule.total / BETWEEN_INTERVALS
    merged: list[list[float]] = []
    for start, end in spans:  # one per rapid sequence: far fewer than the blocks
        if merged and start - merged[-1][1] <= gap:
            merged[-1][1] = max(merged[-1][1], end)
        else:
            merged.append([start, end])
    return [[round(a, 4), round(b, 4)] for a, b in merged]


def _margins(machine: Machine, result: PostResult) -> dict[str, Any]:
    """Singularity margins, rod clearance and the smallest headroom per block end, over time."""
    blocks = result.blocks
    found = blocks.result.margins
    value, _ = smallest(headroom(machine, blocks.joints, found))
    time = np.cumsum(result.duration)
    columns = {name: getattr(found, name) for name in ("serial", "parallel", "machine", "rod_clearance")}
    columns["headroom"] = value
    return _series(time, columns, result.poses.line[blocks.pose])


def _budget(machine: Machine, result: PostResult) -> list[dict[str, Any]]:
    """Time budget per tool (s): at the programmed feed, lost to joint velocity limits, lost to
    acceleration and jerk, rapids."""
    schedule = result.schedule
    blocks = result.blocks
    tools = result.poses.tool[blocks.pose]
    rows = []
    limits = Limits.from_machine(machine)
    speed = feed_speed(result.poses, blocks, result.duration)
    rotary = np.radians(machine.timing.rotary_feed) / 60.0
    for tool in dict.fromkeys(tools.tolist()):
        mine = tools == tool
        entry = {"tool": int(tool), "total_s": float(np.sum(result.duration[mine])),
                 "rapid_s": float(np.sum(result.duration[mine & result.rapid]))}
        if schedule is not None:
            segments = tuple(s for s in schedule.segments if not s.rapid and tools[s.first] == tool)
            entry.update(time_budget(Schedule(schedule.duration, segments), blocks.joints, blocks.tip, speed, limits,
                                     rotary))
        rows.append(entry)
    return rows


def _workspace_maps(machine: Machine, result: PostResult, offset: np.ndarray) -> dict[str, Any]:
    """Workspace sections for the most used tool at the program's median tilt, its tips overlaid."""
    poses = result.poses
    lengths, counts = np.unique(poses.tool_length, return_counts=True)
    length = float(lengths[np.argmax(counts)])
    tilt = float(np.median(np.degrees(np.arctan2(np.hypot(poses.axis[:, 0], poses.axis[:, 1]), poses.axis[:, 2]))))
    tilt = round(tilt)
    ws = workspace(machine, tool_length=length, tilt=tilt, rotary=0.0, step=20.0,
                   z=float(np.round(np.median(poses.tip[:, 2]))))
    sections = []
    for section in ws.sections:
        value = section.headroom
        code = np.where(np.isnan(value), 255, np.where(value < 0, 254, np.clip(np.round(value * 250), 0, 250)))
        sections.append({
            "plane": section.plane, "level": section.level,
            "u": [float(section.u[0]), float(section.u[-1])], "v": [float(section.v[0]), float(section.v[-1])],
            "nu": len(section.u), "nv": len(section.v),
            "cells": base64.b64encode(code.astype(np.uint8).tobytes()).decode("ascii"),
            "labels": [[label, u, v] for label, u, v in boundary_labels(section)],
        })
    step = max(1, len(poses) // 4000)
    tips = poses.tip[::step]
    return {"tool_length": length, "tilt": tilt, "rotary": 0.0, "sections": sections,
            "tips": [rounded(tips[:, k], 4) for k in range(3)], "offset": [float(v) for v in offset]}


def _messages(result: PostResult) -> tuple[list[tuple[str, int | None, str]], set[int]]:
    """(kind, CL line or None, text) of violations then warnings, and the lines they name."""
    out: list[tuple[str, int | None, str]] = [("violation", v.line, v.message) for v in result.violations]
    for warning in result.warnings:
        found = _LINE.search(warning)
        line = int(found.group(1)) if found else None
        out.append(("warning", line, warning[found.end():] if found else warning))
    out = out[:MAX_MESSAGES]
    return out, {line for _, line, _ in out if line is not None}


def _cl_excerpts(source: str, lines: set[int]) -> str:
    """The CL file's lines around each named line, each line an anchor ``cl-N``."""
    try:
        text = Path(source).read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return "<p>(the CL file could not be read again)</p>"
    shown = sorted({k for line in lines for k in range(max(1, line - CONTEXT), min(len(text), line + CONTEXT) + 1)})
    parts, previous = [], None
    for k in shown:
        if previous is not None and k != previous + 1:
            parts.append('<span class="gap">...</span>')
        mark = ' class="named"' if k in lines else ""
        parts.append(f'<span id="cl-{k}"{mark}><b>{k:>7}</b>  {html.escape(text[k - 1])}</span>')
        previous = k
    return "<pre class=\"cl\">" + "\n".join(parts) + "</pre>" if parts else "<p>No CL line is named.</p>"


def _table(rows: list[tuple[str, str]]) -> str:
    return "<table class=\"kv\">" + "".join(f"<tr><th>{html.escape(k)}</th><td>{v}</td></tr>" for k, v in rows) + \
        "</table>"


def render(machine: Machine, options: PostOptions, result: PostResult, scene: dict | None = None) -> str:
    """The report page (ASCII: anything else as character references). ``scene``: the 3D view's
    bodies, setup and path (:mod:`verne_post.report.scene3d`); None: the section says none was given."""
    report = result.report(machine, options)
    offset = np.asarray(report["work_offset_mm"])
    messages, named = _messages(result)
    timing = report["timing"]
    placement = report["placement"]
    offset_text = "{:.3f} {:.3f} {:.3f} mm".format(*offset)
    if placement:
        room = "not measured" if placement["room_mm"] is None else ", ".join(
            f"{a} -{r['minus']:.1f}/+{r['plus']:.1f}" for a, r in placement["room_mm"].items()) + " mm"
        offset_text += (f" (chosen by placement: smallest headroom {placement['smallest_headroom']:.3f}, "
                        f"{html.escape(placement['limiting_constraint'])} at <a href=\"#cl-{placement['line']}\">"
                        f"line {placement['line']}</a>; room {room})")
        named.add(placement["line"])
    tools = "".join(f"<tr><td>{t['tool']}</td><td>{t['length_mm']:g}</td><td>{t['delta_mm']:g}</td>"
                    f"<td><a href=\"#cl-{t['line']}\">{t['line']}</a></td><td>{html.escape(t['length_from'])}</td></tr>"
                    for t in report["tools"])
    named |= {t["line"] for t in report["tools"]}
    named |= scene_lines(scene)  # the 3D findings link to their lines
    section = scene_section(scene)
    summary = _table([
        ("CL file", html.escape(report["source"])),
        ("machine", html.escape(f"{machine.name} ({report['machine']})")),
        ("result", "<b class=\"ok\">runs</b>" if report["ok"] else
         f"<b class=\"bad\">{len(result.violations)} violation(s): nothing written</b>"),
        ("work offset", offset_text),
        ("cycle time", f"{timing['cycle_time_s']:.1f} s (rapids {timing['rapid_time_s']:.1f} s)" if timing else
         f"{report['estimated_time_s']:.1f} s (programmed feeds and joint velocity limits only)"),
        ("points", f"{report['points']['cl']} CL, {report['points']['inserted']} inserted, "
                   f"{report['points']['blocks']} blocks"),
        ("tolerances", f"tip {options.tol:g} mm, axis {options.axis_tol:g} deg"),
        ("verne-post", html.escape(report["verne_post"])),
    ])
    listing = "".join(
        f"<li class=\"{kind}\"><span>{kind}</span> "
        + (f"<a href=\"#cl-{line}\">line {line}</a>: " if line is not None else "")
        + f"{html.escape(text)}</li>" for kind, line, text in messages)
    lower, upper = joint_bounds(machine)
    limits = Limits.from_machine(machine)
    scale = np.array([1.0, 1.0, 1.0, 180 / np.pi, 180 / np.pi])
    t = machine.singularity
    data = {
        "joints": [{"name": name, "unit": unit,
                    "min": float(lower[j] * scale[j]) if np.isfinite(lower[j]) else None,
                    "max": float(upper[j] * scale[j]) if np.isfinite(upper[j]) else None,
                    "velocity": float(limits.velocity[j] * scale[j]),
                    "acceleration": float(limits.acceleration[j] * scale[j])}
                   for j, (name, unit) in enumerate(zip(JOINT_NAMES, _UNITS, strict=True))],
        "trajectory": _trajectory(machine, result),
        "margins": _margins(machine, result),
        "thresholds": {"serial": t.serial_min, "parallel": t.parallel_min, "machine": t.machine_min,
                       "rod_clearance": t.rod_clearance_min, "headroom": 0.0},
        "budget": _budget(machine, result),
        "workspace": _workspace_maps(machine, result, offset),
    }
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    page = _PAGE.format(
        title=html.escape(Path(report["source"]).name), summary=summary, tools=tools,
        messages=f"<ul class=\"messages\">{listing}</ul>" if listing else "<p>None.</p>",
        excerpts=_cl_excerpts(result.poses.source, named), data=payload, script=_SCRIPT,
        style=_STYLE + (SCENE_STYLE if scene is not None else ""), scene=section,
        scene_script=f"\n<script>{SCENE_SCRIPT}</script>" if scene is not None else "",
        timing_note=_BETWEEN_NOTE if data["trajectory"] else "<p class=\"note\">No time-parametrisation "
                    "(--no-timing, or violations): joint traces, feeds and the time budget need it.</p>")
    return page.encode("ascii", "xmlcharrefreplace").decode("ascii")


def write_html_report(path: str | Path, machine: Machine, options: PostOptions, result: PostResult,
                      scene: dict | None = None) -> None:
    """Write the report page atomically (``scene``: as :func:`render`)."""
    page = render(machine, options, result, scene)
    with atomic_write(path) as handle:
        handle.write(page)


_STYLE = """
body{font:14px/1.4 system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:0 auto;max-width:1200px;padding:1em 2em;
color:#222}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:1.6em}
table.kv th{text-align:left;padding-right:1.2em;vertical-align:top;color:#555;font-weight:normal}
table.grid{border-collapse:collapse}table.grid td,table.grid th{border:1px solid #ddd;padding:2px 8px;text-align:right}
.ok{color:#1a7f37}.bad{color:#b42318}
ul.messages{padding-left:1em}ul.messages li{list-style:none;margin:2px 0}
ul.messages li span{display:inline-block;width:5.5em;font-size:.85em;color:#fff;text-align:center;border-radius:3px;
margin-right:.5em}
li.violation span{background:#b42318}li.warning span{background:#b7791f}
pre.cl{background:#f6f8fa;padding:.6em;overflow-x:auto;font-size:12px}pre.cl span{display:block}
pre.cl span.named{background:#fff3bf}pre.cl span:target{background:#ffd43b}pre.cl .gap{color:#999}
.plot{margin:.2em 0 .8em}.plot canvas{width:100%;height:160px;display:block;border:1px solid #e5e5e5}
#joint-plots{display:grid;grid-template-columns:repeat(3,1fr);column-gap:12px}
#margin-plots{display:grid;grid-template-columns:repeat(2,1fr);column-gap:12px}
.plot .caption{font-size:12px;color:#555;min-height:1.3em}
.maps{display:grid;grid-template-columns:repeat(3,1fr);gap:10px}.maps canvas{width:100%;border:1px solid #e5e5e5}
.note{color:#777}.legend span{display:inline-block;margin-right:1em;font-size:12px}
.legend i{display:inline-block;width:14px;height:3px;vertical-align:middle;margin-right:4px}
"""

_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="ascii"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>verne-post report: {title}</title><style>{style}</style></head>
<body>
<h1>verne-post report: {title}</h1>
{summary}
<h2>Tools</h2>
<table class="grid"><tr><th>tool</th><th>length (mm)</th><th>Delta (mm)</th><th>loaded at</th><th>length from</th></tr>
{tools}</table>
<h2>Violations and warnings</h2>
{messages}
<h2>Joints over time</h2>
{timing_note}
<div id="joint-plots"></div>
<h2>Tool-tip feed</h2>
<div id="feed-plots"></div>
<h2>Margins along the program</h2>
<div id="margin-plots"></div>
<h2>Time budget</h2>
<div id="budget"></div>
<h2>Workspace</h2>
<p id="workspace-caption" class="note"></p>
<div class="maps" id="maps"></div>
{scene}<h2>CL lines named above</h2>
{excerpts}
<script type="application/json" id="report-data">{data}</script>
<script>{script}</script>{scene_script}
</body></html>
"""

_SCRIPT = r"""
(function () {
  "use strict";
  function mark(id, text) {
    var d = document.getElementById(id) || document.createElement("div");
    d.id = id; d.textContent = text; d.style.display = "none"; document.body.appendChild(d);
  }
  window.onerror = function (message, source, line) { mark("script-error", message + " at line " + line); };
  var data = JSON.parse(document.getElementById("report-data").textContent);
  var colours = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e"];
  var plots = [];

  function el(tag, cls, parent) { var e = document.createElement(tag); if (cls) e.className = cls;
    if (parent) parent.appendChild(e); return e; }
  function extent(values) { var lo = Infinity, hi = -Infinity;
    for (var i = 0; i < values.length; i++) { var v = values[i]; if (v === null) continue;
      if (v < lo) lo = v; if (v > hi) hi = v; }
    return [lo, hi]; }
  function nice(lo, hi) { if (!isFinite(lo)) { lo = 0; hi = 1; } if (hi - lo < 1e-9) { lo -= 1; hi += 1; }
    var pad = (hi - lo) * 0.05; return [lo - pad, hi + pad]; }
  function ticks(lo, hi, n) { var step = Math.pow(10, Math.floor(Math.log10((hi - lo) / n)));
    var m = (hi - lo) / n / step; step *= m > 5 ? 10 : m > 2 ? 5 : m > 1 ? 2 : 1;
    var out = []; for (var v = Math.ceil(lo / step) * step; v <= hi; v += step) out.push(v); return out; }
  function fmt(v) { var a = Math.abs(v); return a >= 1000 || a === 0 ? v.toFixed(0) : a >= 10 ? v.toFixed(1) :
    a >= 0.1 ? v.toFixed(3) : v.toPrecision(3); }

  // A line plot: spec = {data: {series, line_x, line}, series: [{name, key, colour}], limits: [{y, label}], unit}
  function linePlot(parent, title, spec) {
    var box = el("div", "plot", parent), head = el("div", "caption", box);
    head.textContent = title;
    var canvas = el("canvas", "", box), caption = el("div", "caption", box);
    plots.push(function () {
      var ratio = window.devicePixelRatio || 1, w = canvas.clientWidth, h = canvas.clientHeight;
      canvas.width = w * ratio; canvas.height = h * ratio;
      var g = canvas.getContext("2d"); g.scale(ratio, ratio); g.clearRect(0, 0, w, h);
      var left = 64, right = 10, top = 8, bottom = 22, d = spec.data;
      var lines = spec.series.map(function (s) { return d.series[s.key]; });
      var xr = [Infinity, -Infinity], lo = Infinity, hi = -Infinity;
      lines.forEach(function (xy) { var ex = extent(xy[0]), ey = extent(xy[1]);
        xr = [Math.min(xr[0], ex[0]), Math.max(xr[1], ex[1])]; lo = Math.min(lo, ey[0]); hi = Math.max(hi, ey[1]); });
      if (!(xr[1] > xr[0])) xr = [0, 1];
      (spec.limits || []).forEach(function (l) { lo = Math.min(lo, l.y); hi = Math.max(hi, l.y); });
      var yr = nice(lo, hi);
      function px(v) { return left + (v - xr[0]) / (xr[1] - xr[0]) * (w - left - right); }
      function py(v) { return top + (yr[1] - v) / (yr[1] - yr[0]) * (h - top - bottom); }
      g.font = "11px sans-serif"; g.fillStyle = "#555"; g.strokeStyle = "#eee"; g.lineWidth = 1;
      ticks(yr[0], yr[1], 4).forEach(function (v) { g.beginPath(); g.moveTo(left, py(v)); g.lineTo(w - right, py(v));
        g.stroke(); g.fillText(fmt(v), 4, py(v) + 4); });
      ticks(xr[0], xr[1], 8).forEach(function (v) { g.fillText(fmt(v), px(v) - 8, h - 6); });
      g.fillStyle = "#fde7c4";  // the moves between cuts, behind the traces
      (d.between || []).forEach(function (b) { var a = px(Math.max(b[0], xr[0])), e = px(Math.min(b[1], xr[1]));
        if (e > a - 1) g.fillRect(a, top, Math.max(e - a, 1), h - top - bottom); });
      g.fillStyle = "#555";
      (spec.limits || []).forEach(function (l) { g.strokeStyle = "#b42318"; g.setLineDash([5, 4]); g.beginPath();
        g.moveTo(left, py(l.y)); g.lineTo(w - right, py(l.y)); g.stroke(); g.setLineDash([]);
        g.fillStyle = "#b42318"; g.fillText(l.label, w - right - g.measureText(l.label).width - 2, py(l.y) - 3); });
      lines.forEach(function (xy, k) { var x = xy[0], y = xy[1]; g.strokeStyle = spec.series[k].colour;
        g.lineWidth = 1.2; g.beginPath(); var pen = false;
        for (var i = 0; i < x.length; i++) { if (y[i] === null) { pen = false; continue; }
          if (pen) g.lineTo(px(x[i]), py(y[i])); else g.moveTo(px(x[i]), py(y[i])); pen = true; }
        g.stroke(); });
      function nearest(x, t) { var a = 0, b = x.length - 1;
        while (b - a > 1) { var m = (a + b) >> 1; if (x[m] < t) a = m; else b = m; }
        return Math.abs(x[a] - t) < Math.abs(x[b] - t) ? a : b; }
      canvas.onmousemove = function (event) {
        var r = canvas.getBoundingClientRect(), t = xr[0] + (event.clientX - r.left - left) / (w - left - right) *
          (xr[1] - xr[0]);
        caption.textContent = "t " + fmt(t) + " s, CL line " + d.line[nearest(d.line_x, t)] + ": " +
          lines.map(function (xy, k) { var v = xy[1][nearest(xy[0], t)];
            return spec.series[k].name + " " + (v === null ? "-" : fmt(v)); }).join(", ");
      };
    });
  }

  var traj = data.trajectory, joints = document.getElementById("joint-plots");
  if (traj) {
    data.joints.forEach(function (j) {
      var limits = [];
      if (j.min !== null) limits.push({y: j.min, label: "min"});
      if (j.max !== null) limits.push({y: j.max, label: "max"});
      linePlot(joints, j.name + " position (" + j.unit + ")", {data: traj, unit: j.unit, limits: limits,
        series: [{name: j.name, key: j.name, colour: colours[0]}]});
      linePlot(joints, j.name + " velocity (" + j.unit + "/s)", {data: traj, unit: j.unit + "/s",
        series: [{name: "v", key: "v_" + j.name, colour: colours[2]}],
        limits: [{y: j.velocity, label: "limit"}, {y: -j.velocity, label: "-limit"}]});
      linePlot(joints, j.name + " acceleration (" + j.unit + "/s\u00b2)", {data: traj, unit: j.unit + "/s\u00b2",
        series: [{name: "a", key: "a_" + j.name, colour: colours[3]}],
        limits: [{y: j.acceleration, label: "limit"}, {y: -j.acceleration, label: "-limit"}]});
    });
    linePlot(document.getElementById("feed-plots"), "tool-tip feed relative to the part (mm/min): planned " +
      "(blue) and programmed (red)", {data: traj, unit: "mm/min",
      series: [{name: "planned", key: "feed", colour: colours[0]},
               {name: "programmed", key: "programmed", colour: colours[1]}]});
  }
  var marginBox = document.getElementById("margin-plots");
  [["headroom", "smallest headroom (fraction: 0 at a limit)"], ["serial", "serial singularity margin"],
   ["parallel", "parallel singularity margin"], ["machine", "machine singularity margin"],
   ["rod_clearance", "leg I rod clearance (mm)"]].forEach(function (m, k) {
    linePlot(marginBox, m[1], {data: data.margins, unit: m[0] === "rod_clearance" ? "mm" : "",
      series: [{name: m[0], key: m[0], colour: colours[k % colours.length]}],
      limits: [{y: data.thresholds[m[0]], label: "threshold"}]});
  });

  // Time budget: a table and one stacked bar per tool.
  var budget = document.getElementById("budget"), parts = [["at_programmed_feed_s", "at programmed feed", "#2ca02c"],
    ["lost_to_joint_velocity_s", "lost to joint velocity limits", "#ff7f0e"],
    ["lost_to_acceleration_and_jerk_s", "lost to acceleration and jerk", "#d62728"], ["rapid_s", "rapids", "#7f7f7f"]];
  var table = "<table class='grid'><tr><th>tool</th><th>total (s)</th>" + parts.map(function (p) {
    return "<th>" + p[1] + " (s)</th>"; }).join("") + "</tr>";
  data.budget.forEach(function (b) { table += "<tr><td>" + b.tool + "</td><td>" + b.total_s.toFixed(1) + "</td>" +
    parts.map(function (p) { return "<td>" + (b[p[0]] === undefined ? "-" : b[p[0]].toFixed(1)) + "</td>"; })
      .join("") + "</tr>"; });
  budget.innerHTML = table + "</table><div class='legend'>" + parts.map(function (p) {
    return "<span><i style='background:" + p[2] + "'></i>" + p[1] + "</span>"; }).join("") + "</div>";
  var barCanvas = el("canvas", "", el("div", "plot", budget));
  plots.push(function () {
    var ratio = window.devicePixelRatio || 1, w = barCanvas.clientWidth, h = barCanvas.clientHeight;
    barCanvas.width = w * ratio; barCanvas.height = h * ratio;
    var g = barCanvas.getContext("2d"); g.scale(ratio, ratio); g.clearRect(0, 0, w, h);
    var longest = Math.max.apply(null, data.budget.map(function (b) { return b.total_s; }).concat([1e-9]));
    var row = Math.min(28, (h - 10) / Math.max(1, data.budget.length));
    g.font = "11px sans-serif";
    data.budget.forEach(function (b, i) { var x = 70, y = 5 + i * row;
      g.fillStyle = "#333"; g.fillText("tool " + b.tool, 4, y + row * 0.6);
      parts.forEach(function (p) { var v = b[p[0]] || 0, width = v / longest * (w - 80);
        g.fillStyle = p[2]; g.fillRect(x, y, width, row - 6); x += width; }); });
  });

  // Workspace maps: headroom cells (viridis-like), pink past a limit, grey unreachable; tips in red.
  var ws = data.workspace, maps = document.getElementById("maps");
  document.getElementById("workspace-caption").textContent = "Tool-tip workspace in the table frame for tool " +
    "length " + ws.tool_length + " mm, tilt " + ws.tilt + " deg (the program's median), rotary 0 deg; colour: " +
    "smallest headroom (dark 0, yellow 1); pink: reachable but past a limit; red dots: the program's tool tips " +
    "(work offset " + ws.offset.map(function (v) { return v.toFixed(1); }).join(" ") + " mm).";
  var stops = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
  function colour(code) {
    if (code === 255) return [240, 240, 240]; if (code === 254) return [244, 199, 195];
    var f = code / 250 * (stops.length - 1), i = Math.min(Math.floor(f), stops.length - 2), t = f - i;
    return [0, 1, 2].map(function (c) { return Math.round(stops[i][c] + (stops[i + 1][c] - stops[i][c]) * t); });
  }
  ws.sections.forEach(function (s) {
    var box = el("div", "", maps), canvas = el("canvas", "", box), cap = el("div", "caption", box);
    cap.textContent = s.plane[0] + "-" + s.plane[1] + " section at " + ({xz: "y", yz: "x", xy: "z"})[s.plane] +
      " = " + Math.round(s.level) + " mm";
    var raw = atob(s.cells), axes = {x: 0, y: 1, z: 2};
    plots.push(function () {
      var width = canvas.clientWidth, ratio = window.devicePixelRatio || 1;
      var height = width * (s.v[1] - s.v[0]) / (s.u[1] - s.u[0]);  // 1 mm is as long across as up
      canvas.style.height = height + "px"; canvas.width = width * ratio; canvas.height = height * ratio;
      var g = canvas.getContext("2d"), image = g.createImageData(s.nu, s.nv);
      for (var r = 0; r < s.nv; r++) for (var c = 0; c < s.nu; c++) {
        var rgb = colour(raw.charCodeAt(r * s.nu + c)), k = ((s.nv - 1 - r) * s.nu + c) * 4;
        image.data[k] = rgb[0]; image.data[k + 1] = rgb[1]; image.data[k + 2] = rgb[2]; image.data[k + 3] = 255; }
      var tile = document.createElement("canvas"); tile.width = s.nu; tile.height = s.nv;
      tile.getContext("2d").putImageData(image, 0, 0);
      g.imageSmoothingEnabled = false; g.drawImage(tile, 0, 0, canvas.width, canvas.height);
      function px(u) { return (u - s.u[0]) / (s.u[1] - s.u[0]) * canvas.width; }
      function py(v) { return (s.v[1] - v) / (s.v[1] - s.v[0]) * canvas.height; }
      var tu = ws.tips[axes[s.plane[0]]], tv = ws.tips[axes[s.plane[1]]];
      g.fillStyle = "rgba(214,39,40,0.6)";
      for (var i = 0; i < tu.length; i++) g.fillRect(px(tu[i]) - ratio, py(tv[i]) - ratio, 2 * ratio, 2 * ratio);
      g.font = (10 * ratio) + "px sans-serif"; g.fillStyle = "#000";
      s.labels.forEach(function (l) { g.fillText(l[0], Math.min(px(l[1]), canvas.width - g.measureText(l[0]).width),
        py(l[2])); });
    });
  });

  function drawAll() { plots.forEach(function (draw) { draw(); }); }
  drawAll();
  mark("plots-drawn", String(plots.length));
  var pending = null;
  window.addEventListener("resize", function () { clearTimeout(pending); pending = setTimeout(drawAll, 150); });
})();
"""


__all__ = ["envelope", "render", "write_html_report"]
