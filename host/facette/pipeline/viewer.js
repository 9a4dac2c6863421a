// facette relighting viewer (WebGL 2, no library): the fitted BRDF evaluated per pixel.
// Data: the JSON in <script id="facette-viewer-data">, written by facette/pipeline/_viewer.py.
// The shading follows facette/pipeline/_relight.py (the Python reference): radiance =
// F D G / (4 cos θo) (LI specular lobe, eq 3.10, times cos θs) + g(K_d) J(θs, θo, Δφ),
// with J = I cos θs read from a 3D texture and g(K_d) = a K_d / (1 − b K_d) (eq 3.15).
"use strict";
(function () {
  const api = { ready: false, error: null };
  window.facetteViewer = api;

  function fail(msg) {
    api.error = String(msg);
    const el = document.getElementById("facette-viewer-status");
    if (el) el.textContent = "The viewer could not start: " + msg;
    console.error("facette viewer: " + msg);
  }

  function bytes(b64) {
    const bin = atob(b64);
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }

  const SHADE = `
precision highp float;
precision highp sampler3D;
uniform sampler3D uTable;
uniform float uNTheta, uNPhi, uSigma, uNi, uGaussNorm, uKdA, uKdB;
uniform int uDist, uMasking, uSpec;
const float PI = 3.14159265358979;

float fresnel(float c, float n) {            // eq 3.7-3.9, as facette.brdf.fresnel_dielectric
  c = min(abs(c), 1.0);
  float eta = (n - 1.0) * (n + 1.0);
  if (eta <= 0.0) return 0.0;
  float g = sqrt(eta + c * c), gpc = g + c, gmc = eta / gpc, a = gmc / gpc;
  float r = (c * gpc - 1.0) / (c * gmc + 1.0);
  return 0.5 * a * a * (1.0 + r * r);
}
float g1(float cu, float sigma) {            // Smith G1 = 1 / (1 + Λ), eq 3.19-3.21
  if (cu <= 0.0) return 0.0;
  float q = sigma * sqrt(max(1.0 - cu * cu, 0.0)) / cu;
  if (uDist == 1) return 2.0 / (1.0 + sqrt(1.0 + q * q));
  if (q <= 0.0) return 1.0;
  float a = 1.0 / q;
  if (a > 9.0) return 1.0;
  // erfc(a) = y exp(-a^2), Abramowitz & Stegun 7.1.26 (|error| < 1.5e-7)
  float t = 1.0 / (1.0 + 0.3275911 * a);
  float y = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
  float lam = 0.5 * exp(-a * a) * (1.0 / (a * 1.7724538509) - y);
  return 1.0 / (1.0 + lam);
}
float distD(float c, float s2) {             // table 3.1; c = h.n, s2 = |h x n|^2
  if (c <= 0.0) return 0.0;
  float c2 = c * c, t2 = s2 / c2, a2 = uSigma * uSigma;
  if (uDist == 0) return exp(-t2 / a2) / (PI * a2 * c2 * c2);
  if (uDist == 1) { float k = 1.0 + t2 / a2; return 1.0 / (PI * a2 * c2 * c2 * k * k); }
  float th = atan(sqrt(s2), c);
  return uGaussNorm * exp(-th * th / (2.0 * a2)) / c;
}
vec3 shade(vec3 n, vec3 l, vec3 v, vec3 kd) {
  float cs = dot(n, l), co = dot(n, v);
  if (cs <= 0.0 || co <= 0.0) return vec3(0.0);
  vec3 rad = vec3(0.0);
  if (uSpec == 1) {
    vec3 h = normalize(l + v);
    float ch = dot(n, h);
    vec3 x = cross(h, n);
    float d = distD(ch, dot(x, x));
    float g;
    if (uMasking == 0) {
      float sg = uDist == 2 ? uSigma * 1.41421356 : uSigma;
      g = g1(cs, sg) * g1(co, sg);
    } else {
      g = clamp(min(2.0 * ch * cs / dot(l, h), 2.0 * ch * co / dot(v, h)), 0.0, 1.0);
    }
    rad += vec3(fresnel(dot(l, h), uNi) * d * g / (4.0 * co));
  }
  vec3 lt = l - cs * n, vt = v - co * n;
  float ll = length(lt), lv = length(vt);
  float cphi = (ll > 1e-6 && lv > 1e-6) ? clamp(dot(lt, vt) / (ll * lv), -1.0, 1.0) : 1.0;
  float scale = (uNTheta - 1.0) / (0.5 * PI);
  vec3 uvw = vec3((acos(clamp(cs, 0.0, 1.0)) * scale + 0.5) / uNTheta,
                  (acos(clamp(co, 0.0, 1.0)) * scale + 0.5) / uNTheta,
                  (acos(cphi) * (uNPhi - 1.0) / PI + 0.5) / uNPhi);
  float j = texture(uTable, uvw).r;
  return rad + j * uKdA * kd / (1.0 - uKdB * kd);
}
vec3 srgb(vec3 x) {
  return mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), x));
}
vec3 unpackNormal(vec2 nxy) {
  return normalize(vec3(nxy, sqrt(max(0.0, 1.0 - dot(nxy, nxy)))));
}
`;

  const QUAD_VS = `#version 300 es
in vec2 aPos;
void main() { gl_Position = vec4(aPos, 0.0, 1.0); }`;

  const RELIGHT_FS = `#version 300 es
${SHADE}
uniform sampler2D uNormal, uKd;
uniform vec3 uLight;
uniform float uExposure, uBackground;
uniform int uRows, uStep;
out vec4 outColor;
void main() {
  // uStep > 1: a preview while the light is dragged, every uStep-th pixel of the scan
  ivec2 p = ivec2(int(gl_FragCoord.x) * uStep, (uRows - 1 - int(gl_FragCoord.y)) * uStep);
  vec4 kd = texelFetch(uKd, p, 0);
  if (kd.a < 0.5) { outColor = vec4(vec3(uBackground), 1.0); return; }
  vec3 n = unpackNormal(texelFetch(uNormal, p, 0).rg);
  vec3 rad = shade(n, normalize(uLight), vec3(0.0, 0.0, 1.0), kd.rgb);
  outColor = vec4(srgb(clamp(rad * uExposure, 0.0, 1.0)), 1.0);
}`;

  const MESH_VS = `#version 300 es
in vec3 aPos;
in vec2 aUV;
uniform mat4 uMVP;
out vec3 vPos;
out vec2 vUV;
void main() { vPos = aPos; vUV = aUV; gl_Position = uMVP * vec4(aPos, 1.0); }`;

  const MESH_FS = `#version 300 es
${SHADE}
uniform sampler2D uNormal, uKd;
uniform vec3 uLight, uEye;
uniform float uExposure;
in vec3 vPos;
in vec2 vUV;
out vec4 outColor;
void main() {
  vec4 kd = texture(uKd, vUV);
  if (kd.a < 0.5) discard;
  vec3 n = unpackNormal(texture(uNormal, vUV).rg);
  vec3 rad = shade(n, normalize(uLight), normalize(uEye - vPos), kd.rgb / kd.a);
  outColor = vec4(srgb(clamp(rad * uExposure, 0.0, 1.0)), 1.0);
}`;


  // @relight-model: viewer_model.js is inserted here by pipeline/_viewer.py (same scope)

  function program(gl, vs, fs) {
    const p = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const s = gl.createShader(type);
      gl.shaderSource(s, src);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(s));
      gl.attachShader(p, s);
    }
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error("link: " + gl.getProgramInfoLog(p));
    return p;
  }

  function textures(gl, d) {
    // every texture of one context: normals RG16F, K_d + mask RGBA8, the J table R16F 3D
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    const tex = {};
    const setup = (target, filter) => {
      gl.texParameteri(target, gl.TEXTURE_MIN_FILTER, filter);
      gl.texParameteri(target, gl.TEXTURE_MAG_FILTER, filter);
      gl.texParameteri(target, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
      gl.texParameteri(target, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
      gl.texParameteri(target, gl.TEXTURE_WRAP_R, gl.CLAMP_TO_EDGE);
    };
    tex.normal = gl.createTexture();
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, tex.normal);
    const nb = d.normals;
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RG16F, d.width, d.height, 0, gl.RG, gl.HALF_FLOAT,
                  new Uint16Array(nb.buffer, nb.byteOffset, nb.byteLength / 2));
    setup(gl.TEXTURE_2D, gl.LINEAR);
    tex.kd = gl.createTexture();
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_2D, tex.kd);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, d.width, d.height, 0, gl.RGBA, gl.UNSIGNED_BYTE, d.kd);
    setup(gl.TEXTURE_2D, gl.LINEAR);
    tex.table = gl.createTexture();
    gl.activeTexture(gl.TEXTURE2);
    gl.bindTexture(gl.TEXTURE_3D, tex.table);
    const t = d.table;
    gl.texImage3D(gl.TEXTURE_3D, 0, gl.R16F, t.n_theta, t.n_theta, t.n_phi, 0, gl.RED, gl.HALF_FLOAT,
                  new Uint16Array(t.data.buffer, t.data.byteOffset, t.data.byteLength / 2));
    setup(gl.TEXTURE_3D, gl.LINEAR);
    return tex;
  }

  function setModel(gl, p, d) {
    const m = d.model, u = (name) => gl.getUniformLocation(p, name);
    gl.useProgram(p);
    gl.uniform1i(u("uNormal"), 0);
    gl.uniform1i(u("uKd"), 1);
    gl.uniform1i(u("uTable"), 2);
    gl.uniform1f(u("uNTheta"), d.table.n_theta);
    gl.uniform1f(u("uNPhi"), d.table.n_phi);
    gl.uniform1f(u("uSigma"), m.sigma);
    gl.uniform1f(u("uNi"), m.n_i);
    gl.uniform1f(u("uGaussNorm"), m.gauss_norm);
    gl.uniform1f(u("uKdA"), m.kd_a);
    gl.uniform1f(u("uKdB"), m.kd_b);
    gl.uniform1i(u("uDist"), m.distribution);
    gl.uniform1i(u("uMasking"), m.masking);
    gl.uniform1i(u("uSpec"), m.specular ? 1 : 0);
  }

  // 4x4 column-major matrices for the mesh view
  function perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
  }
  function lookAt(eye, at, up) {
    const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    const norm = (a) => { const l = Math.hypot(a[0], a[1], a[2]); return [a[0] / l, a[1] / l, a[2] / l]; };
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x);
    return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
            -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
  }
  function mul(a, b) {
    const o = new Array(16).fill(0);
    for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) for (let k = 0; k < 4; k++) o[c * 4 + r] += a[k * 4 + r] * b[c * 4 + k];
    return o;
  }

  function start() {
    const node = document.getElementById("facette-viewer-data");
    if (!node) return;
    const tStart = performance.now();
    const d = JSON.parse(node.textContent);
    d.normals = bytes(d.normals);
    d.kd = bytes(d.kd);
    d.table.data = bytes(d.table.data);
    const state = { az: d.light[0], el: d.light[1], ev: 0, yaw: 0.5, pitch: 0.9, dist: 1.0 };
    const canvas = document.getElementById("facette-relight");
    canvas.width = d.width;
    canvas.height = d.height;
    const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: false });
    if (!gl) { fail("this browser has no WebGL 2"); return; }
    const relight = program(gl, QUAD_VS, d.sv ? RELIGHT_SV_FS : RELIGHT_FS);
    textures(gl, d);
    if (d.sv) svTextures(gl, d, relight);
    else setModel(gl, relight, d);
    const quad = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, quad);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 1, -1, -1, 1, 1, 1]), gl.STATIC_DRAW);
    const quadVao = gl.createVertexArray();
    gl.bindVertexArray(quadVao);
    const aPos = gl.getAttribLocation(relight, "aPos");
    gl.enableVertexAttribArray(aPos);
    gl.vertexAttribPointer(aPos, 2, gl.FLOAT, false, 0, 0);
    const U = (name) => gl.getUniformLocation(relight, name);

    function lightVector() {
      const az = state.az * Math.PI / 180, el = state.el * Math.PI / 180;
      return [Math.cos(el) * Math.cos(az), Math.cos(el) * Math.sin(az), Math.sin(el)];
    }
    function exposure() { return d.exposure * Math.pow(2, state.ev); }

    // while dragging a large picture, draw at most ~1 MP (CPU WebGL: ~280 ms a frame at 3 MP)
    const previewStep = Math.max(1, Math.ceil(Math.sqrt(d.width * d.height / 1.0e6)));
    let step = 1;
    function setStep(k) {
      if (k === step) return;
      step = k;
      canvas.width = Math.ceil(d.width / k);
      canvas.height = Math.ceil(d.height / k);
    }
    function draw() {
      gl.viewport(0, 0, canvas.width, canvas.height);
      gl.useProgram(relight);
      gl.bindVertexArray(quadVao);
      gl.uniform3fv(U("uLight"), lightVector());
      if (d.sv) gl.uniform1fv(U("uE"), lightFunctions(d.sv, lightVector()));
      gl.uniform1f(U("uExposure"), exposure());
      gl.uniform1f(U("uBackground"), d.background);
      gl.uniform1i(U("uRows"), canvas.height);
      gl.uniform1i(U("uStep"), step);
      gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
    }

    const mesh = d.mesh ? meshView(d, state, lightVector, exposure) : null;
    const readout = document.getElementById("facette-light-readout");
    const elSlider = document.getElementById("facette-elevation");
    const evSlider = document.getElementById("facette-exposure");
    function update() {
      draw();
      if (mesh) mesh.draw();
      readout.textContent = `light: azimuth ${Math.round(state.az)}°, elevation ${Math.round(state.el)}°; ` +
        `exposure ${state.ev >= 0 ? "+" : ""}${state.ev.toFixed(1)} EV`;
      elSlider.value = state.el;
    }
    function lightFromPointer(ev) {
      const r = canvas.getBoundingClientRect();
      const x = (ev.clientX - r.left - r.width / 2) / (r.width / 2);
      const y = -(ev.clientY - r.top - r.height / 2) / (r.height / 2);
      const rho = Math.min(Math.hypot(x, y), 1);
      state.az = ((Math.atan2(y, x) * 180 / Math.PI) + 360) % 360;
      state.el = Math.max(Math.acos(rho) * 180 / Math.PI, 2);
      update();
    }
    canvas.addEventListener("pointerdown", (ev) => {
      canvas.setPointerCapture(ev.pointerId);
      setStep(previewStep);
      lightFromPointer(ev);
    });
    canvas.addEventListener("pointermove", (ev) => { if (ev.buttons & 1) lightFromPointer(ev); });
    const release = () => { if (step !== 1) { setStep(1); update(); } };
    canvas.addEventListener("pointerup", release);
    canvas.addEventListener("pointercancel", release);
    elSlider.addEventListener("input", () => { state.el = Number(elSlider.value); update(); });
    evSlider.addEventListener("input", () => { state.ev = Number(evSlider.value); update(); });
    update();

    // what the browser test and the benchmark drive
    api.setLight = (az, el) => { state.az = az; state.el = el; update(); };
    api.setExposureEV = (ev) => { state.ev = ev; update(); };
    api.pixels = () => {            // RGBA rows top to bottom, base64, full size
      setStep(1);
      draw();
      const px = new Uint8Array(d.width * d.height * 4);
      gl.readPixels(0, 0, d.width, d.height, gl.RGBA, gl.UNSIGNED_BYTE, px);
      const rows = new Uint8Array(px.length), stride = d.width * 4;
      for (let y = 0; y < d.height; y++) rows.set(px.subarray((d.height - 1 - y) * stride, (d.height - y) * stride), y * stride);
      let s = "";
      for (let i = 0; i < rows.length; i += 32768) s += String.fromCharCode.apply(null, rows.subarray(i, i + 32768));
      return btoa(s);
    };
    api.frameTimes = (n, preview) => new Promise((resolve) => {
      setStep(preview ? previewStep : 1);
      // n frames, each drawn with a new light and waited for, one per animation frame.
      // Chromium's gl.finish() does not wait for the GPU process: reading one pixel back does.
      const times = [], stamps = [], one = new Uint8Array(4);
      let i = 0;
      function frame(ts) {
        stamps.push(ts);
        state.az = (state.az + 7) % 360;
        const t0 = performance.now();
        draw();
        gl.finish();
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, one);
        times.push(performance.now() - t0);
        if (++i < n) requestAnimationFrame(frame);
        else { const size = [canvas.width, canvas.height]; setStep(1); draw(); resolve({ draw_ms: times, raf_ms: stamps, size }); }
      }
      requestAnimationFrame(frame);
    });
    api.size = [d.width, d.height];
    api.startMs = performance.now() - tStart;      // decode, upload, first frame
    api.ready = true;
  }

  function meshView(d, state, lightVector, exposure) {
    const canvas = document.getElementById("facette-mesh");
    const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true });
    if (!gl) throw new Error("no WebGL 2 for the mesh view");
    const p = program(gl, MESH_VS, MESH_FS);
    textures(gl, d);
    setModel(gl, p, d);
    const m = d.mesh, cols = m.cols, rows = m.rows;
    const hb = bytes(m.heights), hgt = new Float32Array(hb.buffer, hb.byteOffset, hb.byteLength / 4);
    const pos = new Float32Array(cols * rows * 3), uv = new Float32Array(cols * rows * 2);
    let zmin = Infinity, zmax = -Infinity;
    for (let r = 0; r < rows; r++) for (let c = 0; c < cols; c++) {
      const k = r * cols + c, z = hgt[k];
      pos[3 * k] = (c - (cols - 1) / 2) * m.step_mm;
      pos[3 * k + 1] = ((rows - 1) / 2 - r) * m.step_mm;
      pos[3 * k + 2] = Number.isFinite(z) ? z : 0;
      if (Number.isFinite(z)) { zmin = Math.min(zmin, z); zmax = Math.max(zmax, z); }
      uv[2 * k] = (c * m.step_px + 0.5) / d.width;
      uv[2 * k + 1] = (r * m.step_px + 0.5) / d.height;
    }
    // triangles of the object only: every corner inside the mask (heights are NaN outside) and
    // no edge steeper than max_slope, so that the surface stops at the object's edge instead of
    // hanging a curtain from its silhouette down to the background
    const rise = (m.max_slope || Infinity) * m.step_mm;
    const ok = (i, j, k) => {
      const a = hgt[i], b = hgt[j], c = hgt[k];
      return Number.isFinite(a) && Number.isFinite(b) && Number.isFinite(c) &&
        Math.abs(a - b) <= rise * (i % cols === j % cols || Math.floor(i / cols) === Math.floor(j / cols) ? 1 : Math.SQRT2) &&
        Math.abs(b - c) <= rise * (j % cols === k % cols || Math.floor(j / cols) === Math.floor(k / cols) ? 1 : Math.SQRT2) &&
        Math.abs(c - a) <= rise * (k % cols === i % cols || Math.floor(k / cols) === Math.floor(i / cols) ? 1 : Math.SQRT2);
    };
    const all = new Uint32Array((cols - 1) * (rows - 1) * 6);
    let q = 0;
    for (let r = 0; r + 1 < rows; r++) for (let c = 0; c + 1 < cols; c++) {
      const a = r * cols + c;
      if (ok(a, a + cols, a + 1)) { all.set([a, a + cols, a + 1], q); q += 3; }
      if (ok(a + 1, a + cols, a + cols + 1)) { all.set([a + 1, a + cols, a + cols + 1], q); q += 3; }
    }
    const idx = all.subarray(0, q);
    api.meshTriangles = q / 3;
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    for (const [name, data, size] of [["aPos", pos, 3], ["aUV", uv, 2]]) {
      const b = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, b);
      gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
      const loc = gl.getAttribLocation(p, name);
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0);
    }
    const ib = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx, gl.STATIC_DRAW);
    const extent = Math.max(cols, rows) * m.step_mm;
    const centre = [0, 0, Number.isFinite(zmin) ? (zmin + zmax) / 2 : 0];
    const U = (name) => gl.getUniformLocation(p, name);
    function draw() {
      gl.viewport(0, 0, canvas.width, canvas.height);
      gl.clearColor(d.background, d.background, d.background, 1);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      gl.enable(gl.DEPTH_TEST);
      gl.useProgram(p);
      gl.bindVertexArray(vao);
      const r = 1.6 * extent * state.dist;
      const eye = [centre[0] + r * Math.sin(state.pitch) * Math.sin(state.yaw),
                   centre[1] - r * Math.sin(state.pitch) * Math.cos(state.yaw),
                   centre[2] + r * Math.cos(state.pitch)];
      const mvp = mul(perspective(0.7, canvas.width / canvas.height, extent * 0.05, extent * 10),
                      lookAt(eye, centre, [0, 0, 1]));
      gl.uniformMatrix4fv(U("uMVP"), false, new Float32Array(mvp));
      gl.uniform3fv(U("uEye"), eye);
      gl.uniform3fv(U("uLight"), lightVector());
      if (d.sv) gl.uniform1fv(U("uE"), lightFunctions(d.sv, lightVector()));
      gl.uniform1f(U("uExposure"), exposure());
      gl.drawElements(gl.TRIANGLES, idx.length, gl.UNSIGNED_INT, 0);
    }
    let last = null;
    canvas.addEventListener("pointerdown", (ev) => { canvas.setPointerCapture(ev.pointerId); last = [ev.clientX, ev.clientY]; });
    canvas.addEventListener("pointermove", (ev) => {
      if (!(ev.buttons & 1) || !last) return;
      state.yaw -= (ev.clientX - last[0]) * 0.01;
      state.pitch = Math.min(Math.max(state.pitch - (ev.clientY - last[1]) * 0.01, 0.0), 1.5);
      last = [ev.clientX, ev.clientY];
      draw();
    });
    canvas.addEventListener("wheel", (ev) => {
      ev.preventDefault();
      state.dist = Math.min(Math.max(state.dist * Math.exp(ev.deltaY * 0.001), 0.2), 5);
      draw();
    }, { passive: false });
    return { draw };
  }

  window.addEventListener("DOMContentLoaded", () => {
    try { start(); } catch (e) { fail(e && e.message ? e.message : e); }
  });
})();
