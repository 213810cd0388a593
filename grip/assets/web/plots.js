/* The 2D plots of the GRIP viewer (grip/export/html.py inlines this file next to viewer.js).
 *
 * A classic script: it only defines gripPlots(), which gripViewer() calls once, and
 * gripOffscreenCanvas() (pace.js draws with it too):
 *   - the vertical ground reaction force of each foot ("grf-left", "grf-right" canvases): every
 *     shown body's against the insole force (dashed), GRIP's fall events shaded, with a cursor
 *     and the values at the current frame;
 *   - the timeline ("timeline" canvas): one lane per reconstruction with its fall events
 *     (shaded: the frames replaced from the history buffer; red: the frame the fall was
 *     detected) and a cursor.
 * It reads the viewer's state (frame, visible) when it draws. Every piece of text that comes from
 * the data is drawn on a canvas, never put in as HTML.
 */
"use strict";

function gripOffscreenCanvas(w, h) {
  // A white canvas of w x h CSS pixels at the screen's pixel ratio, for a plot's static layer
  // (drawn once, then copied under the cursor on every frame). Also used by pace.js.
  const off = document.createElement("canvas");
  const dpr = window.devicePixelRatio || 1;
  off.width = Math.round(w * dpr);
  off.height = Math.round(h * dpr);
  const ctx = off.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.fillStyle = "#ffffff";
  ctx.fillRect(0, 0, w, h);
  return { off, ctx };
}

