"""Headless Chromium (Debian's `chromium` + `chromium-driver`, driven by Selenium) for the
report viewer's test and benchmark. WebGL runs on SwiftShader (the CPU), which this
Chromium needs to be told to use explicitly when there is no GPU."""
import base64
import shutil
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

try:        # selenium is in the dev extra: without it, chromium() says how to install it
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By
except ImportError:
    webdriver = Service = By = None

__all__ = ["By", "chromium", "wait_for_viewer", "viewer_pixels", "console_errors", "CHROMIUM_FLAGS"]

CHROMIUM_FLAGS = ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                  "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                  "--disable-background-timer-throttling", "--allow-file-access-from-files")


def _find(names, what):
    for n in names:
        p = shutil.which(n)
        if p:
            return p
    raise FileNotFoundError(f"{what} not found (looked for {', '.join(names)}); install the Debian "
                            "packages chromium and chromium-driver (tools/install-debian-deps.sh)")


@contextmanager
def chromium(width=1280, height=1000):
    """A Selenium WebDriver on headless Chromium, its console kept (get_log('browser'))."""
    if webdriver is None:
        raise ImportError("selenium is needed for the browser checks: pip install -e '.[dev]'")
    opts = webdriver.ChromeOptions()
    for flag in CHROMIUM_FLAGS:
        opts.add_argument(flag)
    opts.add_argument(f"--window-size={int(width)},{int(height)}")
    opts.binary_location = _find(("chromium", "chromium-browser"), "Chromium")
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(_find(("chromedriver",), "chromedriver")), options=opts)
    driver.set_script_timeout(300)
    try:
        yield driver
    finally:
        driver.quit()


def wait_for_viewer(driver, path, timeout=120):
    """Open report.html at `path` and wait until its viewer is ready (or says why not)."""
    driver.get(Path(path).resolve().as_uri())
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        state = driver.execute_script(
            "return window.facetteViewer ? [window.facetteViewer.ready, window.facetteViewer.error] : [false, null]")
        if state[0]:
            return
        if state[1]:
            raise RuntimeError(f"the viewer failed: {state[1]}")
        time.sleep(0.1)
    raise TimeoutError(f"the viewer of {path} was not ready after {timeout} s")


def viewer_pixels(driver, azimuth_deg, elevation_deg):
    """(H, W, 3) uint8 of the relit picture after setting the light (read from WebGL)."""
    w, h = driver.execute_script("window.facetteViewer.setLight(arguments[0], arguments[1]);"
                                 "return window.facetteViewer.size", float(azimuth_deg), float(elevation_deg))
    raw = base64.b64decode(driver.execute_script("return window.facetteViewer.pixels()"))
    return np.frombuffer(raw, np.uint8).reshape(h, w, 4)[..., :3]


def console_errors(driver):
    """Console messages of level SEVERE (errors) since the last call."""
    return [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
