/* facewrap report viewer (MIT). Reads the JSON in <script id="facewrap-data">,
 * draws its meshes with three.js (global FWTHREE, see three-viewer.min.js) and wires
 * the controls: layer toggles and opacity, heatmap choice and range with a colour
 * bar, blendshape sliders, view presets, and a value read-out under the pointer;
 * draws point sets (landmarks) as small balls (diamonds: detected; hollow wire
 * diamonds: flagged low-confidence), each set with a toggle, and text
 * labels that follow the view. A layer that comes as its glTF has it (vertex_ids:
 * split at UV seams; normals; uvs and groups of triangles, each showing one of the
 * page's textures) is drawn with those normals and images; its heatmaps and
 * blendshapes are per original vertex, and its normals stay smooth across the seams
 * when a blendshape moves it. Distances print as facewrap.units.format_distance
 * does (about four significant digits, never finer than the unit's resolution).
 * Sets window.facewrapViewer = {ready, webgl, meshes, points, pointStyles, labels,
 * textures, error} once drawn with every texture (tests).
 */
(function () {
  "use strict";
  const T = window.FWTHREE;
  const state = { ready: false, webgl: false, meshes: 0, error: null, frames: 0 };
  window.facewrapViewer = state;

  // viridis, 11 stops (sRGB); the colour bar uses the same stops
  const VIRIDIS = ["#440154", "#482475", "#414487", "#355f8d", "#2a788e", "#21918c",
                   "#22a884", "#44bf70", "#7ad151", "#bddf26", "#fde725"];
  const NO_VALUE = [0.62, 0.62, 0.64];
  const STOPS = VIRIDIS.map(function (h) {
    return [1, 3, 5].map(function (i) { return parseInt(h.substr(i, 2), 16) / 255; });
  });

  function $(id) { return document.getElementById(id); }

  function decode(b64, Type) {
    const bin = atob(b64);
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    return new Type(bytes.buffer);
  }

  function srgbToLinear(c) {
    return c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4);
  }

  function colormap(t) {
    if (!(t >= 0)) t = 0;
    if (t > 1) t = 1;
    const x = t * (STOPS.length - 1);
    const i = Math.min(Math.floor(x), STOPS.length - 2);
    const f = x - i;
    const a = STOPS[i], b = STOPS[i + 1];
    return [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])];
  }

  function fmt(v) {
    if (!Number.isFinite(v)) return "–";
    const a = Math.abs(v);
    if (a !== 0 && (a < 1e-3 || a >= 1e5)) return v.toExponential(2);
    return Number(v.toPrecision(3)).toString();
  }

  // the twin of facewrap.units.format_distance: `most` is the unit's resolution
  function fmtDistance(v, most) {
    if (!Number.isFinite(v)) return "–";
    if (v === 0) return "0";
    const a = Math.abs(v), step = Math.pow(10, -most);
    if (a < 0.5 * step) return "< " + step.toFixed(most);
    const d = Math.max(0, Math.min(most, 3 - Math.floor(Math.log10(a))));
    if (a < 1e4) return v.toFixed(d);
    return v.toLocaleString("en-US", { minimumFractionDigits: d, maximumFractionDigits: d });
  }
  state.formatDistance = fmtDistance;  // for tests: the twin of format_distance

  // one ball for the landmarks: an icosahedron, scaled and moved per point
  const ICO = (function () {
    const t = (1 + Math.sqrt(5)) / 2;
    const v = [-1, t, 0, 1, t, 0, -1, -t, 0, 1, -t, 0, 0, -1, t, 0, 1, t, 0, -1, -t,
               0, 1, -t, t, 0, -1, t, 0, 1, -t, 0, -1, -t, 0, 1];
    const f = [0, 11, 5, 0, 5, 1, 0, 1, 7, 0, 7, 10, 0, 10, 11, 1, 5, 9, 5, 11, 4,
               11, 10, 2, 10, 7, 6, 7, 1, 8, 3, 9, 4, 3, 4, 2, 3, 2, 6, 3, 6, 8, 3, 8, 9,
               4, 9, 5, 2, 4, 11, 6, 2, 10, 8, 6, 7, 9, 8, 1];
    const n = Math.sqrt(1 + t * t);
    return { v: v.map(function (x) { return x / n; }), f: f };
  })();

  // a diamond for detected landmarks (and, hollow, for the doubtful ones): an
  // octahedron
  const OCTA = { v: [1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1],
                 f: [0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5] };

  function ballsGeometry(centres, radius, shape) {
    shape = shape || ICO;
    const k = centres.length / 3, nv = shape.v.length / 3;
    const pos = new Float32Array(k * shape.v.length);
    const idx = new Uint32Array(k * shape.f.length);
    for (let p = 0; p < k; p++) {
      for (let j = 0; j < nv; j++) for (let c = 0; c < 3; c++)
        pos[p * shape.v.length + 3 * j + c] = centres[3 * p + c] + radius * shape.v[3 * j + c];
      for (let j = 0; j < shape.f.length; j++) idx[p * shape.f.length + j] = p * nv + shape.f[j];
    }
    const g = new T.BufferGeometry();
    g.setAttribute("position", new T.BufferAttribute(pos, 3));
    g.setIndex(new T.BufferAttribute(idx, 1));
    g.computeVertexNormals();
    return g;
  }

  // angle-weighted smooth normals (as facewrap.geometry.normals.vertex_normals) of
  // positions pos (3k) over triangles idx; written vertices with the same id in ids
  // (split at a UV seam) share one normal
  function smoothNormals(pos, idx, ids, n, out) {
    const acc = new Float64Array(3 * n);
    const e = [0, 0, 0, 0, 0, 0, 0, 0, 0];
    for (let t = 0; t < idx.length; t += 3) {
      const a = 3 * idx[t], b = 3 * idx[t + 1], c = 3 * idx[t + 2];
      const ux = pos[b] - pos[a], uy = pos[b + 1] - pos[a + 1], uz = pos[b + 2] - pos[a + 2];
      const vx = pos[c] - pos[a], vy = pos[c + 1] - pos[a + 1], vz = pos[c + 2] - pos[a + 2];
      const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      const len = Math.hypot(nx, ny, nz);
      if (!(len > 0)) continue;
      // edges leaving each corner: a->b, a->c; b->c, b->a; c->a, c->b
      const P = [a, b, c];
      for (let k = 0; k < 3; k++) {
        const o = P[k], p = P[(k + 1) % 3], q = P[(k + 2) % 3];
        for (let d = 0; d < 3; d++) { e[d] = pos[p + d] - pos[o + d]; e[3 + d] = pos[q + d] - pos[o + d]; }
        const dot = e[0] * e[3] + e[1] * e[4] + e[2] * e[5];
        const angle = Math.atan2(len, dot);
        const v = 3 * ids[idx[t + k]];
        acc[v] += angle * nx / len; acc[v + 1] += angle * ny / len; acc[v + 2] += angle * nz / len;
      }
    }
    for (let j = 0; j < ids.length; j++) {
      const v = 3 * ids[j], l = Math.hypot(acc[v], acc[v + 1], acc[v + 2]);
      if (l > 0) { out[3 * j] = acc[v] / l; out[3 * j + 1] = acc[v + 1] / l; out[3 * j + 2] = acc[v + 2] / l; }
    }
  }

  function fail(message) {
    state.error = message;
    const box = $("fw-viewer-message");
    box.textContent = message;
    box.hidden = false;
    state.ready = true;
    console.warn("facewrap viewer: " + message);
  }

  function main() {
    const data = JSON.parse($("facewrap-data").textContent);
    const host = $("fw-canvas-host");
    if (!T) { fail("three.js did not load."); return; }
    if (!data.meshes.length) { fail("No meshes in this report."); return; }

    let renderer;
    try {
      renderer = new T.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    } catch (e) {
      fail("3D view unavailable: this browser has no WebGL.");
      return;
    }
    state.webgl = true;
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.setClearColor(0xeef1f5, 1);
    renderer.outputColorSpace = T.SRGBColorSpace;
    host.appendChild(renderer.domElement);

    const scene = new T.Scene();
    const camera = new T.PerspectiveCamera(30, 1, 0.1, 1000);
    scene.add(new T.HemisphereLight(0xffffff, 0x8d8d99, 1.4));
    const headlight = new T.DirectionalLight(0xffffff, 1.6);
    headlight.position.set(0.3, 0.5, 1);
    camera.add(headlight);
    scene.add(camera);

    // ---- textures (the baked images of the glTF layers) -----------------------
    const loads = [];
    const textures = (data.textures || []).map(function (uri) {
      const img = new Image();
      const tex = new T.Texture(img);
      tex.colorSpace = T.SRGBColorSpace;
      tex.wrapS = tex.wrapT = T.RepeatWrapping;   // a UDIM tile's u in [k, k + 1)
      img.src = uri;
      loads.push(img.decode().then(function () { tex.needsUpdate = true; }));
      return tex;
    });

    // ---- meshes -------------------------------------------------------------
    const layers = {};
    data.meshes.forEach(function (m, k) {
      const pos = decode(m.positions, Float32Array);
      const idx = decode(m.indices, Uint32Array);
      const geom = new T.BufferGeometry();
      geom.setAttribute("position", new T.BufferAttribute(pos, 3));
      geom.setIndex(new T.BufferAttribute(idx, 1));
      const colors = new Float32Array(pos.length);
      geom.setAttribute("color", new T.BufferAttribute(colors, 3));
      if (m.normals) geom.setAttribute("normal", new T.BufferAttribute(
        decode(m.normals, Float32Array), 3));
      else geom.computeVertexNormals();
      if (m.uvs) geom.setAttribute("uv", new T.BufferAttribute(decode(m.uvs, Float32Array), 2));
      geom.computeBoundingSphere();
      const groups = m.groups || [[0, idx.length / 3, -1]];
      const mats = groups.map(function (g, gi) {
        geom.addGroup(3 * g[0], 3 * g[1], gi);
        return new T.MeshStandardMaterial({
          color: new T.Color(g[2] >= 0 ? 0xffffff : m.color), roughness: 0.62,
          metalness: 0.0, side: T.DoubleSide, polygonOffset: true,
          polygonOffsetFactor: k, polygonOffsetUnits: k,
          map: g[2] >= 0 ? textures[g[2]] : null,
        });
      });
      const obj = new T.Mesh(geom, mats);
      obj.visible = m.visible;
      obj.renderOrder = k;
      scene.add(obj);
      const ids = m.vertex_ids ? decode(m.vertex_ids, Uint32Array) : null;
      layers[m.name] = { spec: m, obj: obj, mats: mats, groups: groups, geom: geom,
                         base: pos.slice(), normals: geom.getAttribute("normal").array.slice(),
                         ids: ids, n: ids ? m.n_original : pos.length / 3, scalar: null };
    });
    state.meshes = data.meshes.length;
    // for tests: a layer's geometry and materials
    state.layerOf = function (name) { return layers[name]; };

    // ---- point sets (landmarks) and labels -----------------------------------
    const headSphere = new T.Box3();
    Object.values(layers).forEach(function (l) { headSphere.expandByObject(l.obj); });
    const ballRadius = 0.006 * Math.max(headSphere.getBoundingSphere(new T.Sphere()).radius,
                                        1e-6);
    // markers: balls (given landmarks), diamonds (detected), hollow wire diamonds
    // half as large again (flagged: low-confidence), so the kinds tell apart at a glance
    const MARKER = { ball: [ICO, 1.0, false], diamond: [OCTA, 1.5, false],
                     ring: [OCTA, 1.8, true] };
    const pointSets = (data.points || []).map(function (p) {
      const m = MARKER[p.marker] || MARKER.ball;
      // the vendored bundle has the standard material only: a hollow marker is its
      // wireframe, lit by its own colour so it reads the same from every side
      const mat = new T.MeshStandardMaterial({ color: new T.Color(p.color),
        emissive: new T.Color(p.color), emissiveIntensity: m[2] ? 0.9 : 0.35,
        roughness: 0.4, flatShading: m[0] === OCTA, wireframe: m[2] });
      const obj = new T.Mesh(ballsGeometry(decode(p.positions, Float32Array),
                                           m[1] * ballRadius, m[0]), mat);
      obj.visible = p.visible;
      obj.renderOrder = 100;
      scene.add(obj);
      return { spec: p, obj: obj };
    });
    state.points = pointSets.length;
    // for tests: how each set is drawn (marker vertices per point, hollow or not)
    state.pointStyles = pointSets.map(function (p) {
      return { name: p.spec.name, marker: p.spec.marker || "ball",
               vertices: p.obj.geometry.getAttribute("position").count /
                         Math.max(p.spec.count, 1),
               wireframe: !!p.obj.material.wireframe, color: "#" + p.obj.material.color.getHexString() };
    });
    const labelHost = $("fw-labels");
    const labels = (data.labels || []).map(function (l) {
      const div = document.createElement("div");
      div.className = "fw-label";
      div.textContent = l.text;
      labelHost.appendChild(div);
      const set = pointSets.find(function (p) { return p.spec.name === l.layer; });
      return { div: div, at: new T.Vector3().fromArray(l.position), set: set };
    });
    state.labels = labels.length;
    document.querySelectorAll("[data-fw-points]").forEach(function (box) {
      const p = pointSets[parseInt(box.dataset.fwPoints, 10)];
      box.addEventListener("change", function () {
        p.obj.visible = box.checked;
        requestRender();
      });
    });

    function placeLabels() {
      const w = host.clientWidth, h = host.clientHeight, q = new T.Vector3();
      const placed = [];  // boxes already placed: a label that would overlap moves down
      labels.forEach(function (l) {
        q.copy(l.at).project(camera);
        const shown = l.set.obj.visible && q.z < 1 && Math.abs(q.x) <= 1 &&
                      Math.abs(q.y) <= 1;
        l.div.hidden = !shown;
        if (!shown) return;
        const x = (q.x + 1) / 2 * w, lw = l.div.offsetWidth + 4, lh = l.div.offsetHeight + 2;
        let y = (1 - q.y) / 2 * h;
        for (let moved = true; moved;) {
          moved = false;
          placed.forEach(function (b) {
            if (Math.abs(b.x - x) < Math.max(lw, b.w) && Math.abs(b.y - y) < lh) {
              y = b.y + lh;
              moved = true;
            }
          });
        }
        placed.push({ x: x, y: y, w: lw });
        l.div.style.left = x + "px";
        l.div.style.top = y + "px";
      });
    }

    // ---- camera -------------------------------------------------------------
    const up = new T.Vector3().fromArray(data.view.up).normalize();
    const front = new T.Vector3().fromArray(data.view.front).normalize();
    const controls = new T.OrbitControls(camera, renderer.domElement);
    controls.enableDamping = false;
    controls.addEventListener("change", requestRender);

    function visibleSphere() {
      const box = new T.Box3();
      Object.values(layers).forEach(function (l) {
        if (l.obj.visible) box.expandByObject(l.obj);
      });
      if (box.isEmpty()) Object.values(layers).forEach(function (l) {
        box.expandByObject(l.obj);
      });
      return box.getBoundingSphere(new T.Sphere());
    }

    function lookFrom(dir) {
      const s = visibleSphere();
      const r = Math.max(s.radius, 1e-6);
      const dist = r / Math.sin((camera.fov * Math.PI) / 360) * 0.86;
      camera.up.copy(up);
      camera.position.copy(s.center).addScaledVector(dir.clone().normalize(), dist);
      camera.near = dist / 100;
      camera.far = dist * 100;
      camera.updateProjectionMatrix();
      controls.target.copy(s.center);
      controls.update();
      requestRender();
    }
    const side = new T.Vector3().crossVectors(up, front).normalize();
    const views = {
      front: function () { return front.clone(); },
      left: function () { return side.clone().negate(); },
      right: function () { return side.clone(); },
      three_quarter: function () {
        return front.clone().multiplyScalar(0.8).addScaledVector(side, -0.55)
          .addScaledVector(up, 0.12);
      },
    };
    document.querySelectorAll("[data-fw-view]").forEach(function (b) {
      b.addEventListener("click", function () { lookFrom(views[b.dataset.fwView]()); });
    });

    // ---- layers -------------------------------------------------------------
    document.querySelectorAll("[data-fw-layer]").forEach(function (box) {
      const l = layers[box.dataset.fwLayer];
      box.checked = l.obj.visible;
      box.addEventListener("change", function () {
        l.obj.visible = box.checked;
        requestRender();
      });
    });
    document.querySelectorAll("[data-fw-opacity]").forEach(function (r) {
      const l = layers[r.dataset.fwOpacity];
      r.addEventListener("input", function () {
        const a = parseFloat(r.value);
        l.mats.forEach(function (mat) {
          mat.opacity = a;
          mat.transparent = a < 0.999;
          mat.depthWrite = a >= 0.999;
          mat.needsUpdate = true;
        });
        requestRender();
      });
    });

    // ---- heatmaps -----------------------------------------------------------
    const scalars = data.scalars.map(function (s) {
      return Object.assign({}, s, { data: decode(s.values, Float32Array),
                                    lo: s.range[0], hi: s.range[1] });
    });
    const select = $("fw-heatmap");
    const loInput = $("fw-range-lo"), hiInput = $("fw-range-hi");
    let active = null;

    function paint(layer, s) {
      const c = layer.geom.getAttribute("color");
      const span = s.hi - s.lo || 1;
      for (let i = 0; i < c.count; i++) {
        const v = s.data[layer.ids ? layer.ids[i] : i];
        const rgb = isNaN(v) ? NO_VALUE : colormap((v - s.lo) / span);
        c.array[3 * i] = srgbToLinear(rgb[0]);
        c.array[3 * i + 1] = srgbToLinear(rgb[1]);
        c.array[3 * i + 2] = srgbToLinear(rgb[2]);
      }
      c.needsUpdate = true;
    }

    // how a layer looks: "heat" (the heatmap's vertex colours), "plain" (its own
    // colour, so the parts that follow stand apart from a heatmap) or "own" (its
    // textures, as its glTF shows it, else its colour)
    function showAs(l, look) {
      l.mats.forEach(function (mat, gi) {
        const t = look === "own" ? l.groups[gi][2] : -1;
        mat.vertexColors = look === "heat";
        mat.map = t >= 0 ? textures[t] : null;
        mat.color.set(look === "heat" || t >= 0 ? 0xffffff : l.spec.color);
        mat.needsUpdate = true;
      });
    }

    function setHeatmap(index) {
      active = index >= 0 ? scalars[index] : null;
      Object.values(layers).forEach(function (l) {
        l.scalar = null;
        showAs(l, active ? "plain" : "own");
      });
      $("fw-colorbar").hidden = active === null;
      if (active) {
        const l = layers[active.mesh];
        l.scalar = active;
        showAs(l, "heat");
        paint(l, active);
        if (!l.obj.visible) {
          l.obj.visible = true;
          const box = document.querySelector('[data-fw-layer="' + CSS.escape(active.mesh) + '"]');
          if (box) box.checked = true;
        }
        loInput.value = fmt(active.lo);
        hiInput.value = fmt(active.hi);
        updateBar();
      }
      requestRender();
    }

    function updateBar() {
      if (!active) return;
      const units = active.units ? " " + active.units : "";
      $("fw-colorbar-title").textContent = active.name + (units ? " (" + active.units + ")" : "");
      const ticks = $("fw-colorbar-ticks");
      ticks.textContent = "";
      for (let k = 0; k <= 4; k++) {
        const span = document.createElement("span");
        span.textContent = fmtDistance(active.lo + (k / 4) * (active.hi - active.lo),
                                       active.decimals);
        ticks.appendChild(span);
      }
      const d = function (v) { return fmtDistance(v, active.decimals) + units; };
      $("fw-colorbar-stats").textContent = "mean " + d(active.stats.mean) +
        " · p95 " + d(active.stats.p95) + " · max " + d(active.stats.max) +
        " over " + active.stats.count + " vertices" +
        (active.stats.missing ? " · " + active.stats.missing + " without value (grey)" : "");
    }

    function onRange() {
      if (!active) return;
      const lo = parseFloat(loInput.value), hi = parseFloat(hiInput.value);
      if (!isFinite(lo) || !isFinite(hi) || hi <= lo) return;
      active.lo = lo;
      active.hi = hi;
      paint(layers[active.mesh], active);
      updateBar();
      requestRender();
    }
    if (select) {
      select.addEventListener("change", function () { setHeatmap(parseInt(select.value, 10)); });
      loInput.addEventListener("change", onRange);
      hiInput.addEventListener("change", onRange);
    }

    // ---- blendshapes --------------------------------------------------------
    const bs = data.blendshapes;
    if (bs) {
      const layer = layers[bs.mesh];
      const shapes = bs.shapes.map(function (s) {
        return { name: s.name, idx: decode(s.indices, Uint32Array),
                 d: decode(s.deltas, Float32Array), w: 0 };
      });
      const ids = layer.ids;
      const offset = new Float32Array(3 * layer.n);  // per original vertex
      const apply = function () {
        const p = layer.geom.getAttribute("position");
        const nrm = layer.geom.getAttribute("normal");
        p.array.set(layer.base);
        offset.fill(0);
        let moved = false;
        shapes.forEach(function (s) {
          if (s.w === 0) return;
          moved = true;
          for (let j = 0; j < s.idx.length; j++) {
            const o = 3 * s.idx[j];
            offset[o] += s.w * s.d[3 * j];
            offset[o + 1] += s.w * s.d[3 * j + 1];
            offset[o + 2] += s.w * s.d[3 * j + 2];
          }
        });
        for (let j = 0; j < p.count; j++) {
          const o = 3 * (ids ? ids[j] : j);
          p.array[3 * j] += offset[o];
          p.array[3 * j + 1] += offset[o + 1];
          p.array[3 * j + 2] += offset[o + 2];
        }
        p.needsUpdate = true;
        if (!moved) nrm.array.set(layer.normals);  // the neutral's own normals
        else if (ids) smoothNormals(p.array, layer.geom.getIndex().array, ids, layer.n,
                                    nrm.array);
        else layer.geom.computeVertexNormals();
        nrm.needsUpdate = true;
        layer.geom.computeBoundingSphere();
        requestRender();
      };
      document.querySelectorAll("[data-fw-shape]").forEach(function (r) {
        const s = shapes[parseInt(r.dataset.fwShape, 10)];
        const out = r.parentElement.querySelector("output");
        r.addEventListener("input", function () {
          s.w = parseFloat(r.value);
          out.textContent = s.w.toFixed(2);
          if (!layer.obj.visible) {
            layer.obj.visible = true;
            const box = document.querySelector('[data-fw-layer="' + CSS.escape(bs.mesh) + '"]');
            if (box) box.checked = true;
          }
          apply();
        });
      });
      const reset = $("fw-shapes-reset");
      if (reset) reset.addEventListener("click", function () {
        document.querySelectorAll("[data-fw-shape]").forEach(function (r) {
          r.value = "0";
          r.parentElement.querySelector("output").textContent = "0.00";
        });
        shapes.forEach(function (s) { s.w = 0; });
        apply();
      });
    }

    // ---- value under the pointer -------------------------------------------
    const ray = new T.Raycaster();
    const ndc = new T.Vector2();
    const probe = $("fw-probe");
    renderer.domElement.addEventListener("pointermove", function (ev) {
      if (!active || ev.buttons) { probe.hidden = true; return; }
      const rect = renderer.domElement.getBoundingClientRect();
      ndc.set(((ev.clientX - rect.left) / rect.width) * 2 - 1,
              -((ev.clientY - rect.top) / rect.height) * 2 + 1);
      ray.setFromCamera(ndc, camera);
      const l = layers[active.mesh];
      const hit = ray.intersectObject(l.obj, false)[0];
      if (!hit || !hit.face) { probe.hidden = true; return; }
      const f = hit.face;
      const p = l.geom.getAttribute("position");
      let best = f.a, bd = Infinity;
      [f.a, f.b, f.c].forEach(function (i) {
        const dx = p.getX(i) - hit.point.x, dy = p.getY(i) - hit.point.y,
              dz = p.getZ(i) - hit.point.z, d = dx * dx + dy * dy + dz * dz;
        if (d < bd) { bd = d; best = i; }
      });
      if (l.ids) best = l.ids[best];  // the original vertex
      probe.textContent = "vertex " + best + ": " +
        fmtDistance(active.data[best], active.decimals) +
        (active.units ? " " + active.units : "");
      probe.style.left = (ev.clientX - rect.left + 14) + "px";
      probe.style.top = (ev.clientY - rect.top + 14) + "px";
      probe.hidden = false;
    });
    renderer.domElement.addEventListener("pointerleave", function () { probe.hidden = true; });

    // ---- rendering ----------------------------------------------------------
    let pending = false;
    function render() {
      pending = false;
      renderer.render(scene, camera);
      placeLabels();
      state.frames += 1;
    }
    function requestRender() {
      if (!pending) { pending = true; requestAnimationFrame(render); }
    }
    state.requestRender = requestRender;  // for tests that change a material
    function resize() {
      const w = Math.max(host.clientWidth, 1), h = Math.max(host.clientHeight, 1);
      renderer.setSize(w, h, true);
      camera.aspect = w / h;
      camera.updateProjectionMatrix();
      render();
    }
    new ResizeObserver(resize).observe(host);

    setHeatmap(select ? parseInt(select.value, 10) : -1);
    lookFrom(views[data.view.initial] ? views[data.view.initial]() : front.clone());
    resize();
    // ready once every texture is on the GPU and drawn
    Promise.all(loads).then(function () {
      state.textures = textures.length;
      render();
      state.ready = true;
    }, function (e) { fail("a texture of this report did not load: " + e); });
  }

  try {
    main();
  } catch (e) {
    state.error = String(e && e.stack ? e.stack : e);
    throw e;
  }
})();
