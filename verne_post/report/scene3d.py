"""The HTML report's 3D view of the machine's bodies, the setup and the tool path (WebGL2, no library).

:func:`scene_section` gives the section's HTML (a ``<canvas>``, a slider through the program's
frames, a legend, the findings linked to their CL lines and an SVG plot of the smallest
clearance along the program); :data:`SCENE_SCRIPT` and :data:`SCENE_STYLE` are inlined once by
:func:`verne_post.report.html.render` when a scene is given.

The scene is a JSON-able dict, everything in the table frame (the part's frame, turning with the
table: the head's bodies move relative to it), lengths in mm::

    {"units": "mm", "frame": "table", "margin": 2.0,
     "colours": {"stock": "#d9a441"},                       # optional, per group
     "fixed": [BODY, ...], "moving": [MOVING BODY, ...],
     "frames": {"t": [F s], "line": [F CL lines], "poses": [F lists, one per frame]},
     "path": {"xyz": [3*P], "clearance": [P mm or null], "rapid": [P bools], "frame": [P]},
     "clearance": {"t": [N s], "mm": [N mm or null]},
     "findings": [{"severity": "collision" | "near miss", "bodies": [A, B], "clearance": mm,
                   "line": CL line, "xyz": [x, y, z], "frame": k}]}

A fixed body is ``{"name", "group", "kind", ...}`` with, by kind: ``box`` ``lo``, ``hi``;
``obox`` ``center``, ``half``, ``rotation`` (9, row-major: world = center + R @ local);
``cylinder`` ``center`` [x, y], ``z0``, ``z1``, ``radius`` (or ``p0``, ``p1``, ``radius``);
``capsule`` ``p0``, ``p1``, ``radius``; ``mesh`` ``triangles`` (9 numbers a triangle). A moving
body gives its shape and takes its place from each frame's pose: ``capsule`` and ``cylinder``
``radius``, pose 6 numbers (p0, p1: the axis' ends); ``box`` ``half``, pose 12 numbers (centre,
then the rotation row-major); ``mesh`` ``triangles`` in the body's own frame, pose 12 numbers
as a box's. A frame's pose list is the moving bodies' poses one after the other, in order.

``path.rapid[i]`` tells whether the move arriving at point i is a rapid; ``path.frame[i]`` the
frame at which the tool is at point i. Numbers are rounded to 3 decimals. Frames beyond
:data:`MAX_FRAMES` (2000, the recommended largest; a caller should decimate first) and path
points beyond :data:`MAX_PATH_POINTS` are thinned here, keeping the findings' frames and the
path points under the margin. The clearance series is drawn as SVG and not embedded.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .series import envelope

#: Frames and path points embedded at most (more are thinned), findings listed at most.
MAX_FRAMES = 2000
MAX_PATH_POINTS = 20_000
MAX_FINDINGS = 500
#: Decimals of every number embedded.
DIGITS = 3
#: Colours of the usual groups; other groups take the next of ``_SPARE``.
GROUP_COLOURS = {"machine": "#9aa0a6", "stock": "#d9a441", "part": "#d9a441", "fixture": "#8e5bb5",
                 "head": "#3b6fb6", "holder": "#2f9e8f", "tool": "#c2410c"}
_SPARE = ("#6b8e23", "#b5527a", "#4f6d7a", "#a0522d", "#5f5fb0", "#2e8b57")
_POSE = {"capsule": 6, "cylinder": 6, "box": 12, "mesh": 12}
_FIXED = ("box", "obox", "cylinder", "capsule", "mesh")
_SEVERITIES = ("collision", "near miss")


def _numbers(values: Any, digits: int = DIGITS) -> list:
    """Flat list of rounded numbers (integral ones as int, to keep the page small); NaN and
    infinities refused."""
    a = np.asarray(values, dtype=float).ravel()
    if not np.all(np.isfinite(a)):
        raise ValueError("the scene holds a number that is NaN or infinite")
    return [int(v) if v.is_integer() else v for v in np.round(a, digits).tolist()]


def _optional(values: Any) -> list:
    """Rounded numbers, non-finite ones (and None) as None (JSON null)."""
    a = np.array([np.nan if v is None else v for v in np.asarray(values, dtype=object).ravel()], dtype=float)
    out = np.round(a, DIGITS).tolist()
    return [None if not math.isfinite(v) else int(v) if v.is_integer() else v for v in out]


def _sized(body: dict, key: str, size: int, where: str) -> list:
    if key not in body:
        raise ValueError(f"{where}: no '{key}'")
    out = _numbers(body[key])
    if len(out) != size:
        raise ValueError(f"{where}: '{key}' has {len(out)} numbers, not {size}")
    return out


def _triangles(body: dict, where: str) -> list:
    triangles = _numbers(body.get("triangles", []))
    if len(triangles) % 9:
        raise ValueError(f"{where}: 'triangles' is not 9 numbers a triangle")
    return triangles


def _fixed(body: dict, k: int) -> dict:
    where = f"scene fixed body {k} ({body.get('name', '?')})"
    kind = body.get("kind")
    out: dict[str, Any] = {"name": str(body.get("name", f"body {k}")), "group": str(body.get("group", "machine")),
                           "kind": kind}
    if kind == "box":
        out.update(lo=_sized(body, "lo", 3, where), hi=_sized(body, "hi", 3, where))
    elif kind == "obox":
        out.update(center=_sized(body, "center", 3, where), half=_sized(body, "half", 3, where),
                   rotation=_sized(body, "rotation", 9, where))
    elif kind == "cylinder" and "p0" not in body:
        out.update(center=_sized(body, "center", 2, where), z0=_sized(body, "z0", 1, where)[0],
                   z1=_sized(body, "z1", 1, where)[0], radius=_sized(body, "radius", 1, where)[0])
    elif kind in ("cylinder", "capsule"):
        out.update(p0=_sized(body, "p0", 3, where), p1=_sized(body, "p1", 3, where),
                   radius=_sized(body, "radius", 1, where)[0])
    elif kind == "mesh":
        out["triangles"] = _triangles(body, where)
    else:
        raise ValueError(f"{where}: kind {kind!r} is none of {', '.join(_FIXED)}")
    if "colour" in body:
        out["colour"] = str(body["colour"])
    return out


def _moving(body: dict, k: int) -> dict:
    where = f"scene moving body {k} ({body.get('name', '?')})"
    kind = body.get("kind")
    out: dict[str, Any] = {"name": str(body.get("name", f"moving {k}")), "group": str(body.get("group", "head")),
                           "kind": kind}
    if kind in ("capsule", "cylinder"):
        out["radius"] = _sized(body, "radius", 1, where)[0]
    elif kind == "box":
        out["half"] = _sized(body, "half", 3, where)
    elif kind == "mesh":
        out["triangles"] = _triangles(body, where)
    else:
        raise ValueError(f"{where}: kind {kind!r} is none of {', '.join(_POSE)}")
    if "colour" in body:
        out["colour"] = str(body["colour"])
    return out


def _thin(count: int, limit: int, keep: np.ndarray) -> np.ndarray:
    """Indices of ``count`` items thinned to about ``limit`` evenly, the first, the last and ``keep`` kept."""
    if count <= limit:
        return np.arange(count)
    even = np.round(np.linspace(0, count - 1, limit)).astype(int)
    return np.unique(np.concatenate([even, keep.astype(int)]))


def normalise(scene: dict) -> dict:
    """The scene checked, rounded and thinned as embedded in the page (the clearance series
    left out: it is drawn as SVG). Raises ValueError naming what is wrong."""
    margin = float(scene.get("margin", 0.0))
    fixed = [_fixed(b, k) for k, b in enumerate(scene.get("fixed", []))]
    moving = [_moving(b, k) for k, b in enumerate(scene.get("moving", []))]
    frames = scene.get("frames") or {"t": [0.0], "line": [0], "poses": [[]]}
    t = np.asarray(frames["t"], dtype=float).ravel()
    lines = np.asarray(frames["line"]).ravel()
    stride = sum(_POSE[b["kind"]] for b in moving)
    rows = [np.asarray(row, dtype=float).ravel() for row in frames["poses"]]
    if len(t) == 0 or len(lines) != len(t) or len(rows) != len(t) or any(len(r) != stride for r in rows):
        raise ValueError(f"scene frames: {len(t)} times, {len(lines)} lines and {len(rows)} poses of "
                         f"{sorted({len(r) for r in rows})} numbers; wanted at least one frame and {stride} pose "
                         f"numbers a frame")
    poses = np.array(rows).reshape(len(t), stride)
    path = scene.get("path") or {"xyz": [], "clearance": [], "rapid": [], "frame": []}
    xyz = np.asarray(path["xyz"], dtype=float).reshape(-1, 3)
    clear = np.array(_optional(path.get("clearance", [None] * len(xyz))), dtype=float)
    rapid = np.asarray(path.get("rapid", [False] * len(xyz)), dtype=bool).ravel()
    pframe = np.asarray(path.get("frame", [0] * len(xyz)), dtype=int).ravel()
    if not (len(clear) == len(rapid) == len(pframe) == len(xyz)):
        raise ValueError(f"scene path: {len(xyz)} points, {len(clear)} clearances, {len(rapid)} rapid flags, "
                         f"{len(pframe)} frames")
    if len(pframe) and (pframe.min() < 0 or pframe.max() >= len(t)):
        raise ValueError("scene path: a frame index outside the frames")
    findings = []
    for k, f in enumerate(scene.get("findings", [])):
        if f.get("severity") not in _SEVERITIES:
            raise ValueError(f"scene finding {k}: severity {f.get('severity')!r} is none of {_SEVERITIES}")
        frame = int(f["frame"])
        if not 0 <= frame < len(t):
            raise ValueError(f"scene finding {k}: frame {frame} outside the {len(t)} frames")
        findings.append({"severity": f["severity"], "bodies": [str(b) for b in f.get("bodies", [])],
                         "clearance": _optional([f.get("clearance")])[0], "line": int(f["line"]),
                         "xyz": _sized(f, "xyz", 3, f"scene finding {k}"), "frame": frame})
    findings.sort(key=lambda f: (f["severity"] != "collision", np.inf if f["clearance"] is None else f["clearance"]))
    findings = findings[:MAX_FINDINGS]
    # Thin the frames, keeping the findings'; every frame index then points to the nearest kept one.
    kept = _thin(len(t), MAX_FRAMES, np.array([f["frame"] for f in findings], dtype=int))
    if len(kept) < len(t):
        nearest = np.clip(np.searchsorted(kept, np.arange(len(t))), 0, len(kept) - 1)
        lower = np.clip(nearest - 1, 0, len(kept) - 1)
        nearest = np.where(np.abs(kept[lower] - np.arange(len(t))) < np.abs(kept[nearest] - np.arange(len(t))),
                           lower, nearest)
        pframe = nearest[pframe]
        for f in findings:
            f["frame"] = int(nearest[f["frame"]])
        t, lines, poses = t[kept], lines[kept], poses[kept]
    close = np.flatnonzero(~(clear >= margin))  # under the margin, or unknown
    keep = _thin(len(xyz), MAX_PATH_POINTS, close if len(close) < MAX_PATH_POINTS else close[:0])
    xyz, clear, rapid, pframe = xyz[keep], clear[keep], rapid[keep], pframe[keep]
    colours = dict(scene.get("colours", {}))
    spare = iter(_SPARE * 10)
    for body in fixed + moving:
        if body["group"] not in colours:
            colours[body["group"]] = GROUP_COLOURS.get(body["group"]) or next(spare)
    return {"units": str(scene.get("units", "mm")), "frame": str(scene.get("frame", "table")),
            "margin": _numbers([margin])[0], "colours": colours, "fixed": fixed, "moving": moving,
            "frames": {"t": _numbers(t), "line": [int(v) for v in lines],
                       "poses": [_numbers(row) for row in poses]},
            "path": {"xyz": _numbers(xyz), "clearance": _optional(clear), "rapid": [bool(v) for v in rapid],
                     "frame": [int(v) for v in pframe]},
            "findings": findings}


def embedded(data: dict) -> str:
    """JSON safe inside a ``<script>`` element: every ``<`` (so ``</script>`` and ``<!--``),
    ``>`` and ``&`` as JSON escapes; ASCII only."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def scene_lines(scene: dict | None) -> set[int]:
    """The CL lines the scene's findings name (the report shows these lines, anchored)."""
    return {int(f["line"]) for f in (scene or {}).get("findings", [])[:MAX_FINDINGS]}


