"""The system's headless Chromium driven by its chromedriver (never a downloaded browser):
WebGL2 by SwiftShader, the browser's log kept; poll a page for a condition. The tools that
drive the live view and the tests (``tests/helpers/browser.py``) start it here."""
from __future__ import annotations

import shutil
import time

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")
NO_BROWSER = ("no system Chromium and chromedriver (Debian: apt-get install chromium "
              "chromium-driver; tools/setup.sh --test installs them as root)")


def chromium(*extra: str, width: int = 1400, height: int = 1500):
    """A new headless Chromium (``extra``: more command-line switches), its console kept
    at every level. Raises RuntimeError where the system browser is missing."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service as DriverService

    if not (CHROMIUM and DRIVER):
        raise RuntimeError(NO_BROWSER)
    options = webdriver.ChromeOptions()
    for arg in ("--headless=new", "--no-sandbox", "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader", f"--window-size={width},{height}",
                "--disable-dev-shm-usage", *extra):
        options.add_argument(arg)
    options.binary_location = CHROMIUM
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=DriverService(DRIVER), options=options)


def browser(width: int = 1400, height: int = 1500):
    """A headless Chromium of that window size (its console kept, every level)."""
    return chromium(width=width, height=height)


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
