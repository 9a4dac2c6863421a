// facette relighting viewer, the relighting model's part: inserted into viewer.js's scope
// (its `bytes` helper) by facette/pipeline/_viewer.py.
  // facette's relighting model (pipeline/_viewer_model.py; reference: recon/_relight_model.py,
  // RelightModel.display): phys = rho max(n.l,0) V + spec max(n.h,0)^k [n.l>0] V + amb max(l_z,0),
  // V the cast shadow marched over the heights; shown = srgb(phys) + sum_j e_j(l) plane_j, in [0, 1].
  const RELIGHT_SV_FS = `#version 300 es
precision highp float;
precision highp sampler2DArray;
uniform sampler2D uNormal, uKd, uRho, uSpecMap, uAmb, uHeight;
uniform sampler2DArray uPlanes;
uniform vec3 uLight, uMapScale;
uniform float uExposure, uBackground, uShininess, uSoft;
uniform int uRows, uStep, uHasHeight, uNPlanes;
uniform float uE[16], uPBias[16], uPScale[16];
out vec4 outColor;
const float NO_HEIGHT = -50000.0;
vec3 srgb(vec3 x) {
  return mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), x));
}
vec3 unpackNormal(vec2 nxy) {
  return normalize(vec3(nxy, sqrt(max(0.0, 1.0 - dot(nxy, nxy)))));
}
float shadow(ivec2 p, vec3 l) {            // recon._relight_model.cast_shadow
  if (uHasHeight == 0) return 1.0;
  float horiz = length(l.xy);
  if (horiz < 0.08715574) return 1.0;      // within 5 deg of the axis: no shadow
  float h0 = texelFetch(uHeight, p, 0).r;
  if (h0 < NO_HEIGHT) return 1.0;
  float rise = l.z / horiz;
  vec2 d = vec2(l.x, -l.y) / horiz;         // columns right, rows down
  ivec2 size = textureSize(uHeight, 0);
  int steps = min(64, max(size.x, size.y));
  float over = -1e30;
  for (int t = 1; t <= 64; t++) {
    if (t > steps) break;
    ivec2 q = ivec2(roundEven(vec2(p) + float(t) * d));
    if (q.x < 0 || q.y < 0 || q.x >= size.x || q.y >= size.y) continue;
    float h = texelFetch(uHeight, q, 0).r;
    if (h < NO_HEIGHT) continue;
    over = max(over, h - h0 - float(t) * rise);
  }
  return clamp(1.0 - over / uSoft, 0.0, 1.0);
}
vec3 decodeMap(sampler2D m, ivec2 p, float scale) {
  vec3 v = texelFetch(m, p, 0).rgb;
  return scale * v * v;
}
void main() {
  ivec2 p = ivec2(int(gl_FragCoord.x) * uStep, (uRows - 1 - int(gl_FragCoord.y)) * uStep);
  vec4 kd = texelFetch(uKd, p, 0);
  if (kd.a < 0.5) { outColor = vec4(vec3(uBackground), 1.0); return; }
  vec3 n = unpackNormal(texelFetch(uNormal, p, 0).rg);
  vec3 l = normalize(uLight);
  float ndl = dot(n, l);
  float ndh = clamp(dot(n, normalize(l + vec3(0.0, 0.0, 1.0))), 0.0, 1.0);
  float vis = ndl > 0.0 ? shadow(p, l) : 0.0;
  vec3 phys = decodeMap(uRho, p, uMapScale.x) * (max(ndl, 0.0) * vis)
            + decodeMap(uSpecMap, p, uMapScale.y) * (pow(ndh, uShininess) * vis)
            + decodeMap(uAmb, p, uMapScale.z) * max(l.z, 0.0);
  vec3 shown = srgb(clamp(phys * uExposure, 0.0, 1.0));
  for (int j = 0; j < 16; j++) {
    if (j >= uNPlanes) break;
    shown += uE[j] * (uPBias[j] + uPScale[j] * texelFetch(uPlanes, ivec3(p, j), 0).rgb);
  }
  outColor = vec4(clamp(shown, 0.0, 1.0), 1.0);
}`;

  function svTextures(gl, d, p) {
    const sv = d.sv, u = (name) => gl.getUniformLocation(p, name);
    const tex2d = (unit, internal, format, type, w, h, data) => {
      const t = gl.createTexture();
      gl.activeTexture(gl.TEXTURE0 + unit);
      gl.bindTexture(gl.TEXTURE_2D, t);
      gl.texImage2D(gl.TEXTURE_2D, 0, internal, w, h, 0, format, type, data);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    };
    gl.useProgram(p);
    ["uRho", "uSpecMap", "uAmb"].forEach((name, k) => {
      tex2d(3 + k, gl.RGBA8, gl.RGBA, gl.UNSIGNED_BYTE, d.width, d.height, bytes([sv.rho, sv.spec, sv.amb][k]));
      gl.uniform1i(u(name), 3 + k);
    });
    if (sv.heights) {
      const hb = bytes(sv.heights);
      tex2d(6, gl.R16F, gl.RED, gl.HALF_FLOAT, d.width, d.height, new Uint16Array(hb.buffer, hb.byteOffset, hb.byteLength / 2));
    } else {
      tex2d(6, gl.R16F, gl.RED, gl.HALF_FLOAT, 1, 1, new Uint16Array(1));
    }
    gl.uniform1i(u("uHeight"), 6);
    const t = gl.createTexture();
    gl.activeTexture(gl.TEXTURE7);
    gl.bindTexture(gl.TEXTURE_2D_ARRAY, t);
    const k = Math.max(sv.n_planes, 1);
    gl.texImage3D(gl.TEXTURE_2D_ARRAY, 0, gl.RGBA8, sv.n_planes ? d.width : 1, sv.n_planes ? d.height : 1, k, 0,
                  gl.RGBA, gl.UNSIGNED_BYTE, sv.n_planes ? bytes(sv.planes) : new Uint8Array(4));
    gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.uniform1i(u("uPlanes"), 7);
    gl.uniform1i(u("uNormal"), 0);
    gl.uniform1i(u("uKd"), 1);
    gl.uniform3fv(u("uMapScale"), sv.map_scales);
    gl.uniform1f(u("uShininess"), sv.shininess);
    gl.uniform1f(u("uSoft"), sv.softness);
    gl.uniform1i(u("uHasHeight"), sv.heights ? 1 : 0);
    gl.uniform1i(u("uNPlanes"), Math.min(sv.n_planes, 16));
    const pad = (a) => { const o = new Float32Array(16); if (a) o.set(a.slice(0, 16)); return o; };
    gl.uniform1fv(u("uPBias"), pad(sv.plane_bias));
    gl.uniform1fv(u("uPScale"), pad(sv.plane_scale));
  }

  function lightFunctions(sv, l) {       // e_j(l): the Gaussian RBF over the captured lights' (x, y), + the trend
    const e = new Float32Array(16), K = sv.n_planes;
    let nearest = Infinity;
    for (let i = 0; i < sv.n_lights; i++) {
      const dx = sv.centres[2 * i] - l[0], dy = sv.centres[2 * i + 1] - l[1];
      const dist = Math.hypot(dx, dy), r = sv.epsilon * dist, g = Math.exp(-r * r);
      nearest = Math.min(nearest, dist);
      for (let j = 0; j < Math.min(K, 16); j++) e[j] += g * sv.weights[i * K + j];
    }
    if (sv.trend) {                      // the HSH order-2 part (recon._rti.hsh_basis(l, 2)) @ trend (4, K)
      const c = Math.min(Math.max(l[2] / Math.hypot(l[0], l[1], l[2]), 0), 1), rho = Math.hypot(l[0], l[1]);
      const s = 2 * Math.sqrt(Math.max(c - c * c, 0)), k1 = Math.sqrt(2) * Math.sqrt(3 / (4 * Math.PI));
      const h = [1 / Math.sqrt(2 * Math.PI), k1 * s * (rho > 0 ? l[0] / rho : 1),
                 Math.sqrt(3 / (2 * Math.PI)) * (2 * c - 1), k1 * s * (rho > 0 ? l[1] / rho : 0)];
      for (let i = 0; i < 4; i++) for (let j = 0; j < Math.min(K, 16); j++) e[j] += h[i] * sv.trend[i * K + j];
    }
    // beyond twice the lights' spacing from the nearest one, or below the lowest, the residual fades out
    const beyond = Math.max(nearest - 2 * sv.spacing, Math.hypot(l[0], l[1]) - sv.reach, 0);
    const f = beyond / sv.spacing, fade = Math.exp(-f * f);
    for (let j = 0; j < 16; j++) e[j] *= fade;
    return e;
  }

