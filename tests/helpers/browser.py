"""The system's headless Chromium driven by its chromedriver (never a downloaded browser),
for tests of pages: WebGL2 by SwiftShader, the browser's log kept."""
from __future__ import annotations

import shutil
import time

import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")
NO_BROWSER = ("no system Chromium and chromedriver (Debian: apt-get install chromium "
              "chromium-driver; tools/setup.sh --test installs them as root)")


def chromium(*extra: str):
    """A new headless Chromium (``extra``: more command-line switches); skips the test
    where selenium or the system browser is missing."""
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed")
    from selenium.webdriver.chrome.service import Service as DriverService

    if not (CHROMIUM and DRIVER):
        pytest.skip(NO_BROWSER)
    options = webdriver.ChromeOptions()
    for arg in ("--headless=new", "--no-sandbox", "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader", "--window-size=1400,1500",
                "--disable-dev-shm-usage", *extra):
        options.add_argument(arg)
    options.binary_location = CHROMIUM
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=DriverService(DRIVER), options=options)


def until(driver, script: str, timeout: float = 60.0, step: float = 0.1):
    """Poll a JavaScript expression in the page until it is truthy; return its value."""
    deadline = time.monotonic() + timeout
    while True:
        value = driver.execute_script(f"return ({script});")
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"never true in the page: {script}")
        time.sleep(step)