def _ticks(lo: float, hi: float, n: int) -> list[float]:
    step = 10 ** math.floor(math.log10((hi - lo) / n))
    m = (hi - lo) / n / step
    step *= 10 if m > 5 else 5 if m > 2 else 2 if m > 1 else 1
    first = math.ceil(lo / step) * step
    return [first + k * step for k in range(int((hi - first) / step + 1e-9) + 1)]


def _fmt(v: float) -> str:
    return f"{v:.0f}" if abs(v) >= 10 or v == 0 else f"{v:.3g}"


#: The clearance plot's size (SVG user units) and its plot area.
_W, _H, _LEFT, _RIGHT, _TOP, _BOTTOM = 560, 220, 46, 10, 10, 26


def clearance_plot(series: dict | None, margin: float, findings: Sequence[dict], frame_t: Sequence[float]) -> str:
    """An SVG of the smallest clearance (mm) over time (s): the margin dashed, zero solid, the
    findings as dots, a cursor at the frame shown (``#scene-cursor``, moved by the script).
    Clearances above 20 margins (at least 10 mm) are drawn at the plot's top."""
    t = np.asarray((series or {}).get("t", []), dtype=float)
    mm = np.array(_optional((series or {}).get("mm", [])), dtype=float)
    if len(t) != len(mm):
        raise ValueError(f"scene clearance: {len(t)} times and {len(mm)} clearances")
    if len(t) == 0:
        return "<p class=\"note\">No clearance series was given.</p>"
    xs, ys = (np.asarray(v, dtype=float) for v in envelope(t, mm, bins=_W))
    top_cap = max(20.0 * margin, 10.0)
    finite = ys[np.isfinite(ys)]
    lo = min(0.0, float(finite.min()) if len(finite) else 0.0)
    hi = min(top_cap, max(float(finite.max()) if len(finite) else 1.0, margin * 1.5, lo + 1.0))
    pad = (hi - lo) * 0.05
    lo, hi = lo - pad, hi + pad
    t0, t1 = float(t[0]), float(t[-1]) if t[-1] > t[0] else float(t[0]) + 1.0

    def px(v: float) -> float:
        return round(_LEFT + (v - t0) / (t1 - t0) * (_W - _LEFT - _RIGHT), 1)

    def py(v: float) -> float:
        return round(_TOP + (hi - min(v, hi)) / (hi - lo) * (_H - _TOP - _BOTTOM), 1)

    parts, pen = [], False
    for x, y in zip(xs, ys, strict=True):
        if not math.isfinite(y):
            pen = False
            continue
        parts.append(f"{'L' if pen else 'M'}{px(x)} {py(y)}")
        pen = True
    grid = "".join(f'<line x1="{_LEFT}" x2="{_W - _RIGHT}" y1="{py(v)}" y2="{py(v)}" class="grid"/>'
                   f'<text x="{_LEFT - 4}" y="{py(v) + 4}" text-anchor="end">{_fmt(v)}</text>'
                   for v in _ticks(lo, hi, 4))
    grid += "".join(f'<text x="{px(v)}" y="{_H - 8}" text-anchor="middle">{_fmt(v)}</text>'
                    for v in _ticks(t0, t1, 6))
    dots = "".join(
        f'<circle cx="{px(frame_t[f["frame"]])}" cy="{py(f["clearance"] if f["clearance"] is not None else hi)}" '
        f'r="3.5" class="{"collision" if f["severity"] == "collision" else "near"}"><title>'
        f'{html.escape(f["severity"])} at CL line {f["line"]}</title></circle>' for f in findings)
    return (f'<svg id="scene-clearance" viewBox="0 0 {_W} {_H}" data-t0="{t0}" data-t1="{t1}" data-left="{_LEFT}" '
            f'data-width="{_W - _LEFT - _RIGHT}" role="img" aria-label="smallest clearance (mm) over time (s)">'
            f'{grid}<line x1="{_LEFT}" x2="{_W - _RIGHT}" y1="{py(0.0)}" y2="{py(0.0)}" class="zero"/>'
            f'<line x1="{_LEFT}" x2="{_W - _RIGHT}" y1="{py(margin)}" y2="{py(margin)}" class="margin"/>'
            f'<path d="{" ".join(parts)}" class="trace"/>{dots}'
            f'<line id="scene-cursor" x1="{_LEFT}" x2="{_LEFT}" y1="{_TOP}" y2="{_H - _BOTTOM}" class="cursor"/>'
            f'<text x="{_W - _RIGHT}" y="{py(margin) - 4}" text-anchor="end" class="margin">margin '
            f'{_fmt(margin)} mm</text></svg>'
            f'<p class="note">Smallest clearance (mm) over time (s); above {_fmt(top_cap)} mm drawn at the top.</p>')


