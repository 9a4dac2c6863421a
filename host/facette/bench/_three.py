"""A .glb drawn by three.js (its GLTFLoader and physically based materials) in headless Chromium:
`three_view`, what a glTF viewer shows of facette's model.glb, pixel for pixel against the image.

three.js is installed beside the Khronos validator (tools/gltf-validator, `make setup`: npm ci).
A module page cannot load from file:// (its imports and the .glb are fetched), so the page and the
file are served on the loopback address, on a free port, for the duration of the `with`.
"""
import base64
import functools
import io
import shutil
import tempfile
import threading
import time
from contextlib import contextmanager
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np

from facette.bench._browser import chromium

__all__ = ["three_view", "THREE_MODULES"]

THREE_MODULES = Path(__file__).resolve().parents[3] / "tools" / "gltf-validator" / "node_modules"

# An orthographic camera along -z over the image: pixel (row, col) at x = col p, y = -row p (the
# mesh's frame, pipeline._exports), one canvas pixel per image pixel; one directional light; no
# tone mapping, sRGB output (three.js's defaults): radiance = BRDF × intensity × (n·l).
PAGE = """<!doctype html><html><head><meta charset="utf-8"><style>body{margin:0;background:#000}</style>
<script type="importmap">{"imports": {"three": "./node_modules/three/build/three.module.js",
 "three/addons/": "./node_modules/three/examples/jsm/"}}</script></head><body>
<script type="module">
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
const P = new URLSearchParams(location.search);
const W = +P.get('w'), H = +P.get('h'), p = +P.get('p');
const renderer = new THREE.WebGLRenderer({preserveDrawingBuffer: true, antialias: false});
renderer.setPixelRatio(1);
renderer.setSize(W, H);
document.body.appendChild(renderer.domElement);
const scene = new THREE.Scene();
const camera = new THREE.OrthographicCamera(-p / 2, (W - 0.5) * p, p / 2, -(H - 0.5) * p, 0.001, 1e4);
camera.position.set(0, 0, 100);
const light = new THREE.DirectionalLight(0xffffff, 1);
scene.add(light, light.target);
const cx = (W - 1) * p / 2, cy = -(H - 1) * p / 2, reach = Math.hypot(W, H) * p;
light.target.position.set(cx, cy, 0);
window.relight = (x, y, z, intensity) => {
  light.position.set(cx + 2 * reach * x, cy + 2 * reach * y, 2 * reach * z);
  light.intensity = intensity;
  renderer.render(scene, camera);
  return renderer.domElement.toDataURL('image/png');
};
new GLTFLoader().load('model.glb', (gltf) => {
  scene.add(gltf.scene);
  const kinds = [];
  gltf.scene.traverse((o) => { if (o.material) kinds.push(o.material.type); });
  window.loaded = {materials: kinds};
}, undefined, (e) => { window.loaded = {error: String(e)}; });
</script></body></html>
"""


class _Quiet(SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@contextmanager
def three_view(glb, width, height, pitch_mm, timeout=120):
    """Yield (draw, materials): draw(light (3,), intensity) -> (height, width, 3) uint8, what three.js
    shows of `glb` under a directional light from `light` (unit, camera frame) of that intensity
    (π: a white Lambertian face-on to it shows its base colour); materials: three.js's material
    types (no shadow map: three.js's did not darken the sphere's cast shadow on the plane, not
    debugged). RuntimeError when three.js is not installed or cannot load the file."""
    if not (THREE_MODULES / "three" / "build" / "three.module.js").is_file():
        raise RuntimeError(f"three.js is not installed in {THREE_MODULES.parent}: run `make setup` (npm ci there)")
    site = Path(tempfile.mkdtemp(prefix="facette-three-"))
    server = None
    try:
        (site / "index.html").write_text(PAGE)
        (site / "node_modules").symlink_to(THREE_MODULES)
        shutil.copyfile(glb, site / "model.glb")
        server = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(site)))
        threading.Thread(target=server.serve_forever, daemon=True).start()
        with chromium(int(width) + 40, int(height) + 160) as driver:
            driver.get(f"http://127.0.0.1:{server.server_port}/index.html?w={int(width)}&h={int(height)}"
                       f"&p={float(pitch_mm) * 1e-3}")
            t0 = time.monotonic()
            loaded = None
            while loaded is None and time.monotonic() - t0 < timeout:
                loaded = driver.execute_script("return window.loaded || null")
                time.sleep(0.1)
            if not loaded or "error" in loaded:
                raise RuntimeError(f"three.js did not load {glb}: {loaded}")

            def draw(light, intensity):
                from PIL import Image
                url = driver.execute_script("return window.relight(...arguments)",
                                            *map(float, np.asarray(light, float)), float(intensity))
                png = base64.b64decode(url.split(",", 1)[1])
                return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

            yield draw, loaded["materials"]
    finally:
        if server is not None:
            server.shutdown()
            server.server_close()
        shutil.rmtree(site, ignore_errors=True)
