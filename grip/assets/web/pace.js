/* Pace in the GRIP viewer (grip/export/html.py inlines this file next to viewer.js).
 *
 * A classic script: it only defines gripPacePlot() and gripPaceMarks(), which gripViewer() calls
 * when the page's data has a "pace" block (format documented in grip/export/html.py):
 *   - gripPacePlot draws, under the timeline and on its time axis, the horizontal distance of
 *     each body's pelvis to the pelvis it followed (solid; GRIP: its kinematic estimate) and to
 *     the ground truth's (dashed), with a cursor and the values at the current frame;
 *   - gripPaceMarks puts into the 3D scene the estimate's pelvis (a ring at its height), its
 *     path on the floor and the gap between it and the body's pelvis (a line on the floor).
 * Every piece of text that comes from the data is drawn on a canvas, never put in as HTML.
 */
"use strict";

function gripPacePlot(data, canvas, opts) {
  // opts: cssSize(canvas), niceStep(span, n), left (px, the timeline's lane start), right (px),
  // visible(bodyKey) -> bool
  const T = data.frames;
  const fps = data.fps;
  const pace = data.pace;
  const top = 22;
  const bottom = 16;
  let cache = null;

  const X = (w, f) => opts.left + (f / Math.max(1, T - 1)) * (w - opts.left - opts.right);
  const shown = () => pace.series.filter((s) => opts.visible(s.body));

  function drawStatic(w, h) {
    const { off, ctx } = gripOffscreenCanvas(w, h);
    const ph = h - top - bottom;
    const series = shown();
    let ymax = 0.2;
    for (const s of series) for (const v of s.dist_mm) if (v / 1000 > ymax) ymax = v / 1000;
    ymax *= 1.1;
    const Y = (m) => top + ph - (m / ymax) * ph;
    ctx.font = "11px sans-serif";
    ctx.lineWidth = 1;
    ctx.strokeStyle = "#e3e3e3";
    ctx.fillStyle = "#555";
    const ys = opts.niceStep(ymax, 3);
    for (let v = 0; v <= ymax + 1e-9; v += ys) {
      ctx.beginPath();
      ctx.moveTo(opts.left, Y(v));
      ctx.lineTo(w - opts.right, Y(v));
      ctx.stroke();
      ctx.textAlign = "right";
      ctx.fillText(`${+v.toFixed(2)} m`, opts.left - 4, Y(v) + 4);
    }
    const xs = opts.niceStep(T / fps, 8);
    ctx.textAlign = "center";
    for (let t = 0; t <= (T - 1) / fps + 1e-9; t += xs) ctx.fillText(`${+t.toFixed(2)} s`, X(w, t * fps), h - 4);
    for (const s of series) {
      ctx.strokeStyle = s.color;
      ctx.setLineDash(s.to === "truth" ? [5, 3] : []);
      ctx.lineWidth = s.to === "truth" ? 1.2 : 1.8;
      ctx.beginPath();
      for (let f = 0; f < T; f++) {
        const x = X(w, f);
        const y = Y(s.dist_mm[f] / 1000);
        if (f === 0) ctx.moveTo(x, y);
        else ctx.lineTo(x, y);
      }
      ctx.stroke();
    }
    ctx.setLineDash([]);
    ctx.fillStyle = "#222";
    ctx.textAlign = "left";
    ctx.font = "12px sans-serif";
    const title = "pelvis distance, horizontal";
    ctx.fillText(title, 6, 13);
    const after = 10 + ctx.measureText(title).width;
    ctx.font = "11px sans-serif";
    ctx.fillStyle = "#666";
    ctx.fillText("(solid: to the estimate it followed; dashed: to the truth)", after, 13);
    if (series.length === 0) {
      ctx.fillStyle = "#888";
      ctx.textAlign = "center";
      ctx.fillText("no body with a pace shown", (opts.left + w) / 2, top + ph / 2);
    }
    return { off, w, h };
  }

  function draw(frame) {
    const { ctx, w, h } = opts.cssSize(canvas);
    if (!cache || cache.w !== w || cache.h !== h) cache = drawStatic(w, h);
    ctx.drawImage(cache.off, 0, 0, w, h);
    const x = X(w, frame);
    ctx.strokeStyle = "#d62728";
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.moveTo(x, top);
    ctx.lineTo(x, h - bottom);
    ctx.stroke();
    ctx.font = "11px sans-serif";
    ctx.textAlign = "right";
    let xr = w - opts.right;
    for (const s of shown().reverse()) {
      const text = `${s.label} ${(s.dist_mm[frame] / 1000).toFixed(2)} m`;
      ctx.fillStyle = s.color;
      ctx.fillText(text, xr, 12);
      xr -= ctx.measureText(text).width + 12;
    }
  }

  return { draw, invalidate: () => (cache = null) };
}

function gripPaceMarks(THREE, data, parent, color) {
  // the estimate's pelvis of the first body (data.pace.ref_root_mm), drawn in its root group so
  // that it moves with it side by side and hides with it
  const r = data.pace.ref_root_mm;
  const T = data.frames;
  const material = new THREE.LineBasicMaterial({ color, transparent: true, opacity: 0.75, depthTest: false });
  const path = new THREE.BufferGeometry();
  const pts = new Float32Array(3 * T);
  for (let f = 0; f < T; f++) {
    pts[3 * f] = r[3 * f] / 1000;
    pts[3 * f + 1] = r[3 * f + 1] / 1000;
    pts[3 * f + 2] = 0.004;
  }
  path.setAttribute("position", new THREE.BufferAttribute(pts, 3));
  const trail = new THREE.Line(path, material);
  const gapGeometry = new THREE.BufferGeometry();
  gapGeometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(6), 3));
  const gap = new THREE.Line(gapGeometry, new THREE.LineBasicMaterial({ color: 0xd62728, depthTest: false }));
  const ring = new THREE.Mesh(
    new THREE.TorusGeometry(0.09, 0.012, 8, 32),
    new THREE.MeshBasicMaterial({ color, transparent: true, opacity: 0.85, depthTest: false }),
  );
  const dot = new THREE.Mesh(
    new THREE.CircleGeometry(0.05, 24),
    new THREE.MeshBasicMaterial({ color, transparent: true, opacity: 0.6, depthTest: false }),
  );
  for (const o of [trail, gap, ring, dot]) {
    o.renderOrder = 11;
    parent.add(o);
  }

  function place(f, pelvis) {
    // pelvis: the body's pelvis at frame f (a THREE.Vector3 in its root group's frame)
    const x = r[3 * f] / 1000;
    const y = r[3 * f + 1] / 1000;
    ring.position.set(x, y, r[3 * f + 2] / 1000);
    dot.position.set(x, y, 0.005);
    const g = gapGeometry.attributes.position;
    g.setXYZ(0, pelvis.x, pelvis.y, 0.006);
    g.setXYZ(1, x, y, 0.006);
    g.needsUpdate = true;
    gapGeometry.computeBoundingSphere();
  }
  return { place };
}