function gripPlots(data, state, opts) {
  // opts: cssSize(canvas), niceStep(span, n)
  const T = data.frames;
  const fps = data.fps;
  const $ = (id) => document.getElementById(id);
  const { cssSize, niceStep } = opts;
  const isReconstruction = (b) => b.role === "reconstruction";

  const footNames = ["left", "right"];
  const grfZ = (b, foot, f) => {
    if (!b.grf_n) return null;
    return b.grf_n[f * 6 + foot * 3 + 2];
  };
  const plotCache = new Map();
  const plotMargin = { l: 46, r: 10, t: 20, b: 22 };

  function shadeFalls(ctx, x0, w, y0, h) {
    data.bodies.forEach((b, i) => {
      if (!state.visible[i] || !isReconstruction(b)) return;
      for (const [a, d] of b.falls) {
        const xa = x0 + (a / Math.max(1, T - 1)) * w;
        const xd = x0 + (d / Math.max(1, T - 1)) * w;
        ctx.fillStyle = "rgba(230, 120, 30, 0.18)";
        ctx.fillRect(xa, y0, Math.max(2, xd - xa), h);
        ctx.fillStyle = "rgba(210, 30, 30, 0.8)";
        ctx.fillRect(xd - 1, y0, 2, h);
      }
    });
  }

  function drawGrfStatic(foot) {
    const canvas = $(`grf-${footNames[foot]}`);
    const { w, h } = cssSize(canvas);
    const { off, ctx } = gripOffscreenCanvas(w, h);
    const m = plotMargin;
    const pw = w - m.l - m.r;
    const ph = h - m.t - m.b;
    const series = [];
    if (data.insole) series.push({ color: "#111111", dash: [5, 3], get: (f) => data.insole.force_n[f * 2 + foot] });
    data.bodies.forEach((b, i) => {
      if (state.visible[i] && b.grf_n) series.push({ color: b.color, dash: [], get: (f) => grfZ(b, foot, f) });
    });
    let ymax = 100;
    for (const s of series) for (let f = 0; f < T; f++) {
      const v = s.get(f);
      if (v !== null && v > ymax) ymax = v;
    }
    ymax *= 1.08;
    const X = (f) => m.l + (f / Math.max(1, T - 1)) * pw;
    const Y = (v) => m.t + ph - (Math.max(0, v) / ymax) * ph;
    shadeFalls(ctx, m.l, pw, m.t, ph);
    ctx.strokeStyle = "#e3e3e3";
    ctx.fillStyle = "#555";
    ctx.font = "11px sans-serif";
    ctx.lineWidth = 1;
    const ys = niceStep(ymax, 4);
    for (let v = 0; v <= ymax; v += ys) {
      ctx.beginPath();
      ctx.moveTo(m.l, Y(v));
      ctx.lineTo(m.l + pw, Y(v));
      ctx.stroke();
      ctx.textAlign = "right";
      ctx.fillText(String(Math.round(v)), m.l - 4, Y(v) + 4);
    }
    const xs = niceStep(T / fps, 8);
    ctx.textAlign = "center";
    for (let t = 0; t <= (T - 1) / fps + 1e-9; t += xs) {
      ctx.fillText(`${+t.toFixed(2)} s`, X(t * fps), h - 6);
    }
    for (const s of series) {
      ctx.strokeStyle = s.color;
      ctx.setLineDash(s.dash);
      ctx.lineWidth = 1.4;
      ctx.beginPath();
      let pen = false;
      for (let f = 0; f < T; f++) {
        const v = s.get(f);
        if (v === null) {
          pen = false;
          continue;
        }
        if (pen) ctx.lineTo(X(f), Y(v));
        else ctx.moveTo(X(f), Y(v));
        pen = true;
      }
      ctx.stroke();
    }
    ctx.setLineDash([]);
    ctx.fillStyle = "#222";
    ctx.textAlign = "left";
    ctx.font = "12px sans-serif";
    const what = data.insole ? "vertical GRF vs insole (dashed), N" : "vertical GRF, N (no insoles: pass --gt)";
    ctx.fillText(`${footNames[foot]} foot: ${what}`, m.l, 13);
    if (series.length === 0) {
      ctx.fillStyle = "#888";
      ctx.textAlign = "center";
      ctx.fillText("no forces to show", m.l + pw / 2, m.t + ph / 2);
    }
    plotCache.set(foot, { off, w, h, X, Y });
  }

  function drawGrf(foot) {
    if (!plotCache.has(foot)) drawGrfStatic(foot);
    const canvas = $(`grf-${footNames[foot]}`);
    const { ctx, w, h } = cssSize(canvas);
    const c = plotCache.get(foot);
    if (c.w !== w || c.h !== h) {
      plotCache.delete(foot);
      return drawGrf(foot);
    }
    ctx.drawImage(c.off, 0, 0, w, h);
    const x = c.X(state.frame);
    ctx.strokeStyle = "#d62728";
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.moveTo(x, plotMargin.t);
    ctx.lineTo(x, h - plotMargin.b);
    ctx.stroke();
    const parts = [];
    if (data.insole) parts.push(["#111111", `insole ${data.insole.force_n[state.frame * 2 + foot].toFixed(0)}`]);
    data.bodies.forEach((b, i) => {
      const v = grfZ(b, foot, state.frame);
      if (state.visible[i] && v !== null) parts.push([b.color, `${b.label} ${v.toFixed(0)}`]);
    });
    ctx.font = "11px sans-serif";
    ctx.textAlign = "right";
    let y = 13;
    let xr = w - plotMargin.r;
    for (const [color, text] of parts.reverse()) {
      ctx.fillStyle = color;
      ctx.fillText(text, xr, y);
      xr -= ctx.measureText(text).width + 10;
    }
  }

  const laneBodies = data.bodies.map((b, i) => [b, i]).filter(([b]) => isReconstruction(b));
  const timelineLeft = 120;
  function drawTimeline() {
    const canvas = $("timeline");
    const { ctx, w, h } = cssSize(canvas);
    ctx.fillStyle = "#ffffff";
    ctx.fillRect(0, 0, w, h);
    const pw = w - timelineLeft - plotMargin.r;
    const n = Math.max(1, laneBodies.length);
    const lh = (h - 4) / n;
    ctx.font = "11px sans-serif";
    laneBodies.forEach(([b, i], k) => {
      const y = 2 + k * lh;
      ctx.fillStyle = state.visible[i] ? "#f1f3f6" : "#fafafa";
      ctx.fillRect(timelineLeft, y + 1, pw, lh - 2);
      ctx.fillStyle = b.color;
      ctx.textAlign = "right";
      const text = b.label.length > 18 ? `${b.label.slice(0, 17)}…` : b.label;
      ctx.fillText(text, timelineLeft - 6, y + lh / 2 + 4);
      for (const [a, d] of b.falls) {
        const xa = timelineLeft + (a / Math.max(1, T - 1)) * pw;
        const xd = timelineLeft + (d / Math.max(1, T - 1)) * pw;
        ctx.fillStyle = "rgba(230, 120, 30, 0.55)";
        ctx.fillRect(xa, y + 2, Math.max(2, xd - xa), lh - 4);
        ctx.fillStyle = "#d62728";
        ctx.fillRect(xd - 1.5, y + 1, 3, lh - 2);
      }
      if (b.falls.length === 0) {
        ctx.fillStyle = "#999";
        ctx.textAlign = "left";
        ctx.fillText("no falls", timelineLeft + 6, y + lh / 2 + 4);
      }
    });
    const x = timelineLeft + (state.frame / Math.max(1, T - 1)) * pw;
    ctx.fillStyle = "#222";
    ctx.fillRect(x - 1, 0, 2, h);
  }

  return {
    margin: plotMargin,
    timelineLeft,
    // draw the GRF plots and the timeline at state.frame
    draw() {
      drawGrf(0);
      drawGrf(1);
      drawTimeline();
    },
    // drop the cached plots (after a resize or a change of the bodies shown)
    invalidate() {
      plotCache.clear();
    },
  };
}