_LEGEND_PATH = ('<span><i style="background:#d62728"></i>path: collision (clearance &lt;= 0)</span>'
                '<span><i style="background:#ff7f0e"></i>under the margin</span>'
                '<span><i style="background:linear-gradient(90deg,#2ca02c,#1f77b4)"></i>clear (green to blue: '
                'farther)</span><span><i class="dashed"></i>rapids (dashed)</span>'
                '<span><i style="background:#ccc"></i>path after the frame shown (paler)</span>')


def scene_section(scene: dict | None) -> str:
    """The report's section "Machine and setup in 3D" (without a scene, a sentence saying so)."""
    head = "<h2 id=\"scene-3d\">Machine and setup in 3D</h2>\n"
    if scene is None:
        return head + "<p class=\"note\">No 3D scene was given for this report.</p>\n"
    data = normalise(scene)
    frames = data["frames"]
    last = len(frames["t"]) - 1
    legend = "".join(f'<span><i style="background:{html.escape(c)}"></i>{html.escape(g)}</span>'
                     for g, c in data["colours"].items()
                     if any(b["group"] == g for b in data["fixed"] + data["moving"]))
    items = []
    for f in data["findings"]:
        value = "-" if f["clearance"] is None else f"{f['clearance']:.3f}"
        kind = "collision" if f["severity"] == "collision" else "near"
        items.append(
            f'<li class="{kind}"><button type="button" data-frame="{f["frame"]}" title="show frame {f["frame"]}">'
            f'{html.escape(f["severity"])}</button> {" / ".join(html.escape(b) for b in f["bodies"])}: '
            f'{value} mm at <a href="#cl-{f["line"]}">CL line {f["line"]}</a>, t {frames["t"][f["frame"]]:.2f} s</li>')
    listing = f'<ul id="scene-findings">{"".join(items)}</ul>' if items else \
        '<p id="scene-findings" class="note">No collision or near miss.</p>'
    plot = clearance_plot(scene.get("clearance"), float(data["margin"]), data["findings"], frames["t"])
    return head + (
        f'<p class="note">Bodies, setup and tool path in the {html.escape(data["frame"])} frame '
        f'({html.escape(data["units"])}); drag to orbit, wheel to zoom. Margin {data["margin"]} mm.</p>\n'
        '<div id="scene" class="scene">\n'
        '<canvas id="scene-canvas"></canvas>\n'
        '<p id="scene-message" class="scene-message" style="display:none"></p>\n'
        f'<div class="scene-slider"><input type="range" id="scene-frame" min="0" max="{last}" value="0" step="1" '
        f'aria-label="frame"> <span id="scene-frame-label">frame 0 of {last}: t {frames["t"][0]:.3f} s, CL line '
        f'{frames["line"][0]}</span></div>\n'
        f'<div class="legend">{legend}{_LEGEND_PATH}</div>\n'
        f'<div class="scene-side"><div><h3>Collisions and near misses</h3>{listing}</div>'
        f'<div><h3>Smallest clearance</h3>{plot}</div></div>\n'
        '<div id="scene-drawn" hidden></div><div id="scene-error" hidden></div><pre id="scene-probe" hidden></pre>\n'
        f'<script type="application/json" id="scene-data">{embedded(data)}</script>\n'
        '</div>\n')


