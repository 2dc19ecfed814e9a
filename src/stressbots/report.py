"""The HTML report of the main job: one self-contained file that opens offline.

Pure presentation: :func:`build_report` takes results that are already computed (the voltage analysis,
the plan, the waveform summary, the closed-loop ``result.json`` document, pictures as PNG bytes, an
animation made by :func:`animation_data`, the event log) and returns the HTML text. Nothing is fetched
from a network: pictures are embedded as ``data:`` URIs, the style and the small animation script are
inline, and the only links are relative links to the files written beside the report.

The page has one ``<section>`` per part, with stable ids that tests and readers can rely on:
``verdict``, ``design``, ``waveform``, ``plan``, ``run``, ``structure``, ``metrics``, ``events``,
``files``.

The animation draws the robots' bodies (rectangles, front edge thick) on a ``<canvas>`` from a JSON
array of poses resampled at uniform times (a few hundred frames), with play/pause, a time slider and a
speed choice. Any script error is recorded by a handler installed first and shown on the page
(``data-js-errors`` on ``<html>`` counts them, ``data-js="ready"`` marks a script that ran to the end),
so a headless browser can check the page.
"""

from __future__ import annotations

import base64
import html
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["SECTIONS", "animation_data", "animation_html", "animation_page", "build_report", "coverage_page", "coverage_section",
           "outcome_text", "png_data_uri"]

#: The report's sections, in page order: (id, heading).
SECTIONS: tuple[tuple[str, str], ...] = (
    ("verdict", "Outcome"),
    ("design", "Voltage design"),
    ("waveform", "Waveform"),
    ("plan", "Nominal plan"),
    ("run", "Closed-loop run"),
    ("structure", "Final structure"),
    ("metrics", "Metrics"),
    ("events", "Event log"),
    ("files", "Files"),
)

MAX_EVENT_ROWS = 2000
MAX_STATE_ROWS = 64


def outcome_text(result: Mapping[str, Any]) -> str:
    """``assembled``, or ``not assembled: <reason>`` for a ``result.json`` document."""
    if result.get("success"):
        return "assembled"
    reason = str(result.get("failure") or "unknown reason").strip()
    if reason.lower().startswith("not assembled"):
        reason = reason[len("not assembled"):].lstrip(" :,")
    return f"not assembled: {reason}"


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def png_data_uri(png: bytes) -> str:
    """A ``data:image/png;base64,...`` URI for embedding a picture."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def _json_script(obj: Any) -> str:
    """JSON text safe inside ``<script type="application/json">`` (no ``</`` sequence, no NaN)."""
    text = json.dumps(obj, separators=(",", ":"), allow_nan=False)
    return text.replace("</", "<\\/").replace("<!--", "<\\!--")


def _fmt(x: Any, spec: str = ".3g") -> str:
    if x is None:
        return "-"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    try:
        f = float(x)
    except (TypeError, ValueError):
        return str(x)
    if not math.isfinite(f):
        return "-"
    return format(f, spec)


def _pose(p: Sequence[float] | None) -> str:
    if p is None:
        return "-"
    return f"({p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f}&deg;)"


# ----------------------------------------------------------------------------------------------------
# Animation


def _hex(colour) -> str:
    from matplotlib.colors import to_hex

    return to_hex(colour)


#: Border around the drawn points when the scenario has no arena (um): room for the bodies' half-lengths.
_VIEW_MARGIN_UM = 300.0


def _uniform_poses(scenario, times, poses, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """The trajectory at ``frames`` uniform times: ``(grid (frames,) s, poses (frames, n, 3) um, rad)``.

    Of repeated times the last sample is kept (the pose after an instantaneous compliance move).
    Headings are unwrapped before the linear interpolation, so a robot turning through +-pi does not
    spin back. Without samples every frame shows the start poses.
    """
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    p = np.asarray(poses, dtype=np.float64).reshape(t.size, scenario.n, 3)
    if t.size:
        last = np.concatenate([np.diff(t) > 0, [True]])
        t, p = t[last], p[last]
    if t.size == 0:
        t = np.zeros(1)
        p = np.asarray(scenario.starts, dtype=np.float64)[None]
    grid = np.linspace(t[0], t[-1], frames) if t[-1] > t[0] else np.full(frames, t[0])
    out = np.empty((frames, scenario.n, 3))
    for i in range(scenario.n):
        theta = np.unwrap(p[:, i, 2])
        for c, series in enumerate((p[:, i, 0], p[:, i, 1], theta)):
            out[:, i, c] = np.interp(grid, t, series) if t.size > 1 else series[0]
    return grid, out


def _drawn_slots(scenario, goals, retargeted, retarget_time_s: float | None) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The slot outlines worth drawing: ``(planned (n, 3) or None, re-targeted (n, 3) or None)`` (um, rad).

    Planned slots with a non-finite entry (no plan) are not drawn. Re-targeted slots are drawn only with
    the time the controller learnt them, and only where they differ from the planned ones (by more than
    0.05 um or rad), so a run that never moved its targets shows one set of outlines.
    """
    g = None
    if goals is not None:
        garr = np.asarray(goals, dtype=np.float64).reshape(scenario.n, 3)
        if np.isfinite(garr).all():
            g = garr
    rt = None
    if retargeted is not None and retarget_time_s is not None and math.isfinite(float(retarget_time_s)):
        rarr = np.asarray(retargeted, dtype=np.float64).reshape(scenario.n, 3)
        if np.isfinite(rarr).all() and (g is None or not np.allclose(rarr, g, atol=0.05)):
            rt = rarr
    return g, rt


def _view_box(scenario, points: Sequence[np.ndarray]) -> list[float]:
    """The drawn area ``[x_min, y_min, x_max, y_max]`` (um): the arena, or else every finite point of
    ``points`` (each ``(k, 2)``) with a border of :data:`_VIEW_MARGIN_UM`."""
    if scenario.arena_um is not None:
        w, h = scenario.arena_um
        return [0.0, 0.0, float(w), float(h)]
    allp = np.vstack(points)
    allp = allp[np.isfinite(allp).all(axis=1)]
    lo, hi = allp.min(axis=0) - _VIEW_MARGIN_UM, allp.max(axis=0) + _VIEW_MARGIN_UM
    return [float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])]


