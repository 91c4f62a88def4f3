"""The replay page's overlay: simulated time, legend, and the contacts on a timeline.

Meshcat's viewer has animation controls (play, pause, a time slider in its closed control
panel) but shows neither the simulated time nor what the colours mean. The compact page of
:mod:`multiarm_pin.app.replay_page` adds, in HTML over the 3-D view:

- top left, the simulated time ``t = t0 + animation time`` [s] of the frame shown, the
  replay's end time, a play / pause button, and the last events before ``t``;
- the legend: the object, yellow (touching) and grey (separated) contact spheres, the force
  arrows' scale, and each support by name, colour and plane;
- under the time, each support point (``"<support>[j]"``) at the frame shown: pressing
  (its force [N]) or separated (its gap above the plane [mm]), as its cube in the scene;
- at the bottom, a timeline with one row per arm that has contacts and one per support
  point: the number of its contacts touching over time (yellow, the rest grey), its
  contact events as markers (separation, touchdown, touchdown with an impact impulse), the
  part after ``t`` dimmed and a cursor at ``t``. Clicking or dragging on it seeks (and
  pauses); the page opened as ``replay.html#t=1.25`` starts paused at 1.25 s.
- for a phased task (``phased_pd``: :class:`~multiarm_pin.app.replay_phases.ReplayPhase`
  s), the current phase under the time (name, kind, moving until / holding), a table of
  the phases in the legend (the current one highlighted: interval, supports pressing,
  arms released) and a top row on the timeline (a band per phase, dark while its motion
  runs, light while it holds) with a line at each phase's start across the rows. A run
  without phases has none of these.

The overlay reads the viewer's own animation clock (``viewer.animator.time``) on every
browser frame, so its time is the one the scene shows. :func:`overlay_data` builds what the
overlay draws; ``OVERLAY_HTML``, ``OVERLAY_CSS`` and ``OVERLAY_JS`` are its page parts.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from multiarm_pin.app.replay_phases import ReplayPhase, check_phases, phase_table
from multiarm_pin.app.replay_scene import ReplayContacts, frame_indices


def _hex(color: int) -> str:
    return f"#{int(color):06x}"


def _num(x) -> str:
    """``x`` in 3 significant digits, round-off near zero written 0."""
    v = float(x)
    return f"{0.0 if abs(v) < 1e-9 else v:.3g}"


def body_of(label: str) -> str:
    """The body of a contact label: ``"<arm>:<contact>"`` -> arm, ``"<support>[j]"`` -> support."""
    if ":" in label:
        return label.split(":", 1)[0]
    return label.split("[", 1)[0]


def touching_runs(t: np.ndarray, counts: np.ndarray) -> list[list[float]]:
    """``[[time [s], count], ...]``: ``counts`` (T,) from each time until the next, runs merged."""
    change = np.flatnonzero(np.diff(counts)) + 1
    starts = np.concatenate([[0], change])
    return [[float(t[i]), int(counts[i])] for i in starts]


def _sig(x: float) -> float:
    """``x`` to 4 significant digits (what the overlay prints; keeps the page small)."""
    return float(f"{float(x):.4g}")


def support_vertex_data(t: np.ndarray, contacts: ReplayContacts, fps: float) -> list[dict]:
    """Each support point's state at every frame of the replay (what the markers show).

    Args:
        t: (T,) sample times [s].
        contacts: the contacts; their support points are those labelled ``"<support>[j]"``.
        fps: the replay's frames per second (frame ``i`` shows the sample
            ``frame_indices(t, fps)[i]``).

    Returns:
        One dict per support point, in the supports' order: ``label``, ``support``,
        ``contact`` (index in ``contacts``), ``runs`` (:func:`touching_runs` of its state
        over the samples: 1 touching, 0 separated) and, per frame, ``on`` (1 touching),
        ``force`` (|force| on the object [N]) and ``gap`` (its distance from the support
        plane along the normal [m], ``(p - c) · n``), 4 significant digits.
    """
    idx = frame_indices(t, fps)
    touching = (contacts.touching if contacts.touching is not None
                else np.ones(contacts.points.shape[:2], dtype=bool))
    planes = {sp.name: sp for sp in contacts.supports}
    out = []
    for name, ks in contacts.support_points().items():
        sp = planes[name]
        for k in ks:
            gap = (contacts.points[idx, k] - sp.center) @ sp.normal
            out.append({"label": contacts.labels[k], "support": name, "contact": k,
                        "runs": touching_runs(t, touching[:, k].astype(int)),
                        "on": touching[idx, k].astype(int).tolist(),
                        "force": [_sig(f) for f in np.linalg.norm(contacts.forces[idx, k],
                                                                  axis=1)],
                        "gap": [_sig(g) for g in gap]})
    return out


def overlay_data(t: np.ndarray, contacts: ReplayContacts | None, *, title: str = "replay",
                 arm_names: Sequence[str] = (), force_scale: float | None = None,
                 support_colors: Sequence[int] = (), colors: dict[str, int] | None = None,
                 phases: Sequence[ReplayPhase] = (), fps: float | None = None) -> dict:
    """What the overlay draws (JSON-ready).

    Args:
        t: (T,) sample times [s].
        contacts: the contacts (labels, touching states, events, supports), or None.
        title: the page's heading (the scenario's name).
        arm_names: the arms, in order.
        force_scale: the force arrows' length per newton [m/N] (None: no arrows).
        support_colors: 0xRRGGBB of each support's slab, in ``contacts.supports`` order.
        colors: 0xRRGGBB of ``object``, ``contact``, ``separated``, ``force`` (and
            ``colliding``: links drawn in it while they collide; in the legend if given).
        phases: the task's phases (a ``phased_pd`` run), in order; none for other runs.
        fps: the replay's frames per second; with it, the support points' per-frame states
            (``vertices``; None: none).

    Returns:
        ``t0``, ``t_end`` [s]; ``title``; ``arms``; ``colors`` (CSS ``#rrggbb``); ``force``
        (``{"m_per_n", "max_n"}`` or None); ``supports`` (name, colour, plane text);
        ``bodies`` (name, ``contacts`` count, ``runs`` of touching counts, see
        :func:`touching_runs`); ``rows``: the timeline's rows, one per arm (its body entry)
        and one per support point (``name`` its label, one contact) when ``vertices`` are
        given, else one per support; ``events`` (``t``, ``kind``, ``label``, ``body``,
        ``impulse`` [N s], ``impact``: a touchdown with a positive impulse, ``row``: its
        timeline row); ``phases``
        (:func:`~multiarm_pin.app.replay_phases.phase_table`); ``fps`` and ``vertices``
        (:func:`support_vertex_data`, empty without ``fps``).
    """
    t = np.asarray(t, dtype=float)
    colors = {k: _hex(v) for k, v in (colors or {}).items()}
    phases = check_phases(phases)
    data: dict = {"t0": float(t[0]), "t_end": float(t[-1]), "title": str(title),
                  "arms": [str(a) for a in arm_names], "colors": colors, "force": None,
                  "supports": [], "bodies": [], "rows": [], "events": [],
                  "phases": phase_table(phases, float(t[-1])),
                  "fps": None if fps is None else float(fps), "vertices": []}
    if contacts is None:
        return data
    K = contacts.points.shape[1]
    labels = list(contacts.labels) if contacts.labels is not None else [
        f"contact {k}" for k in range(K)]
    if force_scale is not None and K:
        fmax = float(np.max(np.linalg.norm(contacts.forces, axis=2), initial=0.0))
        data["force"] = {"m_per_n": float(force_scale), "max_n": fmax}
    for sp, c in zip(contacts.supports, list(support_colors) + [None] * len(contacts.supports),
                     strict=False):
        p, n = sp.center, sp.normal
        data["supports"].append({
            "name": sp.name, "color": _hex(c) if c is not None else "#6c584c",
            "plane": f"plane through ({', '.join(_num(x) for x in p)}) m, "
                     f"normal ({', '.join(_num(x) for x in n)})"})
    touching = (contacts.touching if contacts.touching is not None
                else np.ones(contacts.points.shape[:2], dtype=bool))
    bodies: dict[str, list[int]] = {}
    for k, lab in enumerate(labels):
        bodies.setdefault(body_of(lab), []).append(k)
    if fps is not None:
        data["vertices"] = support_vertex_data(t, contacts, fps)
    by_support: dict[str, list[dict]] = {}
    for v in data["vertices"]:
        by_support.setdefault(v["support"], []).append(v)
    row_of: dict[str, int] = {}  # body name or a support point's label -> row
    for name, cols in bodies.items():
        counts = touching[:, cols].sum(axis=1)
        body = {"name": name, "contacts": len(cols), "runs": touching_runs(t, counts)}
        data["bodies"].append(body)
        for v in by_support.get(name, [body]):
            row_of[v.get("label", name)] = len(data["rows"])
            data["rows"].append(body if v is body else
                                {"name": v["label"], "contacts": 1, "runs": v["runs"]})
    for e in contacts.events:
        lab = labels[e.contact] if 0 <= e.contact < K else f"contact {e.contact}"
        data["events"].append({"t": float(e.t), "kind": e.kind, "label": lab,
                               "body": body_of(lab), "impulse": float(e.impulse),
                               "impact": e.kind == "touchdown" and e.impulse > 0,
                               "row": row_of.get(lab, row_of.get(body_of(lab), -1))})
    return data


OVERLAY_HTML = """<div id="ma-info" class="ma-panel">
<div id="ma-title"></div>
<div><button id="ma-play" title="play / pause">&#9646;&#9646;</button>
<span id="ma-time">t = &ndash;</span><span id="ma-end"></span></div>
<div id="ma-phase"></div>
<div id="ma-events"></div>
<div id="ma-vertices"></div>
<div id="ma-legend"></div>
</div>
<div id="ma-timeline" class="ma-panel"><canvas id="ma-canvas"></canvas></div>
"""

OVERLAY_CSS = """
.ma-panel {position: absolute; background: rgba(15, 20, 35, 0.78); color: #f1f1f1;
  font: 13px/1.35 system-ui, -apple-system, "Segoe UI", "Liberation Sans", sans-serif;
  border-radius: 6px; padding: 8px 10px; z-index: 10;}
#ma-info {left: 10px; top: 10px; max-width: 420px; max-height: calc(100vh - 250px);
  overflow-y: auto; overflow-x: hidden;}