SCENE_STYLE = """
.scene canvas#scene-canvas{width:100%;height:520px;display:block;border:1px solid #e5e5e5;cursor:grab;
touch-action:none}
.scene-message{color:#b42318;font-weight:bold}
.scene-slider{display:flex;align-items:center;gap:.8em;margin:.4em 0}.scene-slider input{flex:1}
.scene-slider span{font-size:12px;color:#333;min-width:22em}
.legend i.dashed{background:repeating-linear-gradient(90deg,#2ca02c 0 4px,transparent 4px 7px)}
.scene-side{display:grid;grid-template-columns:1fr 1fr;column-gap:16px}.scene-side h3{font-size:1em;margin:.6em 0 .3em}
#scene-findings{padding-left:0;margin:0;max-height:240px;overflow-y:auto}
#scene-findings li{list-style:none;margin:2px 0;font-size:13px}
#scene-findings button{width:6.5em;white-space:nowrap;
font-size:.8em;color:#fff;border:0;border-radius:3px;cursor:pointer;margin-right:.4em}
#scene-findings li.collision button{background:#b42318}#scene-findings li.near button{background:#d97706}
#scene-findings li.shown{background:#fff3bf}
#scene-clearance{width:100%;height:auto;font:10px sans-serif}#scene-clearance text{fill:#555}
#scene-clearance .grid{stroke:#eee}#scene-clearance .zero{stroke:#999}
#scene-clearance .margin{stroke:#d97706;stroke-dasharray:5 4}#scene-clearance text.margin{fill:#d97706;stroke:none}
#scene-clearance .trace{fill:none;stroke:#1f77b4;stroke-width:1.3}#scene-clearance .cursor{stroke:#333}
#scene-clearance circle.collision{fill:#b42318}#scene-clearance circle.near{fill:#d97706}
"""

