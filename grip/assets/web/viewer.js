/* The GRIP motion viewer (grip/export/html.py inlines this file into every page it writes).
 *
 * A classic script: it only defines gripViewer(). The page's bootstrap imports three.js and its
 * OrbitControls from the module sources inlined in the same page and then calls
 * gripViewer(THREE, OrbitControls, data, reportError) with the JSON of the page's "grip-data"
 * block (format "grip-viewer", documented in grip/export/html.py). World frame: z up, metres
 * (the JSON holds millimetres and quaternions times data.quat_scale). The GRF plots and the
 * timeline are gripPlots() (plots.js), the pace gripPacePlot() and gripPaceMarks() (pace.js),
 * inlined before this file in the same script element.
 *
 * Every piece of text that comes from the data (clip, method and file names) is put into the page
 * with textContent, never as HTML.
 */
"use strict";

function gripViewer(THREE, OrbitControls, data, reportError) {
  if (data.format !== "grip-viewer" || data.version !== 1) {
    throw new Error("not a grip-viewer data block of version 1");
  }
  const T = data.frames;
  const fps = data.fps;
  const NJ = data.skeleton.parents.length;
  const QS = data.quat_scale;
  const $ = (id) => document.getElementById(id);

  const state = {
    frame: 0,
    playing: false,
    speed: 1,
    side: false,
    forces: true,
    props: true,
    follow: true,
    visible: data.bodies.map(() => true),
  };
  // the address may say where to start: #frame=N (negative: from the end), &side=1, &play=1
  const hashFrame = /(?:^#|&)frame=(-?\d+)/.exec(window.location.hash);
  if (hashFrame) {
    const f = parseInt(hashFrame[1], 10);
    state.frame = Math.min(T - 1, Math.max(0, f < 0 ? T + f : f));
  }
  if (/(?:^#|&)side=1(?:&|$)/.test(window.location.hash)) state.side = true;

  // ---------------------------------------------------------------------------- helpers
  const el = (tag, attrs, text) => {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    return e;
  };
  const cssSize = (canvas) => {
    const r = canvas.getBoundingClientRect();
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(r.width));
    const h = Math.max(1, Math.round(r.height));
    if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
      canvas.width = Math.round(w * dpr);
      canvas.height = Math.round(h * dpr);
    }
    const ctx = canvas.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    return { ctx, w, h };
  };
  const niceStep = (span, n) => {
    const raw = span / Math.max(1, n);
    const p = Math.pow(10, Math.floor(Math.log10(raw)));
    for (const m of [1, 2, 5, 10]) if (raw <= m * p) return m * p;
    return 10 * p;
  };

  // ---------------------------------------------------------------------------- page header
  $("title").textContent = data.title;
  const legend = $("legend");
  data.bodies.forEach((b, i) => {
    const label = el("label", { class: "body-toggle", title: b.detail });
    const box = el("input", { type: "checkbox" });
    box.checked = true;
    box.dataset.body = b.key;
    box.addEventListener("change", () => {
      state.visible[i] = box.checked;
      applyVisibility();
    });
    const swatch = el("span", { class: "swatch" });
    swatch.style.background = b.color;
    if (b.opacity < 1) swatch.style.opacity = String(Math.max(0.5, b.opacity));
    label.append(box, swatch, el("span", {}, b.label));
    if (b.mpjpe_mm !== null) label.append(el("span", { class: "stat" }, `MPJPE ${b.mpjpe_mm.toFixed(0)} mm`));
    legend.append(label);
  });
  const option = (id, key, after) => {
    const box = $(id);
    box.checked = state[key];
    box.addEventListener("change", () => {
      state[key] = box.checked;
      after();
    });
  };

  // ---------------------------------------------------------------------------- 2D plots
  const timeOf = (f) => f / fps;
  // the GRF plots and the falls timeline (plots.js)
  const plots = gripPlots(data, state, { cssSize, niceStep });
  const timelineLeft = plots.timelineLeft;

  function frameFromX(canvas, clientX, left) {
    const r = canvas.getBoundingClientRect();
    const w = r.width - left - plots.margin.r;
    const u = (clientX - r.left - left) / Math.max(1, w);
    return Math.min(T - 1, Math.max(0, Math.round(u * (T - 1))));
  }

  function seekFromPointer(canvas, left) {
    let dragging = false;
    const go = (e) => setFrame(frameFromX(canvas, e.clientX, left));
    canvas.addEventListener("pointerdown", (e) => {
      dragging = true;
      canvas.setPointerCapture(e.pointerId);
      go(e);
    });
    canvas.addEventListener("pointermove", (e) => dragging && go(e));
    canvas.addEventListener("pointerup", () => (dragging = false));
  }
  seekFromPointer($("timeline"), timelineLeft);
  seekFromPointer($("grf-left"), plots.margin.l);
  seekFromPointer($("grf-right"), plots.margin.l);

  // the pace plot (pace.js) on the timeline's time axis, under it
  const paceCanvas = $("pace");
  const pacePlot = data.pace ? gripPacePlot(data, paceCanvas, {
    cssSize, niceStep, left: timelineLeft, right: plots.margin.r,
    visible: (key) => state.visible[data.bodies.findIndex((b) => b.key === key)],
  }) : null;
  paceCanvas.hidden = !pacePlot;
  if (pacePlot) seekFromPointer(paceCanvas, timelineLeft);

  // ---------------------------------------------------------------------------- controls
  const slider = $("frame");
  slider.max = String(T - 1);
  slider.addEventListener("input", () => setFrame(parseInt(slider.value, 10)));
  const playButton = $("play");
  const setPlaying = (on) => {
    state.playing = on;
    playButton.textContent = on ? "Pause" : "Play";
  };
  playButton.addEventListener("click", () => setPlaying(!state.playing));
  $("speed").addEventListener("change", () => (state.speed = parseFloat($("speed").value)));
  document.addEventListener("keydown", (e) => {
    const tag = (e.target && e.target.tagName) || "";
    if (tag === "INPUT" || tag === "SELECT" || tag === "BUTTON") return;
    if (e.key === " ") {
      setPlaying(!state.playing);
      e.preventDefault();
    } else if (e.key === "ArrowRight" || e.key === "ArrowLeft") {
      const step = (e.shiftKey ? 10 : 1) * (e.key === "ArrowRight" ? 1 : -1);
      setFrame(state.frame + step);
      e.preventDefault();
    }
  });

  // ---------------------------------------------------------------------------- 3D scene
  const view = $("view");
  let renderer = null;
  try {
    renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  } catch (err) {
    // the timeline and the plots still work; the page reports the missing 3D view
    reportError(`the 3D view needs WebGL, which this browser does not provide (${err.message})`);
  }
  if (renderer) {
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.shadowMap.enabled = true;
    renderer.shadowMap.type = THREE.PCFSoftShadowMap;
    view.prepend(renderer.domElement);
  }
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xdfe6ee);
  const camera = new THREE.PerspectiveCamera(40, 1, 0.05, 200);
  camera.up.set(0, 0, 1);

  scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8070, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.8);
  sun.castShadow = true;
  sun.shadow.mapSize.set(2048, 2048);
  Object.assign(sun.shadow.camera, { left: -4, right: 4, top: 4, bottom: -4, near: 0.5, far: 30 });
  scene.add(sun, sun.target);

  const mm = (v) => v / 1000;
  const floor = data.floor;
  const floorMesh = new THREE.Mesh(
    new THREE.PlaneGeometry(floor.size_m[0], floor.size_m[1]),
    new THREE.MeshStandardMaterial({ color: 0xc9c6c0, roughness: 0.95 }),
  );
  floorMesh.position.set(floor.center_m[0], floor.center_m[1], 0);
  floorMesh.receiveShadow = true;
  scene.add(floorMesh);
  const gridSize = Math.ceil(Math.max(floor.size_m[0], floor.size_m[1]));
  const grid = new THREE.GridHelper(gridSize, gridSize * 2, 0x8f8f8f, 0xb0b0b0);
  grid.rotation.x = Math.PI / 2;
  grid.position.set(floor.center_m[0], floor.center_m[1], 0.001);
  scene.add(grid);

  const propGroup = new THREE.Group();
  for (const o of data.objects) {
    const g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.Float32BufferAttribute(o.vertices_mm.map(mm), 3));
    g.setIndex(o.faces);
    const flat = g.toNonIndexed();
    flat.computeVertexNormals();
    const mesh = new THREE.Mesh(flat, new THREE.MeshStandardMaterial({
      color: 0xb08d5b, roughness: 0.8, side: THREE.DoubleSide, transparent: true, opacity: 0.9,
    }));
    mesh.castShadow = true;
    mesh.receiveShadow = true;
    mesh.name = o.name;
    propGroup.add(mesh);
  }
  scene.add(propGroup);

  // one geometry per body-model shape, shared by every body
  const Y_AXIS = new THREE.Vector3(0, 1, 0);
  const shapes = data.skeleton.geoms.map((g) => {
    let geometry;
    const quat = new THREE.Quaternion();
    if (g.kind === "capsule") {
      geometry = new THREE.CapsuleGeometry(mm(g.size_mm[0]), 2 * mm(g.size_mm[1]), 6, 14);
      quat.setFromUnitVectors(Y_AXIS, new THREE.Vector3(...g.axis).normalize());
    } else if (g.kind === "box") {
      geometry = new THREE.BoxGeometry(...g.size_mm.map((s) => 2 * mm(s)));
    } else {
      geometry = new THREE.SphereGeometry(mm(g.size_mm[0]), 20, 14);
    }
    return { joint: g.joint, geometry, quat, pos: new THREE.Vector3(...g.pos_mm.map(mm)) };
  });
  const offsets = data.skeleton.offsets_mm.map((o) => new THREE.Vector3(...o.map(mm)));
  const parents = data.skeleton.parents;

  const sideDir = new THREE.Vector3(data.side_dir[0], data.side_dir[1], 0);
  const discGeometry = new THREE.CylinderGeometry(0.035, 0.035, 0.006, 24);
  discGeometry.rotateX(Math.PI / 2);

  // a force arrow: a unit shaft along +y scaled to its length, and a cone head on top
  const HEAD = 0.06;
  const shaftGeometry = new THREE.CylinderGeometry(0.009, 0.009, 1, 10);
  shaftGeometry.translate(0, 0.5, 0);
  const headGeometry = new THREE.ConeGeometry(0.025, HEAD, 14);
  headGeometry.translate(0, -HEAD / 2, 0);
  function forceMarkers(parent, color) {
    // drawn over the bodies: a force from under the foot runs up through the leg
    const material = new THREE.MeshBasicMaterial({ color, depthTest: false, transparent: true, opacity: 0.9 });
    return [0, 1].map(() => {
      const disc = new THREE.Mesh(discGeometry, material);
      const arrow = new THREE.Group();
      const shaft = new THREE.Mesh(shaftGeometry, material);
      const head = new THREE.Mesh(headGeometry, material);
      for (const mesh of [disc, shaft, head]) mesh.renderOrder = 10;
      arrow.add(shaft, head);
      parent.add(disc, arrow);
      return { disc, arrow, shaft, head };
    });
  }
  const tmpV = new THREE.Vector3();
  function placeMarker(m, cop, f, foot, force) {
    const k = f * 6 + foot * 3;
    const ok = cop && cop[k] !== null && state.forces;
    m.disc.visible = m.arrow.visible = !!ok;
    if (!ok) return;
    m.disc.position.set(mm(cop[k]), mm(cop[k + 1]), mm(cop[k + 2]) + 0.004);
    const n = force ? Math.hypot(force[0], force[1], force[2]) : 0;
    if (n < 1) {
      m.arrow.visible = false;
      return;
    }
    const length = Math.max(2 * HEAD, n / data.newtons_per_m);
    m.arrow.position.copy(m.disc.position);
    m.arrow.quaternion.setFromUnitVectors(Y_AXIS, tmpV.set(force[0] / n, force[1] / n, force[2] / n));
    m.shaft.scale.set(1, length - HEAD, 1);
    m.head.position.set(0, length, 0);
  }

  const bodies = data.bodies.map((b, index) => {
    const root = new THREE.Group();
    root.name = b.key;
    const material = new THREE.MeshStandardMaterial({
      color: b.color, roughness: 0.55, metalness: 0.05,
      transparent: b.opacity < 1, opacity: b.opacity, depthWrite: b.opacity >= 1,
    });
    const joints = [];
    for (let j = 0; j < NJ; j++) {
      const g = new THREE.Group();
      joints.push(g);
      root.add(g);
    }
    for (const s of shapes) {
      const mesh = new THREE.Mesh(s.geometry, material);
      mesh.position.copy(s.pos);
      mesh.quaternion.copy(s.quat);
      mesh.castShadow = b.opacity >= 1;
      joints[s.joint].add(mesh);
    }
    // darker than the body, over which they are drawn
    const markers = b.cop_mm ? forceMarkers(root, new THREE.Color(b.color).multiplyScalar(0.12)) : null;
    scene.add(root);
    return {
      data: b, index, root, joints, markers,
      quats: joints.map(() => new THREE.Quaternion()),
      pos: joints.map(() => new THREE.Vector3()),
    };
  });
  // the insoles belong to the recording: drawn with the ground truth's body when there is one
  const insoleOwner = bodies.find((b) => b.data.role === "ground_truth") || bodies[0];
  const insoleMarkers = data.insole ? forceMarkers(insoleOwner.root, 0x111111) : null;
  // the pelvis the first body followed (its estimate's), with the gap to it (pace.js)
  const paceMarks = data.pace && data.pace.ref_root_mm
    ? gripPaceMarks(THREE, data, bodies[0].root, bodies[0].data.color) : null;

  function poseBody(b, f) {
    const q = b.data.quat_wxyz;
    const r = b.data.root_mm;
    const base = f * NJ * 4;
    for (let j = 0; j < NJ; j++) {
      const k = base + 4 * j;
      b.quats[j].set(q[k + 1] / QS, q[k + 2] / QS, q[k + 3] / QS, q[k] / QS).normalize();
    }
    b.pos[0].set(mm(r[3 * f]), mm(r[3 * f + 1]), mm(r[3 * f + 2]));
    for (let j = 1; j < NJ; j++) {
      b.pos[j].copy(offsets[j]).applyQuaternion(b.quats[parents[j]]).add(b.pos[parents[j]]);
    }
    for (let j = 0; j < NJ; j++) {
      b.joints[j].position.copy(b.pos[j]);
      b.joints[j].quaternion.copy(b.quats[j]);
    }
    if (b.markers) {
      for (const foot of [0, 1]) {
        const k = f * 6 + foot * 3;
        const force = b.data.grf_n ? b.data.grf_n.slice(k, k + 3) : null;
        placeMarker(b.markers[foot], b.data.cop_mm, f, foot, force);
      }
    }
  }

  function placeBodies() {
    for (const b of bodies) {
      b.root.position.copy(sideDir).multiplyScalar(state.side ? b.index * data.side_step_m : 0);
      b.root.visible = state.visible[b.index];
    }
  }

  // camera: looking at the first body's pelvis from the side of its walk
  const controls = new OrbitControls(camera, renderer ? renderer.domElement : view);
  controls.enableDamping = false;
  const target = new THREE.Vector3();
  function followTarget(out) {
    const p = bodies[0].pos[0];
    out.set(p.x, p.y, Math.max(0.8, p.z) * 0.85);
    if (state.side) {
      const shown = bodies.filter((b) => state.visible[b.index]).map((b) => b.index);
      if (shown.length) {
        const mid = (Math.min(...shown) + Math.max(...shown)) / 2;
        out.addScaledVector(sideDir, mid * data.side_step_m);
      }
    }
    return out;
  }
  const travel = new THREE.Vector3(data.travel_dir[0], data.travel_dir[1], 0);
  function frameView() {
    // overlaid: three-quarter view from the front right; side by side: more from the front,
    // further away the more lanes there are, so that the lanes stand next to each other
    followTarget(target);
    if (state.side) {
      const lanes = bodies.filter((b) => state.visible[b.index]).length;
      camera.position.copy(target).addScaledVector(sideDir, -1.2).addScaledVector(travel, 1.6 + 0.7 * lanes);
    } else {
      camera.position.copy(target).addScaledVector(sideDir, -2.6).addScaledVector(travel, 2.2);
    }
    camera.position.z = target.z + 0.7;
    controls.target.copy(target);
    controls.update();
  }
  for (const b of bodies) poseBody(b, state.frame);
  placeBodies();
  frameView();

  let dirty = true;
  controls.addEventListener("change", () => (dirty = true));

  function resize() {
    const w = Math.max(1, view.clientWidth);
    const h = Math.max(1, view.clientHeight);
    if (renderer) renderer.setSize(w, h);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    plots.invalidate();
    dirty = true;
    drawAll2d();
  }

  function applyVisibility() {
    placeBodies();
    if (insoleMarkers) for (const m of insoleMarkers) m.disc.visible = m.arrow.visible = state.forces;
    propGroup.visible = state.props;
    plots.invalidate();
    if (pacePlot) pacePlot.invalidate();
    updateFrame(true);
  }

  function drawAll2d() {
    plots.draw();
    if (pacePlot) pacePlot.draw(state.frame);
  }

  function updateFrame(moveCamera) {
    const f = state.frame;
    for (const b of bodies) poseBody(b, f);
    if (paceMarks) paceMarks.place(f, bodies[0].pos[0]);
    if (insoleMarkers) {
      for (const foot of [0, 1]) {
        const n = data.insole.force_n[f * 2 + foot];
        placeMarker(insoleMarkers[foot], data.insole.cop_mm, f, foot, [0, 0, n]);
      }
    }
    if (state.follow && moveCamera) {
      const next = followTarget(new THREE.Vector3());
      const delta = next.clone().sub(controls.target);
      camera.position.add(delta);
      controls.target.copy(next);
      controls.update();
    }
    const p = bodies[0].pos[0];
    sun.target.position.copy(p);
    sun.position.copy(p).add(new THREE.Vector3(2.5, -2.0, 6.0));
    slider.value = String(f);
    $("clock").textContent = `frame ${f} / ${T - 1} · ${timeOf(f).toFixed(2)} s of ${timeOf(T - 1).toFixed(2)} s`;
    drawAll2d();
    dirty = true;
  }

  function setFrame(f) {
    const next = Math.min(T - 1, Math.max(0, Math.round(f)));
    if (next === state.frame) return;
    state.frame = next;
    updateFrame(true);
  }

  option("opt-side", "side", () => {
    applyVisibility();
    frameView();
  });
  option("opt-forces", "forces", applyVisibility);
  option("opt-follow", "follow", () => updateFrame(true));
  option("opt-props", "props", applyVisibility);
  if (data.objects.length === 0) $("opt-props").parentElement.hidden = true;
  if (!data.insole && !data.bodies.some((b) => b.cop_mm)) $("opt-forces").parentElement.hidden = true;

  if (/(?:^#|&)play=1(?:&|$)/.test(window.location.hash)) setPlaying(true);
  window.addEventListener("resize", resize);
  resize();
  applyVisibility();

  let last = null;
  let carry = 0;
  function tick(now) {
    if (state.playing && last !== null) {
      carry += ((now - last) / 1000) * fps * state.speed;
      const steps = Math.floor(carry);
      if (steps > 0) {
        carry -= steps;
        state.frame = (state.frame + steps) % T;
        updateFrame(true);
      }
    } else {
      carry = 0;
    }
    last = now;
    if (dirty && renderer) {
      renderer.render(scene, camera);
      dirty = false;
    }
    window.requestAnimationFrame(tick);
  }
  if (renderer) renderer.render(scene, camera);
  dirty = false;
  window.requestAnimationFrame(tick);
  document.body.dataset.ready = `${T},${data.bodies.length}`;
}