#ma-title {font-weight: 600; margin-bottom: 2px;}
#ma-time {font: 600 22px/1.2 ui-monospace, "DejaVu Sans Mono", "Liberation Mono", monospace;}
#ma-end {color: #b8c0cc; margin-left: 6px;}
#ma-play {background: #33415c; color: #fff; border: 0; border-radius: 4px; width: 28px;
  height: 24px; margin-right: 6px; vertical-align: 3px; cursor: pointer;}
#ma-phase {font-size: 14px; margin-top: 3px;}
#ma-phase:empty, #ma-vertices:empty {display: none;}
#ma-events {color: #d8dde6; font-size: 12px; margin: 4px 0 6px 0;}
#ma-vertices {font-size: 12px; margin: 0 0 6px 0;}
#ma-vertices span {white-space: nowrap; margin-right: 6px;}
#ma-legend div {margin: 1px 0; padding-left: 20px; text-indent: -20px;}
#ma-legend table {border-collapse: collapse; font-size: 11px; margin: 1px 0 2px 0;}
#ma-legend td {padding: 0 5px 0 0; vertical-align: top;}
#ma-legend td:nth-child(-n+4) {white-space: nowrap;}
#ma-legend tr.ma-now {background: rgba(255, 255, 255, 0.2); font-weight: 600;}
.ma-sw {display: inline-block; width: 12px; height: 12px; margin-right: 6px;
  vertical-align: -1px; border: 1px solid rgba(255,255,255,0.5);}