def _timed_events(events: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The events the animation lists, by time (s, rounded to ms); events without a finite time are left out."""
    evs: list[dict[str, Any]] = []
    for ev in events:
        tt = ev.get("t_s", ev.get("time_s"))
        if tt is None or not math.isfinite(float(tt)):
            continue
        evs.append({"t": round(float(tt), 3), "robot": ev.get("robot"), "kind": str(ev.get("kind", "")),
                    "detail": str(ev.get("detail", ""))})
    evs.sort(key=lambda e: e["t"])
    return evs


def animation_data(
    scenario,
    times,
    poses,
    goals=None,
    events: Iterable[Mapping[str, Any]] = (),
    *,
    max_frames: int = 480,
    title: str = "",
    retargeted=None,
    retarget_time_s: float | None = None,
) -> dict[str, Any]:
    """The data of an animation: poses resampled at uniform times, bodies, colours, arena, events.

    ``times`` ``(M,)`` (s) and ``poses`` ``(M, n, 3)`` (um, rad) are a sampled trajectory (e.g.
    :meth:`stressbots.sim.SimulatedPlant.trace`); ``goals`` ``(n, 3)`` the planned slots, drawn as
    outlines from the start; ``retargeted`` ``(n, 3)`` the re-targeted slots (moved with G_1 as it
    really formed), drawn only from ``retarget_time_s`` on, when the controller knew them (not drawn
    when that time is unknown); ``events`` dicts with ``t_s``, ``robot``, ``kind``, ``detail``. Poses
    between samples are interpolated linearly (headings unwrapped), so the size does not depend on the
    run's length.
    """
    from .viz import robot_colours

    frames = int(max(2, max_frames))
    grid, out = _uniform_poses(scenario, times, poses, frames)
    g, rt = _drawn_slots(scenario, goals, retargeted, retarget_time_s)
    box = _view_box(scenario, [out[:, :, :2].reshape(-1, 2)] + [s[:, :2] for s in (g, rt) if s is not None])
    return {
        "title": title,
        "names": list(scenario.names),
        "lengths": [round(float(x), 3) for x in scenario.lengths_um],
        "widths": [round(float(x), 3) for x in scenario.widths_um],
        "colours": [_hex(c) for c in robot_colours(scenario.n)],
        "box": box,
        "arena": scenario.arena_um is not None,
        "t": [round(float(x), 3) for x in grid],
        "poses": np.round(out, 2).reshape(frames, -1).tolist(),
        "goals": None if g is None else np.round(g, 3).tolist(),
        "retargeted": None if rt is None else np.round(rt, 3).tolist(),
        "retarget_t": None if rt is None or retarget_time_s is None else round(float(retarget_time_s), 3),
        "events": _timed_events(events),
    }


_ANIM_JS = r"""
(function () {
  "use strict";
  function corners(x, y, th, L, W) {
    var hx = Math.sin(th), hy = Math.cos(th), rx = Math.cos(th), ry = -Math.sin(th);
    var a = L / 2, b = W / 2;
    return [[x + a * hx - b * rx, y + a * hy - b * ry], [x + a * hx + b * rx, y + a * hy + b * ry],
            [x - a * hx + b * rx, y - a * hy + b * ry], [x - a * hx - b * rx, y - a * hy - b * ry]];
  }
  function init(root) {
    var src = document.getElementById(root.getAttribute("data-src"));
    var d = JSON.parse(src.textContent);
    var canvas = root.querySelector("canvas");
    var slider = root.querySelector("input[type=range]");
    var button = root.querySelector("button");
    var speedSel = root.querySelector("select");
    var label = root.querySelector(".anim-time");
    var log = root.querySelector(".anim-events");
    var ctx = canvas.getContext("2d");
    var n = d.names.length, F = d.t.length;
    var box = d.box, pad = 20, padL = 58, padB = 34;
    var cssW = Math.min(root.clientWidth || 760, 760);
    var bw = box[2] - box[0], bh = box[3] - box[1];
    var s = (cssW - padL - pad) / bw;
    var cssH = Math.min(bh * s + pad + padB, 760);
    s = Math.min(s, (cssH - pad - padB) / bh);
    var ratio = window.devicePixelRatio || 1;
    canvas.width = Math.round(cssW * ratio);
    canvas.height = Math.round(cssH * ratio);
    canvas.style.width = cssW + "px";
    canvas.style.height = cssH + "px";
    function px(x, y) { return [padL + (x - box[0]) * s, cssH - padB - (y - box[1]) * s]; }
    function niceStep(span, count) {
      var raw = span / count, mag = Math.pow(10, Math.floor(Math.log10(raw))), f = raw / mag;
      return (f < 1.5 ? 1 : f < 3.5 ? 2 : f < 7.5 ? 5 : 10) * mag;
    }
    function axes() {
      var step = niceStep(Math.max(bw, bh), 6), v, q;
      ctx.strokeStyle = "#999999"; ctx.fillStyle = "#444444"; ctx.lineWidth = 1; ctx.font = "11px sans-serif";
      ctx.textAlign = "center"; ctx.textBaseline = "top";
      for (v = Math.ceil(box[0] / step) * step; v <= box[2] + 1e-9; v += step) {
        q = px(v, box[1]); ctx.beginPath(); ctx.moveTo(q[0], q[1]); ctx.lineTo(q[0], q[1] + 5); ctx.stroke();
        ctx.fillText(String(Math.round(v)), q[0], q[1] + 7);
      }
      ctx.textAlign = "right"; ctx.textBaseline = "middle";
      for (v = Math.ceil(box[1] / step) * step; v <= box[3] + 1e-9; v += step) {
        q = px(box[0], v); ctx.beginPath(); ctx.moveTo(q[0], q[1]); ctx.lineTo(q[0] - 5, q[1]); ctx.stroke();
        ctx.fillText(String(Math.round(v)), q[0] - 7, q[1]);
      }
      ctx.save(); ctx.translate(12, (pad + cssH - padB) / 2); ctx.rotate(-Math.PI / 2);
      ctx.textAlign = "center"; ctx.fillText("y (um)", 0, 0); ctx.restore();
      ctx.textAlign = "right"; ctx.textBaseline = "bottom"; ctx.fillText("x (um)", cssW - pad, cssH - 1);
      var bar = niceStep(bw, 5), a = px(box[0] + 0.04 * bw, box[1] + 0.04 * bh), b = px(box[0] + 0.04 * bw + bar, box[1] + 0.04 * bh);
      ctx.strokeStyle = "#222222"; ctx.lineWidth = 3; ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
      ctx.lineWidth = 1; ctx.beginPath();
      ctx.moveTo(a[0], a[1] - 4); ctx.lineTo(a[0], a[1] + 4); ctx.moveTo(b[0], b[1] - 4); ctx.lineTo(b[0], b[1] + 4); ctx.stroke();
      ctx.fillStyle = "#222222"; ctx.textAlign = "center"; ctx.textBaseline = "bottom";
      ctx.fillText(String(bar) + " um", (a[0] + b[0]) / 2, a[1] - 5);
      ctx.textAlign = "start"; ctx.textBaseline = "alphabetic";
    }
    function pose(f, i) { var r = d.poses[f]; return [r[3 * i], r[3 * i + 1], r[3 * i + 2]]; }
    function poly(c, fill, stroke, width, dash) {
      ctx.beginPath();
      for (var k = 0; k < c.length; k++) {
        var q = px(c[k][0], c[k][1]);
        if (k === 0) { ctx.moveTo(q[0], q[1]); } else { ctx.lineTo(q[0], q[1]); }
      }
      ctx.closePath();
      if (fill) { ctx.fillStyle = fill; ctx.fill(); }
      if (stroke) { ctx.setLineDash(dash || []); ctx.strokeStyle = stroke; ctx.lineWidth = width || 1; ctx.stroke(); ctx.setLineDash([]); }
    }
    function alpha(hex, a) {
      var v = parseInt(hex.slice(1), 16);
      return "rgba(" + ((v >> 16) & 255) + "," + ((v >> 8) & 255) + "," + (v & 255) + "," + a + ")";
    }
    var frame = 0, playing = false, last = null, acc = 0;
    function draw() {
      ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
      ctx.fillStyle = "#ffffff";
      ctx.fillRect(0, 0, cssW, cssH);
      if (d.arena) { poly([[box[0], box[1]], [box[2], box[1]], [box[2], box[3]], [box[0], box[3]]], "#fbfbf8", "#555555", 1.2); }
      axes();
      var i, f, p, c;
      if (d.goals) {
        for (i = 0; i < n; i++) {
          c = corners(d.goals[i][0], d.goals[i][1], d.goals[i][2], d.lengths[i], d.widths[i]);
          poly(c, null, "#888888", 1, [4, 3]);
        }
      }
      if (d.retargeted && d.t[frame] >= d.retarget_t - 1e-9) {
        for (i = 0; i < n; i++) {
          c = corners(d.retargeted[i][0], d.retargeted[i][1], d.retargeted[i][2], d.lengths[i], d.widths[i]);
          poly(c, null, alpha(d.colours[i], 0.9), 1, [1.5, 2.5]);
        }
      }
      for (i = 0; i < n; i++) {
        ctx.beginPath();
        for (f = 0; f <= frame; f++) {
          p = pose(f, i); var q = px(p[0], p[1]);
          if (f === 0) { ctx.moveTo(q[0], q[1]); } else { ctx.lineTo(q[0], q[1]); }
        }
        ctx.strokeStyle = alpha(d.colours[i], 0.7); ctx.lineWidth = 1.2; ctx.stroke();
        p = pose(0, i);
        poly(corners(p[0], p[1], p[2], d.lengths[i], d.widths[i]), null, alpha(d.colours[i], 0.35), 1);
      }
      for (i = 0; i < n; i++) {
        p = pose(frame, i);
        c = corners(p[0], p[1], p[2], d.lengths[i], d.widths[i]);
        poly(c, alpha(d.colours[i], 0.6), d.colours[i], 1.2);
        var a = px(c[0][0], c[0][1]), b = px(c[1][0], c[1][1]);
        ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.strokeStyle = d.colours[i]; ctx.lineWidth = 3.5; ctx.stroke();
        var m = px(p[0], p[1]);
        ctx.fillStyle = "#222222"; ctx.font = "12px sans-serif"; ctx.fillText(d.names[i], m[0] + 8, m[1] - 8);
      }
      var t = d.t[frame];
      label.textContent = "t = " + t.toFixed(1) + " s of " + d.t[F - 1].toFixed(1) + " s (simulated), frame " + (frame + 1) + "/" + F;
      var recent = [];
      for (var k = 0; k < d.events.length && d.events[k].t <= t + 1e-9; k++) { recent.push(d.events[k]); }
      recent = recent.slice(-4);
      log.textContent = recent.length ? recent.map(function (e) {
        return e.t.toFixed(1) + " s  " + (e.robot ? e.robot + "  " : "") + e.kind + ": " + e.detail;
      }).join("\n") : "(no events yet)";
      slider.value = String(frame);
    }
    function step(now) {
      if (!playing) { return; }
      if (last !== null) {
        var dt = (d.t[F - 1] - d.t[0]) / Math.max(F - 1, 1);
        acc += (now - last) / 1000 * parseFloat(speedSel.value);
        if (dt > 0) { var adv = Math.floor(acc / dt); if (adv > 0) { acc -= adv * dt; frame = Math.min(frame + adv, F - 1); draw(); } }
        if (frame >= F - 1) { playing = false; button.textContent = "Play"; }
      }
      last = now;
      if (playing) { window.requestAnimationFrame(step); }
    }
    button.addEventListener("click", function () {
      if (playing) { playing = false; button.textContent = "Play"; return; }
      if (frame >= F - 1) { frame = 0; }
      playing = true; last = null; acc = 0; button.textContent = "Pause";
      window.requestAnimationFrame(step);
    });
    slider.max = String(F - 1);
    slider.addEventListener("input", function () { frame = parseInt(slider.value, 10) || 0; draw(); });
    var total = d.t[F - 1] - d.t[0], best = speedSel.options[0].value;
    for (var o = 0; o < speedSel.options.length; o++) {
      if (total / parseFloat(speedSel.options[o].value) >= 15) { best = speedSel.options[o].value; }
    }
    speedSel.value = best;
    draw();
  }
  var roots = document.querySelectorAll(".stressbots-anim");
  for (var r = 0; r < roots.length; r++) { init(roots[r]); }
  document.documentElement.setAttribute("data-js", "ready");
})();
"""

# Installed first: records script errors (also console.error) on <html> and in #js-errors.
_ERROR_HOOK_JS = r"""
(function () {
  "use strict";
  var errors = [];
  function show() {
    var box = document.getElementById("js-errors");
    if (box && errors.length) { box.hidden = false; box.textContent = "Script errors on this page:\n" + errors.join("\n"); }
  }
  function record(msg) {
    errors.push(String(msg));
    document.documentElement.setAttribute("data-js-errors", String(errors.length));
    show();
  }
  window.addEventListener("error", function (e) { record((e && e.message) || "script error"); });
  window.addEventListener("unhandledrejection", function (e) { record("unhandled rejection: " + (e && e.reason)); });
  var orig = console.error;
  console.error = function () { record(Array.prototype.join.call(arguments, " ")); if (orig) { orig.apply(console, arguments); } };
  document.addEventListener("DOMContentLoaded", show);
})();
"""

_SPEEDS = (1, 2, 5, 10, 20, 50, 100)


def animation_html(data: Mapping[str, Any], *, element_id: str = "anim") -> str:
    """An HTML fragment: the animation's canvas, controls and data (needs :data:`_ANIM_JS` on the page)."""
    opts = "".join(f'<option value="{v}">{v}&times;</option>' for v in _SPEEDS)
    return (
        f'<div class="stressbots-anim" id="{_e(element_id)}" data-src="{_e(element_id)}-data">'
        f'<canvas width="760" height="600" aria-label="animation of the run">Your browser cannot draw the animation.</canvas>'
        f'<div class="anim-controls"><button type="button">Play</button> '
        f'<input type="range" min="0" max="{max(len(data["t"]) - 1, 0)}" value="0" aria-label="time"> '
        f'<label>speed <select aria-label="playback speed">{opts}</select> simulated s per s</label></div>'
        f'<div class="anim-time"></div><pre class="anim-events"></pre>'
        f'<script type="application/json" id="{_e(element_id)}-data">{_json_script(data)}</script></div>'
    )


_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 0; color: #1d1d1f; background: #f6f6f3; }
main { max-width: 1120px; margin: 0 auto; padding: 0 20px 40px; }
header { background: #20303c; color: #fff; padding: 18px 20px; }
header h1 { margin: 0 auto; max-width: 1120px; font-size: 1.5em; }
header p { margin: 4px auto 0; max-width: 1120px; opacity: .85; }
nav { position: sticky; top: 0; background: #e9ece9; padding: 6px 20px; border-bottom: 1px solid #ccd; z-index: 1; }
nav a { margin-right: 14px; color: #20303c; text-decoration: none; font-size: .92em; }
section { background: #fff; margin: 18px 0; padding: 12px 20px 18px; border-radius: 6px; box-shadow: 0 1px 2px rgba(0,0,0,.08); }
h2 { font-size: 1.2em; border-bottom: 1px solid #dde; padding-bottom: 4px; }
h3 { font-size: 1.02em; margin-bottom: 4px; }
table { border-collapse: collapse; margin: 6px 0 10px; font-size: .88em; }
th, td { border: 1px solid #d6d9de; padding: 3px 8px; text-align: right; }
th { background: #eef0f3; }
td.l, th.l { text-align: left; }
.scroll { max-height: 480px; overflow: auto; border: 1px solid #e3e5e8; }
img { max-width: 100%; height: auto; }
.banner { padding: 12px 16px; border-radius: 6px; font-size: 1.15em; font-weight: 600; }
.ok { background: #e3f4e1; border: 1px solid #7bbf74; color: #1f5b1a; }
.fail { background: #fbe5e3; border: 1px solid #d9776c; color: #7d1d12; }
.note { color: #555; font-size: .9em; }
code, pre { font-family: ui-monospace, "DejaVu Sans Mono", monospace; font-size: .88em; }
pre.anim-events { background: #f4f4f1; padding: 6px 8px; min-height: 4.8em; white-space: pre-wrap; }
.anim-controls { margin: 6px 0; }
.anim-controls input[type=range] { width: 420px; vertical-align: middle; }
.stressbots-anim canvas { border: 1px solid #ccd; background: #fff; display: block; }
#js-errors { background: #fbe5e3; color: #7d1d12; padding: 8px; white-space: pre-wrap; }
.kv td:first-child { text-align: left; font-weight: 600; background: #f7f8f9; }
.kv td { text-align: left; }
"""


def _page(title: str, subtitle: str, body: str, *, nav: Sequence[tuple[str, str]] = ()) -> str:
    links = "".join(f'<a href="#{_e(i)}">{_e(h)}</a>' for i, h in nav)
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en" data-js="loading" data-js-errors="0">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        '<link rel="icon" href="data:,">\n'
        f"<title>{_e(title)}</title>\n"
        f"<script>{_ERROR_HOOK_JS}</script>\n"
        f"<style>{_CSS}</style>\n</head>\n<body>\n"
        f"<header><h1>{_e(title)}</h1><p>{subtitle}</p></header>\n"
        + (f"<nav>{links}</nav>\n" if links else "")
        + '<main>\n<pre id="js-errors" hidden></pre>\n'
        + body
        + f"\n</main>\n<script>{_ANIM_JS}</script>\n</body>\n</html>\n"
    )


def animation_page(data: Mapping[str, Any], *, title: str, subtitle: str = "") -> str:
    """A standalone, offline HTML page with one animation (``stressbots simulate`` writes it)."""
    body = f'<section id="run"><h2>{_e(title)}</h2>{animation_html(data)}</section>'
    return _page(title, subtitle or "closed-loop run on the simulated plant", body)


# ----------------------------------------------------------------------------------------------------
# The report


def _table(headers: Sequence[str], rows: Iterable[Sequence[Any]], *, left: Iterable[int] = (0,), cls: str = "") -> str:
    left = set(left)
    head = "".join(f'<th class="l">{_e(h)}</th>' if k in left else f"<th>{_e(h)}</th>" for k, h in enumerate(headers))
    body = []
    for row in rows:
        cells = "".join(f'<td class="l">{c}</td>' if k in left else f"<td>{c}</td>" for k, c in enumerate(row))
        body.append(f"<tr>{cells}</tr>")
    return f'<table{f" class={cls!r}" if cls else ""}><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table>'


def _kv(rows: Iterable[tuple[str, str]]) -> str:
    return '<table class="kv"><tbody>' + "".join(f"<tr><td>{_e(k)}</td><td>{v}</td></tr>" for k, v in rows) + "</tbody></table>"


def _img(figures: Mapping[str, bytes], key: str, alt: str) -> str:
    png = figures.get(key)
    if not png:
        return f'<p class="note">(no picture: {_e(alt)})</p>'
    return f'<img src="{png_data_uri(png)}" alt="{_e(alt)}">'


def _design_verdict(a) -> str:
    """Whether the design is STRING (order D_1..D_n and Lemma 1's count) or why not, and the electrode limits
    (V, Hz, ms) every level keeps."""
    e = a.electrodes
    if a.is_string:
        verdict = (
            f"<p><b>{a.n} robots, STRING</b>: order D<sub>1</sub>..D<sub>{a.n}</sub> = {_e(', '.join(a.order))} "
            f"(by snap-down voltage). Lemma 1: {a.count} accessible control states, the primitives "
            f"P<sub>0</sub>..P<sub>{a.n}</sub> (P<sub>k</sub>: D<sub>1</sub>..D<sub>k</sub> arm down, turning).</p>"
        )
    else:
        reasons = "".join(f"<li>{_e(r)}</li>" for r in a.reasons)
        verdict = (f"<p><b>{a.n} robots, not STRING</b>:</p><ul>{reasons}</ul>"
                   f"<p>{a.count} accessible control states (exhaustive search).</p>")
    return verdict + (
        f"<p>Limits: every level in [0, {e.max_V:g}] V and at least {e.margin_V:g} V from every threshold; drive band "
        f"[{e.drive_low_V:g}, {e.drive_high_V:g}] V at {e.drive_frequency_hz:g} Hz; setting levels held {e.hold_s * 1e3:g} ms.</p>"
    )


def _robots_table(scenario, a, goals) -> str:
    """One row per robot (scenario order): its place D_k in the STRING order, thresholds (V), body (um),
    speed (um/s), turning radius (um), start and planned slot (headings in degrees)."""
    rank = {i: k + 1 for k, i in enumerate(a.order_index)} if a.is_string else {}
    rows = []
    for i, r in enumerate(scenario.robots):
        start = None if r.start is None else (r.start.x, r.start.y, math.degrees(r.start.theta) % 360.0)
        goal = None if goals is None or not np.isfinite(goals[i]).all() else (goals[i][0], goals[i][1], math.degrees(goals[i][2]) % 360.0)
        rows.append([
            _e(r.name), f"D<sub>{rank[i]}</sub>" if rank else "-", f"{a.snap_down_V[i]:g}", f"{a.release_V[i]:g}",
            f"{r.length_um:g} &times; {r.width_um:g}", f"{r.speed_um_s:g}", f"{r.turn_radius_um:g}", _pose(start), _pose(goal),
        ])
    return "<h3>Robots</h3>" + _table(
        ["robot", "order", "snap-down V_d (V)", "release V_u (V)", "body L x W (um)", "speed (um/s)", "turn radius (um)",
         "start (x, y, heading)", "slot (x, y, heading)"], rows)


def _states_table(a) -> str:
    """The accessible control states (arm down = 1) with their primitive; the first :data:`MAX_STATE_ROWS`
    only, since a non-STRING design can reach up to 2^n states (states.json lists them all)."""
    st_rows = []
    for s in a.accessible_states[:MAX_STATE_ROWS]:
        prim = a.primitive_for_state(s)
        down = [a.names[i] for i in np.flatnonzero(s)]
        st_rows.append([_e(prim.name if prim is not None else "-")] + [str(int(x)) for x in s] + [_e(", ".join(down) or "none")])
    more = a.count - min(a.count, MAX_STATE_ROWS)
    return (
        "<h3>Accessible control states</h3><p class=\"note\">1 = arm down (the robot turns under a Drive), "
        "scenario order; reached from all arms up by levels within the limits.</p>"
        + _table(["primitive"] + list(a.names) + ["arms down"], st_rows, left=(0, a.n + 1))
        + (f'<p class="note">... {more} more states (see states.json).</p>' if more > 0 else "")
    )


def _primitive_levels_table(a) -> str:
    """For a STRING design: the Hold level (V) that sets each primitive P_k, coming from a lower and from a
    higher primitive (empty otherwise)."""
    if not (a.is_string and a.raise_levels_V is not None):
        return ""
    lv = []
    for k, p in enumerate(a.primitives):
        up = a.raise_levels_V[k]
        down = a.release_levels_V[k]
        lv.append([_e(p.name), _e(", ".join(p.turning) or "none"), _fmt(up, "g") if np.isfinite(up) else "-",
                   _fmt(down, "g") if np.isfinite(down) else "-"])
    return ("<h3>Primitives</h3>" + _table(
        ["primitive", "turning (arm down)", "Hold from a lower primitive (V)", "Hold from a higher primitive (V)"], lv, left=(0, 1)))


def _control_matrix_table(a) -> str:
    """The control matrix M (robots x primitives, at most 64 x 64 shown), rows named D_k for a STRING design."""
    M = np.asarray(a.control_matrix)
    if a.is_string:
        row_names = [f"D<sub>{k + 1}</sub> ({_e(a.order[k])})" for k in range(a.n)]
    else:
        row_names = [_e(nm) for nm in a.names]
    cols = [p.name for p in a.primitives[: M.shape[1]]] if M.shape[1] <= 64 else [f"P{k}" for k in range(M.shape[1])]
    m_rows = [[row_names[i]] + [str(int(x)) for x in M[i, :64]] for i in range(min(M.shape[0], 64))]
    return (
        "<h3>Control matrix M</h3><p class=\"note\">M[i][k] = 1 when the robot turns under P<sub>k</sub>; "
        "a 0 means it drives straight.</p>" + _table(["robot"] + cols[:64], m_rows)
    )


def _design_section(scenario, analysis, goals) -> str:
    """The voltage design: verdict and limits, the robots, the accessible control states, M and the primitives' levels."""
    return (_design_verdict(analysis) + _robots_table(scenario, analysis, goals) + _states_table(analysis)
            + _control_matrix_table(analysis) + _primitive_levels_table(analysis))


def _plan_section(plan_summary: Mapping[str, Any], plan_steps: Sequence[tuple[str, Sequence[str], float]], notes: Sequence[str],
                  figures: Mapping[str, bytes]) -> str:
    s = plan_summary
    kv = [
        ("structure", _e(f"{s.get('structure', '-')} ({s.get('variant', '-')})")),
        ("duration", f"{_fmt(s.get('duration_s'), '.1f')} s in {_e(s.get('steps', '-'))} steps"),
        ("lower bound", f"{_fmt(s.get('lower_bound_s'), '.1f')} s (efficiency {_fmt(s.get('efficiency'), '.2f')})"),
        ("planning time", f"{_fmt(s.get('planning_time_s'), '.2f')} s"),
        ("verified", "replayed by the independent verifier (stressbots.replay): every robot ends in its slot, no overlaps"),
    ]
    shown = list(plan_steps[:40])
    t = 0.0
    rows = []
    for k, (name, turning, dur) in enumerate(plan_steps):
        if k < len(shown):
            rows.append([str(k + 1), _e(name), _e(", ".join(turning) or "none"), f"{t:.2f}", f"{dur:.3f}"])
        t += dur
    more = len(plan_steps) - len(shown)
    note_html = "".join(f"<li>{_e(n)}</li>" for n in notes)
    return (
        "<p>The nominal plan the controller follows: D<sub>n</sub> and D<sub>n-1</sub> form the pair G<sub>1</sub> "
        "while the others orbit in place, then D<sub>n-2</sub>..D<sub>1</sub> dock one at a time (the paper's Appendix 2). "
        "Lines: planned trajectories; dashed discs: orbits; faint bodies: starts; filled bodies: the planned slots.</p>"
        + _img(figures, "plan", "nominal plan")
        + _kv(kv)
        + (f"<p>Planner notes:</p><ul>{note_html}</ul>" if note_html else "")
        + "<h3>Steps</h3>"
        + _table(["#", "primitive", "turning", "starts at (s)", "duration (s)"], rows, left=(1, 2))
        + (f'<p class="note">... {more} more steps in plan.json.</p>' if more > 0 else "")
    )


def _verdict(result: Mapping[str, Any]) -> str:
    robots = result.get("robots", [])
    docked = sum(1 for r in robots if r.get("docked"))
    shape = result.get("shape_error_rms_um")
    if result.get("success"):
        return (
            f'<div class="banner ok" id="verdict-text">Assembled: every robot docked ({docked}/{len(robots)}), shape error '
            f"{_fmt(shape)} um RMS after the best rigid alignment, in {_fmt(result.get('duration_s'), '.1f')} s (simulated).</div>"
        )
    text = outcome_text(result)
    return (
        f'<div class="banner fail" id="verdict-text">{_e(text[0].upper() + text[1:])}</div>'
        f"<p>{docked}/{len(robots)} robots docked; shape error {_fmt(shape)} um RMS after the best rigid alignment; "
        f"{_fmt(result.get('duration_s'), '.1f')} s simulated. The event log below shows what happened.</p>"
    )


def _metrics_section(result: Mapping[str, Any], comparisons: Sequence[Mapping[str, Any]]) -> str:
    r = result
    robots = r.get("robots", [])
    noise = r.get("noise") or {}
    kv = [
        ("outcome", _e(outcome_text(r))),
        ("robots docked", f"{sum(1 for x in robots if x.get('docked'))} of {len(robots)}"),
        ("shape error (RMS, best rigid alignment)", f"{_fmt(r.get('shape_error_rms_um'))} um"
         + (f" (tolerance {_fmt(r.get('shape_tol_um'), 'g')} um)" if r.get("shape_tol_um") is not None else "")),
        ("rotation of that alignment", f"{_fmt(r.get('shape_rotation_deg'))}&deg;"),
        ("largest placement error", f"{_fmt(max((x.get('position_error_um') or 0.0) for x in robots) if robots else None)} um"),
        ("duration (simulated)", f"{_fmt(r.get('duration_s'), '.1f')} s"
         + (f" of a budget of {_fmt(r.get('time_budget_s'), 'g')} s" if r.get("time_budget_s") else "")),
        ("re-plans", _e(r.get("replans", "-"))),
        ("wall time of the run", f"{_fmt(r.get('wall_time_s'), '.1f')} s"),
        ("plant seed", _e(r.get("seed"))),
        ("noise", _e(", ".join(f"{k} = {v:g}" for k, v in noise.items())) if noise else "none (nominal)"),
    ]
    rows = []
    for x in robots:
        rows.append([
            _e(x.get("name")), "yes" if x.get("docked") else "<b>no</b>", _pose(x.get("final")), _pose(x.get("goal")),
            _pose(x.get("goal_after_G1", x.get("goal"))), _fmt(x.get("position_error_um")), _fmt(x.get("heading_error_deg")),
        ])
    comp = ""
    if comparisons:
        crow = [[_e(c["label"]), "yes" if c.get("success") else "no", _e(c.get("docked", "-")), _fmt(c.get("shape_error_rms_um")),
                 _fmt(c.get("max_position_error_um")), _e(c.get("note", ""))] for c in comparisons]
        comp = ("<h3>For comparison</h3>" + _table(
            ["run", "success", "docked", "shape error RMS (um)", "largest placement error (um)", "note"], crow, left=(0, 5)))
    return (
        _kv(kv)
        + "<h3>Per robot</h3><p class=\"note\">final: true pose at the end; planned slot: the slot of the nominal plan; "
        "re-targeted slot: where the controller aimed once G<sub>1</sub> had formed (the planned slots moved with the pair "
        "as it really lies; the same as planned for a run that never formed G<sub>1</sub>). The placement and heading "
        "errors are absolute, against the planned slot.</p>"
        + _table(["robot", "docked", "final (x, y, heading)", "planned slot (x, y, heading)", "re-targeted slot (x, y, heading)",
                  "placement error (um)", "heading error (deg)"], rows)
        + comp
    )


def _events_section(events: Sequence[Mapping[str, Any]]) -> str:
    rows = []
    for ev in events[:MAX_EVENT_ROWS]:
        detail = ev.get("detail", "")
        other = ev.get("other")
        if other:
            detail = f"with {other}: {detail}" if detail else f"with {other}"
        rows.append([_fmt(ev.get("t_s"), ".3f"), _e(ev.get("source", "")), _e(ev.get("robot") or "-"), _e(ev.get("kind", "")), _e(detail)])
    more = len(events) - len(rows)
    return (
        f"<p>{len(events)} events: <i>controller</i> (re-plans, docking decisions, recoveries, the reason it stopped) and "
        "<i>plant</i> (contacts and compliance outcomes of the simulator: docking, self-alignment, stuck, arena edge). "
        "A <i>retarget</i> event marks the moment the planned slots of the robots still to dock became their "
        "re-targeted slots (moved with G<sub>1</sub> as it really formed).</p>"
        + '<div class="scroll">' + _table(["t (s)", "source", "robot", "kind", "detail"], rows, left=(1, 2, 3, 4)) + "</div>"
        + (f'<p class="note">... {more} more in result.json.</p>' if more > 0 else "")
    )


def _subtitle(scenario, result: Mapping[str, Any], source: str | None) -> str:
    """The line under the title: scenario (and its file), number of robots, outcome, plant seed."""
    return (
        f"scenario {_e(scenario.name)}{f' ({_e(source)})' if source else ''}: {scenario.n} robots; "
        + ("assembled" if result.get("success") else "not assembled")
        + f"; plant seed {_e(result.get('seed'))}"
    )


def _outcome_section(result: Mapping[str, Any]) -> str:
    """The verdict banner and what the main job did to reach it."""
    return _verdict(result) + (
        "<p>The main job: analyse the voltage design, turn the plan's primitives into a waveform, plan the assembly, "
        "then run it in closed loop on the simulated plant (control error, contact, compliance, noisy camera): every "
        "replanning interval the controller measures the poses and re-plans from where the robots really are.</p>"
    )


def _waveform_section(w: Mapping[str, Any], figures: Mapping[str, bytes], max_V: float) -> str:
    """The plan's waveform: picture, segment counts, duration (s) and the levels used (V) against ``[0, max_V]``.

    ``w`` is :meth:`stressbots.waveform.WaveformSummary.as_dict` (plus an optional ``"excerpt"`` text
    saying what the sampled file holds).
    """
    levels = ", ".join(f"{v:g}" for v in w.get("levels_V", ()))
    return (
        "<p>The voltage signal every robot receives while the nominal plan is executed open loop: each step is reached "
        "with the fewest setting levels (Holds), then driven (a square wave in the drive band). The closed loop sends "
        "the same kind of waveform, one replanning interval at a time.</p>"
        + _img(figures, "waveform", "plan waveform")
        + _kv([
            ("segments", f"{_e(w.get('segments'))} ({_e(w.get('holds'))} Holds, {_e(w.get('drives'))} Drives)"),
            ("duration", f"{_fmt(w.get('duration_s'), '.2f')} s"),
            ("levels used", f"{_e(levels)} V (min {_fmt(w.get('min_V'), 'g')} V, max {_fmt(w.get('max_V'), 'g')} V, "
                            f"within [0, {max_V:g}] V)"),
            ("files", _e(w.get("excerpt", "waveform.json: every segment"))),
        ])
    )


def _run_section(animation: Mapping[str, Any], figures: Mapping[str, bytes]) -> str:
    """The closed-loop run: the animation (:func:`animation_data`), the trajectories and, for a run with the
    image in the loop, the tracked camera frames."""
    return (
        "<p>The closed-loop run on the simulated plant: true poses (not the camera's), resampled at uniform times. "
        "Grey dashed outlines: the planned slots; dotted outlines in a robot's colour: its re-targeted slot, drawn from "
        "the moment G<sub>1</sub> formed (when the controller learnt it); faint outlines: the start poses; the thick "
        "edge is each robot's front. Axes in um, with a scale bar. Press Play or drag the slider; the latest events "
        "are listed under the picture.</p>"
        + animation_html(animation, element_id="run-animation")
        + "<h3>Trajectories</h3>"
        + _img(figures, "run", "closed-loop trajectories")
        + ("<h3>Camera frames (image in the loop)</h3><p>The controller saw the robots only through these rendered frames "
           "and the tracker; outlines: the tracked poses.</p>" + _img(figures, "frames", "tracked camera frames")
           if figures.get("frames") else "")
    )


def _structure_section(result: Mapping[str, Any], figures: Mapping[str, bytes]) -> str:
    """The final bodies against the target after the best proper rigid alignment, with the shape error (um RMS)."""
    return (
        "<p>Final bodies (filled) against the target structure after the best proper rigid alignment (dark outlines; "
        "success is judged on this shape, since the pair may legitimately end shifted or rotated) and the target where "
        "it was planned (dotted).</p>" + _img(figures, "structure", "final structure against the target")
        + f"<p>Shape error {_fmt(result.get('shape_error_rms_um'))} um RMS over the body corners, alignment rotation "
        f"{_fmt(result.get('shape_rotation_deg'))}&deg;.</p>"
    )


def _files_section(files: Sequence[tuple[str, str]], provenance: Mapping[str, Any] | None) -> str:
    """Relative links to the files written beside the report, and the provenance (versions, seed)."""
    prov = provenance or {}
    versions = prov.get("versions", {})
    file_rows = [[f'<a href="{_e(name)}">{_e(name)}</a>', _e(desc)] for name, desc in files]
    return (
        "<p>Written beside this report (links are relative; this page needs no network).</p>"
        + _table(["file", "content"], file_rows, left=(0, 1))
        + "<p class=\"note\">Provenance: "
        + _e(", ".join(f"{k} {v}" for k, v in versions.items()))
        + (f"; seed {_e(prov.get('seed'))}" if prov.get("seed") is not None else "")
        + "</p>"
    )


def build_report(
    *,
    title: str,
    scenario,
    analysis,
    plan_summary: Mapping[str, Any],
    plan_steps: Sequence[tuple[str, Sequence[str], float]],
    plan_notes: Sequence[str] = (),
    goals=None,
    waveform_summary: Mapping[str, Any],
    result: Mapping[str, Any],
    figures: Mapping[str, bytes],
    animation: Mapping[str, Any],
    events: Sequence[Mapping[str, Any]],
    files: Sequence[tuple[str, str]] = (),
    comparisons: Sequence[Mapping[str, Any]] = (),
    provenance: Mapping[str, Any] | None = None,
    source: str | None = None,
    coverage: Mapping[str, Any] | None = None,
) -> str:
    """The report's HTML text: one section per entry of :data:`SECTIONS` (and ``coverage`` when given).

    Parameters
    ----------
    plan_steps:
        ``(primitive name, turning robot names, duration_s)`` per plan step.
    goals:
        ``(n, 3)`` planned slots (um, rad) for the design table.
    waveform_summary:
        :meth:`stressbots.waveform.WaveformSummary.as_dict` of the plan's waveform (plus an optional
        ``"excerpt"`` text saying what the sampled file holds).
    result:
        The ``result.json`` document of the closed-loop run.
    figures:
        PNG bytes: ``"waveform"``, ``"plan"``, ``"run"``, ``"structure"`` (optionally ``"frames"``, ``"coverage"``).
    animation:
        :func:`animation_data` of the run.
    events:
        Dicts with ``t_s``, ``source``, ``robot``, ``kind``, ``detail`` (optionally ``other``), by time.
    files:
        ``(relative name, description)`` of the files written beside the report.
    comparisons:
        Other runs to list beside this one (dicts with ``label``, ``success``, ``docked``,
        ``shape_error_rms_um``, ``max_position_error_um``, ``note``).
    coverage:
        Optional: the controller's regions and their Monte Carlo coverage
        (:meth:`stressbots.coverage.ControllerCoverage.to_dict`), shown with ``figures["coverage"]`` in a
        section after the metrics.
    """
    sec = {
        "verdict": _outcome_section(result),
        "design": _design_section(scenario, analysis, goals),
        "waveform": _waveform_section(waveform_summary, figures, analysis.electrodes.max_V),
        "plan": _plan_section(plan_summary, plan_steps, plan_notes, figures),
        "run": _run_section(animation, figures),
        "structure": _structure_section(result, figures),
        "metrics": _metrics_section(result, comparisons),
        "events": _events_section(events),
        "files": _files_section(files, provenance),
    }
    sections = SECTIONS
    if coverage is not None:
        sec["coverage"] = coverage_section(coverage, figures.get("coverage"))
        at = [sid for sid, _ in SECTIONS].index("metrics") + 1
        sections = (*SECTIONS[:at], ("coverage", "Controller regions"), *SECTIONS[at:])
    body = "\n".join(f'<section id="{sid}"><h2>{_e(head)}</h2>\n{sec[sid]}\n</section>' for sid, head in sections)
    return _page(title, _subtitle(scenario, result, source), body, nav=sections)


# ----------------------------------------------------------------------------------------------------
# The controller's regions and their coverage (stressbots bounds --trials)


def coverage_section(coverage: Mapping[str, Any], png: bytes | None) -> str:
    """HTML of the controller's regions and their Monte Carlo coverage (``controller_coverage`` of
    ``bounds.json``, :meth:`stressbots.coverage.ControllerCoverage.to_dict`) with its picture."""
    regions = coverage.get("regions", [])
    rows = [[_e(r["region"]), _e(r["robot"]), _e(r["size"]), f"{r['scale']:g}x", f"{r['inside']}/{r['samples']}",
             f"{100 * r['fraction']:.0f} %", f"{100 * r['low']:.0f}-{100 * r['high']:.0f} %", _e(r["seed_verdict"])] for r in regions]
    succ = ", ".join(f"{s}/{coverage.get('trials')} at {x:g}x" for x, s in zip(coverage.get("noise_scales", []),
                                                                             coverage.get("successes", []), strict=False))
    moments = coverage.get("moments", {})
    return (
        "<p>The seed's bounds ask whether the worst-case error region fits in the docking region (A<sub>i</sub>* non-empty); "
        "at the literature's noise it never does. The closed-loop controller measures and re-plans instead: these are the "
        "regions it aims at when it commits to an open-loop stretch, and how often the <em>true</em> pose (not the camera's) "
        f"was inside them over {_e(coverage.get('trials'))} simulated assemblies per noise scale (assembled: {_e(succ)}; "
        f"seed {_e(coverage.get('seed'))}). Coverage with its 95 % Wilson interval; the last column is the seed's verdict for "
        "the same robot.</p>"
        + _table(["region", "robot", "size", "noise", "inside", "coverage", "95 % CI", "seed A_i*"], rows, left=(0, 1, 2, 7))
        + _kv([(k, _e(v)) for k, v in moments.items()])
        + (f'<img src="{png_data_uri(png)}" alt="the controller\'s regions with the Monte Carlo moments">' if png else "")
    )


def coverage_page(coverage: Mapping[str, Any], png: bytes | None, *, title: str) -> str:
    """A standalone offline page with :func:`coverage_section` (``bounds --trials N --out DIR`` writes it)."""
    body = f'<section id="coverage"><h2>The controller\'s regions and their coverage</h2>\n{coverage_section(coverage, png)}\n</section>'
    return _page(title, f"scenario {_e(coverage.get('scenario'))}", body)