SCENE_SCRIPT = r"""
(function () {
  "use strict";
  var root = document.getElementById("scene");
  if (!root) return;
  function byId(id) { return document.getElementById(id); }
  function fail(message) {
    byId("scene-error").textContent = message;
    var m = byId("scene-message"); m.textContent = "The 3D view could not be drawn: " + message;
    m.style.display = "block";
  }
  try { start(); } catch (e) { fail(String(e && e.message || e)); }

  function start() {
  var scene = JSON.parse(byId("scene-data").textContent);
  var canvas = byId("scene-canvas");
  var gl = null;
  try { gl = canvas.getContext("webgl2", {preserveDrawingBuffer: true, antialias: true}); } catch (e) { gl = null; }
  if (!gl) { fail("this browser gives no WebGL2 context"); return; }
  canvas.addEventListener("webglcontextlost", function (e) { e.preventDefault(); fail("the WebGL context was lost"); });
  var BG = [247, 247, 247];

  // ---- vectors and matrices (column-major 4x4, as GL takes them)
  function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
  function add(a, b) { return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]; }
  function mul(a, s) { return [a[0] * s, a[1] * s, a[2] * s]; }
  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  function unit(a) { var n = Math.sqrt(dot(a, a)); return n > 0 ? mul(a, 1 / n) : [0, 0, 1]; }
  function matmul(a, b) { var o = new Float32Array(16);
    for (var c = 0; c < 4; c++) for (var r = 0; r < 4; r++) { var s = 0;
      for (var k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k]; o[c * 4 + r] = s; }
    return o; }
  function perspective(fovy, aspect, near, far) { var f = 1 / Math.tan(fovy / 2), o = new Float32Array(16);
    o[0] = f / aspect; o[5] = f; o[10] = (far + near) / (near - far); o[11] = -1; o[14] = 2 * far * near / (near - far);
    return o; }
  function lookAt(eye, target, up) { var z = unit(sub(eye, target)), x = unit(cross(up, z)), y = cross(z, x);
    var o = new Float32Array(16);
    o[0] = x[0]; o[4] = x[1]; o[8] = x[2]; o[12] = -dot(x, eye);
    o[1] = y[0]; o[5] = y[1]; o[9] = y[2]; o[13] = -dot(y, eye);
    o[2] = z[0]; o[6] = z[1]; o[10] = z[2]; o[14] = -dot(z, eye); o[15] = 1; return o; }
  function rgb(hex) { var v = parseInt(String(hex).replace("#", ""), 16);
    return isNaN(v) ? [0.5, 0.5, 0.5] : [(v >> 16 & 255) / 255, (v >> 8 & 255) / 255, (v & 255) / 255]; }
  function mix(a, b, t) { return [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t]; }

  // ---- tessellation into interleaved [position, normal, colour] floats
  function Batch() { this.v = []; }
  Batch.prototype.vertex = function (p, n, c) { this.v.push(p[0], p[1], p[2], n[0], n[1], n[2], c[0], c[1], c[2]); };
  Batch.prototype.tri = function (a, b, c, n, col) { this.vertex(a, n, col); this.vertex(b, n, col);
    this.vertex(c, n, col); };
  Batch.prototype.quad = function (a, b, c, d, n, col) { this.tri(a, b, c, n, col); this.tri(a, c, d, n, col); };
  function frameOf(w) { var u = unit(cross(Math.abs(w[2]) < 0.9 ? [0, 0, 1] : [1, 0, 0], w)); return [u, cross(w, u)]; }
  var SEG = 32;
  function obox(b, c, R, h, col) {  // world = c + R (row-major) local
    function at(sx, sy, sz) { var l = [sx * h[0], sy * h[1], sz * h[2]];
      return [c[0] + R[0] * l[0] + R[1] * l[1] + R[2] * l[2], c[1] + R[3] * l[0] + R[4] * l[1] + R[5] * l[2],
              c[2] + R[6] * l[0] + R[7] * l[1] + R[8] * l[2]]; }
    for (var a = 0; a < 3; a++) for (var s = -1; s <= 1; s += 2) {
      var n = [s * R[a], s * R[3 + a], s * R[6 + a]], i = (a + 1) % 3, j = (a + 2) % 3, q = [];
      [[-1, -1], [1, -1], [1, 1], [-1, 1]].forEach(function (uv) { var k = [0, 0, 0]; k[a] = s; k[i] = uv[0];
        k[j] = uv[1]; q.push(at(k[0], k[1], k[2])); });
      b.quad(q[0], q[1], q[2], q[3], n, col);
    }
  }
  function tube(b, p0, p1, r, col, capsule) {
    var w = unit(sub(p1, p0)), f = frameOf(w), u = f[0], v = f[1], ring = [];
    for (var k = 0; k <= SEG; k++) { var a = 2 * Math.PI * k / SEG;
      ring.push(add(mul(u, Math.cos(a)), mul(v, Math.sin(a)))); }
    for (k = 0; k < SEG; k++) { var n0 = ring[k], n1 = ring[k + 1];
      var a0 = add(p0, mul(n0, r)), a1 = add(p0, mul(n1, r)), b0 = add(p1, mul(n0, r)), b1 = add(p1, mul(n1, r));
      b.vertex(a0, n0, col); b.vertex(a1, n1, col); b.vertex(b1, n1, col);
      b.vertex(a0, n0, col); b.vertex(b1, n1, col); b.vertex(b0, n0, col);
      if (!capsule) { b.tri(p0, a1, a0, mul(w, -1), col); b.tri(p1, b0, b1, w, col); } }
    if (!capsule) return;
    var M = 8;
    [[p1, w], [p0, mul(w, -1)]].forEach(function (end) {
      var c = end[0], z = end[1];
      for (var i = 0; i < M; i++) { var f0 = Math.PI / 2 * i / M, f1 = Math.PI / 2 * (i + 1) / M;
        for (var k = 0; k < SEG; k++) {
          var d = [add(mul(ring[k], Math.cos(f0)), mul(z, Math.sin(f0))),
                   add(mul(ring[k + 1], Math.cos(f0)), mul(z, Math.sin(f0))),
                   add(mul(ring[k + 1], Math.cos(f1)), mul(z, Math.sin(f1))),
                   add(mul(ring[k], Math.cos(f1)), mul(z, Math.sin(f1)))];
          var p = d.map(function (n) { return add(c, mul(n, r)); });
          b.vertex(p[0], d[0], col); b.vertex(p[1], d[1], col); b.vertex(p[2], d[2], col);
          b.vertex(p[0], d[0], col); b.vertex(p[2], d[2], col); b.vertex(p[3], d[3], col); } } });
  }
  function mesh(b, t, c, R, col) {
    function at(i) { var l = [t[i], t[i + 1], t[i + 2]];
      return R ? [c[0] + R[0] * l[0] + R[1] * l[1] + R[2] * l[2], c[1] + R[3] * l[0] + R[4] * l[1] + R[5] * l[2],
                  c[2] + R[6] * l[0] + R[7] * l[1] + R[8] * l[2]] : l; }
    for (var i = 0; i + 8 < t.length; i += 9) { var p = at(i), q = at(i + 3), s = at(i + 6);
      var n = cross(sub(q, p), sub(s, p)); if (dot(n, n) > 0) b.tri(p, q, s, unit(n), col); }
  }
  var IDENTITY = [1, 0, 0, 0, 1, 0, 0, 0, 1];
  function colourOf(body) { return rgb(body.colour || scene.colours[body.group]); }
  // A body in world terms: {kind: "tube" | "capsule" | "obox" | "mesh", ..., ref: its reference point}
  function fixedSolid(d) {
    if (d.kind === "box") return {kind: "obox", c: mul(add(d.lo, d.hi), 0.5), R: IDENTITY,
      h: mul(sub(d.hi, d.lo), 0.5)};
    if (d.kind === "obox") return {kind: "obox", c: d.center, R: d.rotation, h: d.half};
    if (d.kind === "cylinder" && d.center) return {kind: "tube", p0: [d.center[0], d.center[1], d.z0],
      p1: [d.center[0], d.center[1], d.z1], r: d.radius};
    if (d.kind === "cylinder") return {kind: "tube", p0: d.p0, p1: d.p1, r: d.radius};
    if (d.kind === "capsule") return {kind: "capsule", p0: d.p0, p1: d.p1, r: d.radius};
    return {kind: "mesh", t: d.triangles, c: [0, 0, 0], R: null};
  }
  var offsets = [], stride = 0;
  scene.moving.forEach(function (d) { offsets.push(stride); stride += (d.kind === "capsule" || d.kind === "cylinder") ?
    6 : 12; });
  function movingSolid(d, pose, o) {
    if (d.kind === "capsule" || d.kind === "cylinder") return {kind: d.kind === "capsule" ? "capsule" : "tube",
      p0: pose.slice(o, o + 3), p1: pose.slice(o + 3, o + 6), r: d.radius};
    var c = pose.slice(o, o + 3), R = pose.slice(o + 3, o + 12);
    if (d.kind === "box") return {kind: "obox", c: c, R: R, h: d.half};
    return {kind: "mesh", t: d.triangles, c: c, R: R};
  }
  function refPoint(s) {
    if (s.kind === "obox") return s.c;
    if (s.kind === "mesh") { var m = [0, 0, 0], n = 0, t = s.t;
      for (var i = 0; i + 2 < t.length; i += 3) { m = add(m, [t[i], t[i + 1], t[i + 2]]); n++; }
      m = n ? mul(m, 1 / n) : m; if (!s.R) return m; var R = s.R;
      return add(s.c, [R[0] * m[0] + R[1] * m[1] + R[2] * m[2], R[3] * m[0] + R[4] * m[1] + R[5] * m[2],
                       R[6] * m[0] + R[7] * m[1] + R[8] * m[2]]); }
    return mul(add(s.p0, s.p1), 0.5);
  }
  function tessellate(b, s, col) {
    if (s.kind === "obox") obox(b, s.c, s.R, s.h, col);
    else if (s.kind === "tube") tube(b, s.p0, s.p1, s.r, col, false);
    else if (s.kind === "capsule") tube(b, s.p0, s.p1, s.r, col, true);
    else mesh(b, s.t, s.c, s.R, col);
  }

  // ---- GL program and buffers
  var VS = "#version 300 es\nin vec3 a_pos; in vec3 a_normal; in vec3 a_colour; uniform mat4 u_mvp;" +
    " uniform vec3 u_light; uniform float u_lit; out vec3 v_colour; void main() {" +
    " gl_Position = u_mvp * vec4(a_pos, 1.0); float d = abs(dot(normalize(a_normal), u_light));" +
    " v_colour = a_colour * mix(1.0, 0.35 + 0.65 * d, u_lit); }";
  var FS = "#version 300 es\nprecision mediump float; in vec3 v_colour; out vec4 colour;" +
    " void main() { colour = vec4(v_colour, 1.0); }";
  function shader(type, source) { var s = gl.createShader(type); gl.shaderSource(s, source); gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(s));
    return s; }
  var program = gl.createProgram();
  gl.attachShader(program, shader(gl.VERTEX_SHADER, VS)); gl.attachShader(program, shader(gl.FRAGMENT_SHADER, FS));
  gl.bindAttribLocation(program, 0, "a_pos"); gl.bindAttribLocation(program, 1, "a_normal");
  gl.bindAttribLocation(program, 2, "a_colour"); gl.linkProgram(program);
  if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error("program: " + gl.getProgramInfoLog(program));
  var uMvp = gl.getUniformLocation(program, "u_mvp"), uLight = gl.getUniformLocation(program, "u_light"),
    uLit = gl.getUniformLocation(program, "u_lit");
  function buffer() { var vao = gl.createVertexArray(), vbo = gl.createBuffer(); gl.bindVertexArray(vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, vbo);
    for (var a = 0; a < 3; a++) { gl.enableVertexAttribArray(a);
      gl.vertexAttribPointer(a, 3, gl.FLOAT, false, 36, a * 12); }
    gl.bindVertexArray(null); return {vao: vao, vbo: vbo, count: 0}; }
  function upload(buf, batch) { gl.bindBuffer(gl.ARRAY_BUFFER, buf.vbo);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(batch.v), gl.DYNAMIC_DRAW); buf.count = batch.v.length / 9; }
  var fixedBuf = buffer(), movingBuf = buffer(), pathBuf = buffer(), markerBuf = buffer();

  var fixedSolids = scene.fixed.map(function (d) { return {body: d, solid: fixedSolid(d)}; });
  var batch = new Batch();
  fixedSolids.forEach(function (f) { tessellate(batch, f.solid, colourOf(f.body)); });
  upload(fixedBuf, batch);
  var frames = scene.frames, F = frames.t.length, frame = 0, movingSolids = [];

  // ---- the camera: orbit about the setup's centre (stock, fixtures, path and the head at its first frame)
  var lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  function grow(p) { for (var i = 0; i < 3; i++) { lo[i] = Math.min(lo[i], p[i]); hi[i] = Math.max(hi[i], p[i]); } }
  function growBatch(b) { for (var i = 0; i < b.v.length; i += 9) grow([b.v[i], b.v[i + 1], b.v[i + 2]]); }
  fixedSolids.forEach(function (f) { if (f.body.group !== "machine") { var b = new Batch();
    tessellate(b, f.solid, [0, 0, 0]); growBatch(b); } });
  for (var i = 0; i + 2 < scene.path.xyz.length; i += 3) grow(scene.path.xyz.slice(i, i + 3));
  var first = new Batch(); scene.moving.forEach(function (d, k) {
    tessellate(first, movingSolid(d, frames.poses[0], offsets[k]), [0, 0, 0]); }); growBatch(first);
  if (!(hi[0] >= lo[0])) { growBatch(batch); }
  if (!(hi[0] >= lo[0])) { lo = [-1, -1, -1]; hi = [1, 1, 1]; }
  var centre = mul(add(lo, hi), 0.5), radius = Math.max(Math.sqrt(dot(sub(hi, lo), sub(hi, lo))) / 2, 1);
  var FOV = 35 * Math.PI / 180, yaw = -60 * Math.PI / 180, pitch = 28 * Math.PI / 180;
  var distance = radius / Math.sin(FOV / 2) * 0.9, mvp = null;

  // ---- the path as lines coloured by clearance; rapids dashed; after the frame shown paler
  var margin = scene.margin, far = Math.max(5 * margin, margin + 10);
  var RED = rgb("#d62728"), ORANGE = rgb("#ff7f0e"), GREEN = rgb("#2ca02c"), BLUE = rgb("#1f77b4"), WHITE = [1, 1, 1];
  function clearanceColour(c) { if (c === null) return BLUE; if (c <= 0) return RED; if (c < margin) return ORANGE;
    return mix(GREEN, BLUE, Math.min(1, (c - margin) / Math.max(far - margin, 1e-9))); }
  var dash = radius / 60, UP = [0, 0, 1];
  function pathBatch() {
    var b = new Batch(), p = scene.path, n = p.clearance.length;
    for (var i = 0; i + 1 < n; i++) {
      var a = p.xyz.slice(3 * i, 3 * i + 3), e = p.xyz.slice(3 * i + 3, 3 * i + 6), ca = p.clearance[i],
        ce = p.clearance[i + 1];
      var c = clearanceColour(ca === null ? ce : ce === null ? ca : Math.min(ca, ce));
      if (p.frame[i + 1] > frame) c = mix(c, WHITE, 0.6);
      if (!p.rapid[i + 1]) { b.vertex(a, UP, c); b.vertex(e, UP, c); continue; }
      var d = sub(e, a), len = Math.sqrt(dot(d, d)), pieces = Math.max(1, Math.ceil(len / dash));
      for (var k = 0; k < pieces; k += 2) { b.vertex(add(a, mul(d, k / pieces)), UP, c);
        b.vertex(add(a, mul(d, Math.min(k + 1, pieces) / pieces)), UP, c); }
    }
    return b;
  }
  // ---- findings: small octahedra at their xyz
  var markers = new Batch(), size = radius * 0.03;
  scene.findings.forEach(function (f) { var c = f.severity === "collision" ? RED : ORANGE, x = f.xyz;
    var ax = [[size, 0, 0], [0, size, 0], [0, 0, size]];
    for (var s = 0; s < 8; s++) { var p = [mul(ax[0], s & 1 ? 1 : -1), mul(ax[1], s & 2 ? 1 : -1),
      mul(ax[2], s & 4 ? 1 : -1)];
      markers.tri(add(x, p[0]), add(x, p[1]), add(x, p[2]), unit(add(add(p[0], p[1]), p[2])), c); } });
  upload(markerBuf, markers);

  function project(p) { var m = mvp, w = m[3] * p[0] + m[7] * p[1] + m[11] * p[2] + m[15];
    var x = (m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12]) / w, y = (m[1] * p[0] + m[5] * p[1] + m[9] * p[2] +
      m[13]) / w;
    return [Math.round((x + 1) / 2 * canvas.width), Math.round((1 - y) / 2 * canvas.height)]; }

  var drawn = false;
  function draw() {
    var ratio = window.devicePixelRatio || 1, w = Math.max(1, Math.round(canvas.clientWidth * ratio)),
      h = Math.max(1, Math.round(canvas.clientHeight * ratio));
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, w, h);
    gl.clearColor(BG[0] / 255, BG[1] / 255, BG[2] / 255, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    var dir = [Math.cos(pitch) * Math.cos(yaw), Math.cos(pitch) * Math.sin(yaw), Math.sin(pitch)];
    var eye = add(centre, mul(dir, distance));
    var near = Math.max(distance - 3 * radius, distance * 0.01), farPlane = distance + 3 * radius;
    mvp = matmul(perspective(FOV, w / h, near, farPlane), lookAt(eye, centre, UP));
    var right = unit(cross(dir, UP));
    gl.useProgram(program); gl.uniformMatrix4fv(uMvp, false, mvp);
    gl.uniform3fv(uLight, unit(add(add(mul(dir, 0.7), mul(UP, 0.5)), mul(right, 0.3))));
    function run(buf, mode) { if (!buf.count) return; gl.bindVertexArray(buf.vao); gl.drawArrays(mode, 0, buf.count); }
    gl.enable(gl.DEPTH_TEST); gl.depthMask(true); gl.uniform1f(uLit, 1); run(fixedBuf, gl.TRIANGLES);
    gl.disable(gl.DEPTH_TEST); gl.uniform1f(uLit, 0); run(pathBuf, gl.LINES);  // over the stock, under the head
    gl.enable(gl.DEPTH_TEST); gl.uniform1f(uLit, 1); run(movingBuf, gl.TRIANGLES);
    gl.disable(gl.DEPTH_TEST); run(markerBuf, gl.TRIANGLES);
    gl.bindVertexArray(null);
    var error = gl.getError();
    if (error !== gl.NO_ERROR) throw new Error("WebGL error " + error);
    if (!drawn) { drawn = true; byId("scene-drawn").textContent = "1"; }
  }
  var pending = false;
  function redraw() { if (pending) return; pending = true;
    requestAnimationFrame(function () { pending = false;
      try { draw(); } catch (e) { fail(String(e.message || e)); } }); }

  var slider = byId("scene-frame"), label = byId("scene-frame-label"), cursor = byId("scene-cursor"),
    plot = byId("scene-clearance");
  window.sceneSetFrame = function (k) {
    k = Math.max(0, Math.min(F - 1, Math.round(Number(k) || 0)));
    frame = k; slider.value = String(k);
    label.textContent = "frame " + k + " of " + (F - 1) + ": t " + frames.t[k].toFixed(3) + " s, CL line " +
      frames.line[k];
    var b = new Batch(), pose = frames.poses[k];
    movingSolids = scene.moving.map(function (d, j) { var s = movingSolid(d, pose, offsets[j]);
      tessellate(b, s, colourOf(d)); return {body: d, solid: s}; });
    upload(movingBuf, b); upload(pathBuf, pathBatch());
    if (cursor && plot) { var t0 = Number(plot.dataset.t0), t1 = Number(plot.dataset.t1);
      var x = Number(plot.dataset.left) + (frames.t[k] - t0) / (t1 - t0) * Number(plot.dataset.width);
      cursor.setAttribute("x1", x.toFixed(1)); cursor.setAttribute("x2", x.toFixed(1)); }
    Array.prototype.forEach.call(document.querySelectorAll("#scene-findings button[data-frame]"), function (e) {
      e.parentNode.className = e.parentNode.className.replace(/ ?shown/, "") +
        (Number(e.dataset.frame) === k ? " shown" : ""); });
    draw();
    return k;
  };
  // The test hook: pixels read back (count not background, the centre's colour, each body's reference point
  // projected and the colour there; and the colours at the given [x, y] canvas pixels, from the top left).
  window.sceneProbe = function (points) {
    var w = canvas.width, h = canvas.height, px = new Uint8Array(w * h * 4), count = 0;
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    for (var i = 0; i < px.length; i += 4)
      if (px[i] !== BG[0] || px[i + 1] !== BG[1] || px[i + 2] !== BG[2]) count++;
    function at(x, y) { if (x < 0 || y < 0 || x >= w || y >= h) return null; var k = ((h - 1 - y) * w + x) * 4;
      return [px[k], px[k + 1], px[k + 2], px[k + 3]]; }
    function bodies(list, moving) { return list.map(function (b) { var p = project(refPoint(b.solid));
      return {name: b.body.name, group: b.body.group, moving: moving, x: p[0], y: p[1], rgba: at(p[0], p[1])}; }); }
    return {frame: frame, width: w, height: h, nonBackground: count, centre: at(w >> 1, h >> 1),
      bodies: bodies(fixedSolids, false).concat(bodies(movingSolids, true)),
      points: (points || []).map(function (p) { return {x: p[0], y: p[1], rgba: at(p[0], p[1])}; })};
  };

  slider.addEventListener("input", function () { window.sceneSetFrame(slider.value); });
  Array.prototype.forEach.call(document.querySelectorAll("#scene-findings button[data-frame]"), function (e) {
    e.addEventListener("click", function () { window.sceneSetFrame(e.dataset.frame); }); });
  var drag = null;
  canvas.addEventListener("pointerdown", function (e) { drag = [e.clientX, e.clientY];
    canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointermove", function (e) { if (!drag) return;
    yaw -= (e.clientX - drag[0]) * 0.01; pitch = Math.max(-1.55, Math.min(1.55, pitch + (e.clientY - drag[1]) * 0.01));
    drag = [e.clientX, e.clientY]; redraw(); });
  canvas.addEventListener("pointerup", function () { drag = null; });
  canvas.addEventListener("wheel", function (e) { e.preventDefault();
    distance = Math.max(radius * 0.05, Math.min(radius * 50, distance * Math.exp(e.deltaY * 0.001))); redraw(); },
    {passive: false});
  window.addEventListener("resize", redraw);

  // The URL hash: #frame=K selects frame K; &probe (or probe=x,y,x,y...) writes sceneProbe() to #scene-probe.
  function fromHash() {
    var h = {}; location.hash.replace(/^#/, "").split("&").forEach(function (kv) { var i = kv.indexOf("=");
      if (kv) h[i < 0 ? kv : kv.slice(0, i)] = i < 0 ? "" : decodeURIComponent(kv.slice(i + 1)); });
    window.sceneSetFrame(h.frame === undefined ? frame : h.frame);
    if (h.probe !== undefined) { var n = h.probe.split(",").filter(function (v) { return v !== ""; }).map(Number),
      points = []; for (var i = 0; i + 1 < n.length; i += 2) points.push([n[i], n[i + 1]]);
      byId("scene-probe").textContent = JSON.stringify(window.sceneProbe(points)); }
  }
  window.addEventListener("hashchange", function () {
    try { fromHash(); } catch (e) { fail(String(e.message || e)); } });
  fromHash();
  }
})();
"""