.ma-dot {border-radius: 50%;}
#ma-timeline {left: 10px; right: 10px; bottom: 10px; padding: 6px;}
#ma-canvas {display: block; width: 100%; cursor: pointer;}
"""

# The overlay's script: runs after the loader's ``multiarmReplay`` (see replay_page).
OVERLAY_JS = r"""
(function () {
  "use strict";
  const EVENT_COLORS = {separation: "#4cc9f0", touchdown: "#ff9f1c", impact: "#f72585",
                        off_edge: "#c77dff"};
  const PHASE_COLORS = ["#577590", "#43aa8b", "#f3722c", "#90be6d", "#f94144", "#4d908e",
                        "#f8961e", "#277da1", "#b5838d"];
  const fmt = x => x.toFixed(3);
  function el(id) { return document.getElementById(id); }
  function esc(s) {
    const d = document.createElement("div");
    d.textContent = s;
    return d.innerHTML;
  }
  function eventName(e) {
    return e.kind === "touchdown" && e.impact ? "touchdown (impact " + e.impulse.toPrecision(3) +
      " N s)" : e.kind;
  }
  function phaseColor(i) { return PHASE_COLORS[i % PHASE_COLORS.length]; }
  // The phase current at t: the last one started (the first one before its start), as
  // phased_pd chooses it.
  function phaseAt(o, t) {
    let k = 0;
    o.phases.forEach((p, i) => { if (p.t <= t + 1e-9) k = i; });
    return k;
  }
  function legend(o) {
    const c = o.colors, rows = [];
    const sw = (color, dot, text) => rows.push('<div><span class="ma-sw' + (dot ? " ma-dot" : "") +
      '" style="background:' + color + '"></span>' + text + "</div>");
    sw(c.object, false, "object");
    if (o.bodies.length) {
      sw(c.contact, true, "contact touching (held or pushing)");
      sw(c.separated, true, "contact separated");
    }
    if (o.vertices.length) {
      sw(c.contact, false, "support point touching (cube)");
      sw(c.separated, false, "support point separated (cube)");
    }
    if (o.force) {
      sw(c.force, false, "force on the object: arrow " + (1000 * o.force.m_per_n).toPrecision(3) +
        " mm per N (longest " + o.force.max_n.toPrecision(3) + " N)");
    }
    for (const s of o.supports) {
      sw(s.color, false, "support <b>" + esc(s.name) + "</b>: " + esc(s.plane));
    }
    if (c.colliding) sw(c.colliding, false, "a link while it collides (feasibility check)");
    if (o.arms.length) {
      const names = o.arms.length <= 6 ? o.arms.join(", ") :
        o.arms.slice(0, 6).join(", ") + ", \u2026 (" + o.arms.length + " arms)";
      rows.push("<div>arms: " + esc(names) + "</div>");
    }
    if (o.rows.length) {
      rows.push('<div>timeline: <span style="color:' + c.contact + '">\u2588</span> touching, ' +
        '<span style="color:' + c.separated + '">\u2588</span> separated' +
        (o.events.length ? '; <span style="color:' + EVENT_COLORS.separation +
         '">\u25BC</span> separation <span style="color:' + EVENT_COLORS.touchdown +
         '">\u25B2</span> touchdown <span style="color:' + EVENT_COLORS.impact +
         '">\u25C6</span> impact' : "") + "</div>");
    }
    if (o.phases.length) {
      rows.push("<div>phases (top row of the timeline; dark: moving, light: holding):</div>" +
        '<table id="ma-phases"><tr><th></th><th>phase</th><th>kind</th><th>from&ndash;to [s]' +
        "</th><th>supports pressing; arms</th></tr>" + o.phases.map((p, i) =>
          '<tr id="ma-phase-' + i + '"><td><span class="ma-sw" style="background:' +
          phaseColor(i) + '"></span></td><td>' + esc(p.name) + "</td><td>" + esc(p.kind) +
          "</td><td>" + fmt(p.t) + "&ndash;" + fmt(p.end) + "</td><td>" +
          (p.press.length ? esc(p.press.join(", ")) : "none") +
          (p.release.length ? "; released: " + esc(p.release.join(", ")) : "") +
          (p.offsets.length ? "; moving: " + esc(p.offsets.join(", ")) : "") + "</td></tr>"
        ).join("") + "</table>");
    }
    el("ma-legend").innerHTML = rows.join("");
  }
  function countAt(runs, t) {
    let n = runs.length ? runs[0][1] : 0;
    for (const r of runs) { if (r[0] <= t + 1e-9) n = r[1]; else break; }
    return n;
  }
  function start(o) {
    const a = viewer.animator, canvas = el("ma-canvas"), ctx = canvas.getContext("2d");
    const t0 = o.t0, t1 = Math.max(o.t_end, o.t0 + 1e-9);
    const rows = o.rows, nb = rows.length, np = o.phases.length;
    el("ma-title").textContent = o.title;
    el("ma-end").textContent = "of " + fmt(o.t_end) + " s";
    legend(o);
    if (!nb && !np) el("ma-timeline").style.display = "none";
    // Rows of at most 16 px, all of them in at most a quarter of the window (200 px);
    // below 8 px a row has no label (hovering names it). The phases' row on top.
    const gap = nb > 12 ? 1 : 2;
    const maxH = Math.max(60, Math.min(200, 0.25 * window.innerHeight));
    const rowH = nb ? Math.max(2, Math.min(16, Math.floor(maxH / nb) - gap)) : 0;
    const pitch = rowH + gap, labelled = rowH >= 8;
    const phH = np ? 18 : 0;
    const gutter = 170, axisH = 18;
    let width = 0, shown = null;
    function layout() {
      const w = canvas.clientWidth, h = phH + nb * (pitch) + axisH;
      const r = window.devicePixelRatio || 1;
      canvas.style.height = h + "px";
      canvas.width = Math.round(w * r);
      canvas.height = Math.round(h * r);
      ctx.setTransform(r, 0, 0, r, 0, 0);
      width = w;
      shown = null;
    }
    const x = t => gutter + (width - gutter - 8) * (t - t0) / (t1 - t0);
    function frameAt(t) {
      const n = o.vertices.length ? o.vertices[0].on.length : 0;
      return Math.min(n - 1, Math.max(0, Math.round((t - t0) * (o.fps || 1))));
    }
    function vertexText(t) {
      if (!o.vertices.length) return "";
      const f = frameAt(t), parts = [];
      let support = null;
      for (const v of o.vertices) {
        if (v.support !== support) {
          parts.push((support === null ? "" : "<br>") + "<b>" + esc(v.support) + "</b>: ");
          support = v.support;
        }
        const on = v.on[f] === 1;
        const state = !on ? "separated " + (1000 * v.gap[f]).toPrecision(3) + " mm" :
          (v.force[f] > 0 ? "pressing " + v.force[f].toPrecision(3) + " N" : "touching, 0 N");
        parts.push('<span style="color:' + (on ? o.colors.contact : o.colors.separated) + '">' +
          esc(v.label.slice(v.support.length)) + " " + state + "</span>");
      }
      return "support points: " + parts.join(" ");
    }
    function phaseText(t) {
      if (!np) return "";
      const k = phaseAt(o, t), p = o.phases[k];
      const motion = t < p.t - 1e-9 ? "before its start at " + fmt(p.t) + " s" :
        t < p.motion_end - 1e-9 ? (p.kind === "hold" ? esc(p.offsets.join(", ")) +
          " moving" : "moving") + " until " + fmt(p.motion_end) + " s" : "holding";
      return '<span class="ma-sw" style="background:' + phaseColor(k) + '"></span>phase ' +
        (k + 1) + "/" + np + ": <b>" + esc(p.name) + "</b> (" + esc(p.kind) + "), " + motion;
    }
    function draw(t) {
      const h = phH + nb * (pitch) + axisH, yEnd = phH + nb * (pitch);
      ctx.clearRect(0, 0, width, h);
      ctx.textBaseline = "middle";
      if (np) {  // the phases: dark while its motion runs, light while it holds
        ctx.font = "11px system-ui, sans-serif";
        o.phases.forEach((p, i) => {
          ctx.fillStyle = phaseColor(i);
          ctx.globalAlpha = 0.45;
          ctx.fillRect(x(p.t), 0, Math.max(x(p.end) - x(p.t), 1), phH - 3);
          ctx.globalAlpha = 1.0;
          if (p.motion_end > p.t) ctx.fillRect(x(p.t), 0, x(p.motion_end) - x(p.t), phH - 3);
          const w = x(p.end) - x(p.t) - 4;
          if (w > 14) {
            ctx.fillStyle = "#ffffff";
            ctx.fillText(p.name, x(p.t) + 2, (phH - 3) / 2, w);
          }
        });
        const k = phaseAt(o, t);
        ctx.fillStyle = "#f1f1f1";
        ctx.fillText("phase: " + o.phases[k].name, 2, (phH - 3) / 2, gutter - 6);
      }
      ctx.font = Math.min(12, rowH + 1) + "px system-ui, sans-serif";
      rows.forEach((b, i) => {
        const y = phH + i * (pitch);
        ctx.fillStyle = o.colors.separated;
        ctx.fillRect(x(t0), y, x(t1) - x(t0), rowH);
        b.runs.forEach((r, k) => {
          const end = k + 1 < b.runs.length ? b.runs[k + 1][0] : t1;
          const f = r[1] / b.contacts;
          if (f > 0) {
            ctx.fillStyle = o.colors.contact;
            ctx.fillRect(x(r[0]), y + rowH * (1 - f), Math.max(x(end) - x(r[0]), 1), rowH * f);
          }
        });
        if (labelled) {
          ctx.fillStyle = "#f1f1f1";
          ctx.fillText(b.contacts === 1 && b.name.indexOf("[") > 0 ?
                       b.name + "  " + (countAt(b.runs, t) ? "touching" : "separated") :
                       b.name + "  " + countAt(b.runs, t) + "/" + b.contacts + " touching", 2,
                       y + rowH / 2, gutter - 6);
        }
      });
      if (!labelled && nb) {
        const touching = rows.reduce((n, b) => n + countAt(b.runs, t), 0);
        const total = rows.reduce((n, b) => n + b.contacts, 0);
        ctx.fillStyle = "#f1f1f1";
        ctx.font = "12px system-ui, sans-serif";
        ctx.fillText(nb + " rows (arms, supports)", 2, phH + 8, gutter - 6);
        ctx.fillText(touching + "/" + total + " touching", 2, phH + 24, gutter - 6);
        ctx.fillText("hover a row: its name", 2, phH + 40, gutter - 6);
      }
      ctx.fillStyle = "rgba(255, 255, 255, 0.35)";  // the phases' starts, across the rows
      for (const p of o.phases.slice(1)) ctx.fillRect(x(p.t), phH, 1, nb * (pitch));
      ctx.fillStyle = "rgba(15, 20, 35, 0.55)";  // not yet played
      ctx.fillRect(x(t), 0, x(t1) - x(t) + 8, yEnd);
      for (const e of o.events) {
        const i = e.row;
        if (i === undefined || i < 0) continue;
        const cx = x(e.t), cy = phH + i * (pitch) + rowH / 2, s = Math.max(3, rowH / 2);
        ctx.fillStyle = EVENT_COLORS[e.impact ? "impact" : e.kind] || "#ffffff";
        ctx.strokeStyle = "#10131c";
        ctx.beginPath();
        if (e.impact) {
          ctx.moveTo(cx, cy - s); ctx.lineTo(cx + s, cy);
          ctx.lineTo(cx, cy + s); ctx.lineTo(cx - s, cy);
        } else if (e.kind === "separation" || e.kind === "off_edge") {
          ctx.moveTo(cx - s, cy - s); ctx.lineTo(cx + s, cy - s); ctx.lineTo(cx, cy + s);
        } else {
          ctx.moveTo(cx - s, cy + s); ctx.lineTo(cx + s, cy + s); ctx.lineTo(cx, cy - s);
        }
        ctx.closePath(); ctx.fill(); ctx.stroke();
      }
      const yAxis = yEnd + axisH / 2;  // time axis
      ctx.fillStyle = "#b8c0cc";
      ctx.font = "11px system-ui, sans-serif";
      const span = t1 - t0, raw = span / 8, p = Math.pow(10, Math.floor(Math.log10(raw)));
      const step = [1, 2, 5, 10].map(m => m * p).find(v => v >= raw);
      for (let v = Math.ceil(t0 / step) * step; v <= t1 + 1e-9; v += step) {
        ctx.fillRect(x(v), yAxis - axisH / 2, 1, 4);
        ctx.fillText(+v.toFixed(6) + " s", Math.min(x(v) - 8, width - 34), yAxis + 2);
      }
      ctx.fillStyle = "#ffffff";  // cursor
      ctx.fillRect(x(t) - 1, 0, 2, yEnd + 4);
    }
    function seek(t) {
      t = Math.min(Math.max(t, t0), t1);
      a.pause();
      a.seek(t - t0);
      a.display_progress(t - t0);
    }
    function fromMouse(ev) {
      const r = canvas.getBoundingClientRect();
      return t0 + (ev.clientX - r.left - gutter) / (width - gutter - 8) * (t1 - t0);
    }
    let dragging = false;
    canvas.addEventListener("mousemove", ev => {  // a tooltip: the row, its events near
      const r = canvas.getBoundingClientRect(), yy = ev.clientY - r.top;
      if (yy < phH) {
        const p = o.phases[phaseAt(o, fromMouse(ev))];
        canvas.title = "phase " + p.name + " (" + p.kind + "): " + fmt(p.t) + "\u2013" +
          fmt(p.end) + " s, motion until " + fmt(p.motion_end) + " s";
        return;
      }
      const i = Math.floor((yy - phH) / pitch), b = rows[i];
      if (!b || ev.clientX - r.left < gutter) { canvas.title = b ? b.name : ""; return; }
      const tm = fromMouse(ev), px = (t1 - t0) / (width - gutter - 8);
      const near = o.events.filter(e => e.row === i && Math.abs(e.t - tm) < 6 * px);
      canvas.title = b.name + ": " + countAt(b.runs, tm) + "/" + b.contacts +
        " touching at " + fmt(tm) + " s" + near.map(e => "\n" + fmt(e.t) + " s " +
        eventName(e) + " " + e.label).join("");
    });
    canvas.addEventListener("mousedown", ev => { dragging = true; seek(fromMouse(ev)); });
    window.addEventListener("mousemove", ev => { if (dragging) seek(fromMouse(ev)); });
    window.addEventListener("mouseup", () => { dragging = false; });
    el("ma-play").addEventListener("click", () => {
      if (a.playing) { a.pause(); } else {
        if (a.time >= a.duration - 1e-6) a.reset();
        a.play();
      }
    });
    window.addEventListener("resize", layout);
    const hash = /(?:^#|&)t=([0-9.eE+-]+)/.exec(location.hash);
    if (hash) seek(parseFloat(hash[1]));
    layout();
    function tick() {
      const t = Math.min(t0 + (a.time || 0), t1);
      const key = t + ":" + a.playing;
      if (key !== shown) {
        shown = key;
        el("ma-time").textContent = "t = " + fmt(t) + " s";
        el("ma-play").innerHTML = a.playing ? "&#9646;&#9646;" : "&#9654;";
        el("ma-phase").innerHTML = phaseText(t);
        o.phases.forEach((p, i) => {
          const row = el("ma-phase-" + i);
          if (row) row.className = i === phaseAt(o, t) ? "ma-now" : "";
        });
        el("ma-vertices").innerHTML = vertexText(t);
        const past = o.events.filter(e => e.t <= t + 1e-9);
        el("ma-events").innerHTML = !o.events.length ? (nb ? "no contact events" : "") :
          (past.length ? past.slice(-3).reverse().map(e => fmt(e.t) + " s " +
            esc(eventName(e)) + " <b>" + esc(e.label) + "</b>").join("<br>") : "no event yet") +
          "<br>" + past.length + " of " + o.events.length + " events so far";
        if (nb || np) draw(t);
      }
      requestAnimationFrame(tick);
    }
    tick();
  }
  multiarmReplay.ready.then(m => { if (m.overlay) start(m.overlay); });
})();
"""


__all__ = ["OVERLAY_CSS", "OVERLAY_HTML", "OVERLAY_JS", "body_of", "overlay_data",
           "support_vertex_data", "touching_runs"]