def _box_distance(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances of points to an axis-aligned box (0 inside) and the box's nearest points."""
    nearest = np.clip(points, lo, hi)
    return np.linalg.norm(points - nearest, axis=-1), nearest


def example_scene(frames: int = 50) -> dict:
    """A small plausible scene: a round table, a stock block, two clamps (a box and a mesh
    wedge), a head (spindle, holder, cutter, housing) coming down in rapids, plunging and
    cutting across the stock while tilting towards the first clamp, where the holder passes it
    closer than the margin: one near miss. Clearances of the head's round bodies as capsules
    against the boxes (the cutter not against the stock it cuts)."""
    margin = 2.0
    stock_lo, stock_hi = np.array([-80.0, -60.0, -60.0]), np.array([80.0, 60.0, 0.0])
    clamp_lo, clamp_hi = np.array([95.0, -30.0, -60.0]), np.array([135.0, 30.0, 16.2])
    # The second clamp: a wedge (a prism over a triangle in x-z), 8 triangles.
    corners = ((-95.0, -60.0), (-135.0, -60.0), (-135.0, -20.0))
    front = [(x, -30.0, z) for x, z in corners]
    back = [(x, 30.0, z) for x, z in corners]
    wedge = [front, back[::-1]]
    for i in range(3):
        j = (i + 1) % 3
        wedge += [[front[i], front[j], back[j]], [front[i], back[j], back[i]]]
    fixed = [
        {"name": "table", "group": "machine", "kind": "cylinder", "center": [0, 0], "z0": -140, "z1": -60,
         "radius": 315},
        {"name": "stock", "group": "stock", "kind": "box", "lo": stock_lo.tolist(), "hi": stock_hi.tolist()},
        {"name": "clamp 1", "group": "fixture", "kind": "box", "lo": clamp_lo.tolist(), "hi": clamp_hi.tolist()},
        {"name": "clamp 2", "group": "fixture", "kind": "mesh",
         "triangles": [v for tri in wedge for p in tri for v in p]},
    ]
    moving = [{"name": "spindle", "group": "head", "kind": "capsule", "radius": 60},
              {"name": "holder", "group": "holder", "kind": "cylinder", "radius": 20},
              {"name": "cutter", "group": "tool", "kind": "cylinder", "radius": 5},
              {"name": "housing", "group": "head", "kind": "box", "half": [130, 110, 60]}]
    k = np.arange(frames)
    rapid_end, plunge_end = round(0.3 * frames), round(0.4 * frames)
    tips, tilts = [], []
    for i in k:
        if i < rapid_end:
            s = i / max(rapid_end - 1, 1)
            tips.append([-70.0, 20.0, 150.0 + (5.0 - 150.0) * s])
            tilts.append(0.0)
        elif i < plunge_end:
            s = (i - rapid_end + 1) / (plunge_end - rapid_end)
            tips.append([-70.0, 20.0, 5.0 - 8.0 * s])
            tilts.append(0.0)
        else:
            s = (i - plunge_end) / max(frames - 1 - plunge_end, 1)
            tips.append([-70.0 + 140.0 * s, 20.0, -3.0])
            tilts.append(np.radians(20.0) * s)
    tips_a, tilt = np.array(tips), np.array(tilts)
    axis = np.stack([np.sin(tilt), np.zeros_like(tilt), np.cos(tilt)], axis=1)
    rot = np.zeros((frames, 3, 3))
    rot[:, 0, 0], rot[:, 0, 2], rot[:, 1, 1], rot[:, 2, 0], rot[:, 2, 2] = \
        np.cos(tilt), np.sin(tilt), 1.0, -np.sin(tilt), np.cos(tilt)
    spans = {"spindle": (150.0, 350.0), "holder": (40.0, 90.0), "cutter": (0.0, 40.0)}
    radii = {"spindle": 60.0, "holder": 20.0, "cutter": 5.0}
    ends = {name: (tips_a + axis * a, tips_a + axis * b) for name, (a, b) in spans.items()}
    housing = tips_a + axis * 440.0
    poses = np.concatenate([*(np.hstack(ends[n]) for n in ("spindle", "holder", "cutter")),
                            housing, rot.reshape(frames, 9)], axis=1)
    boxes = {"stock": (stock_lo, stock_hi), "clamp 1": (clamp_lo, clamp_hi),
             "clamp 2": (np.array([-135.0, -30.0, -60.0]), np.array([-95.0, 30.0, -20.0])),
             "table": (np.array([-315.0, -315.0, -140.0]), np.array([315.0, 315.0, -60.0]))}
    s = np.linspace(0.0, 1.0, 41)[None, :, None]
    best = np.full(frames, np.inf)
    pair: list[tuple[str, str]] = [("", "")] * frames
    where = np.zeros((frames, 3))
    for body, (p0, p1) in ends.items():
        samples = p0[:, None, :] + (p1 - p0)[:, None, :] * s
        for other, (lo, hi) in boxes.items():
            if body == "cutter" and other == "stock":
                continue
            gap, nearest = _box_distance(samples, lo, hi)
            gap = gap - radii[body]
            j = np.argmin(gap, axis=1)
            value = gap[k, j]
            better = value < best
            best = np.where(better, value, best)
            where[better] = nearest[k, j][better]
            for i in np.flatnonzero(better):
                pair[i] = (body, other)
    line = 100 + 2 * k
    t = 0.2 * k
    worst = int(np.argmin(best))
    findings = []
    if best[worst] < margin:
        findings.append({"severity": "collision" if best[worst] <= 0 else "near miss", "bodies": list(pair[worst]),
                         "clearance": float(best[worst]), "line": int(line[worst]), "xyz": where[worst].tolist(),
                         "frame": worst})
    return {"units": "mm", "frame": "table", "margin": margin, "fixed": fixed, "moving": moving,
            "frames": {"t": t.tolist(), "line": line.tolist(), "poses": poses.tolist()},
            "path": {"xyz": tips_a.ravel().tolist(), "clearance": best.tolist(),
                     "rapid": (k < rapid_end).tolist(), "frame": k.tolist()},
            "clearance": {"t": t.tolist(), "mm": best.tolist()},
            "findings": findings}


__all__ = ["MAX_FRAMES", "MAX_PATH_POINTS", "SCENE_SCRIPT", "SCENE_STYLE", "clearance_plot", "embedded",
           "example_scene", "normalise", "scene_lines", "scene_section"]
