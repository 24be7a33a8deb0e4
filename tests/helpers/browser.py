"""The headless Chromium of ``tools/headless_browser.py`` for tests of pages: a test skips,
saying why, where selenium or the system browser is missing; an element's pixels; the
console's errors."""
from __future__ import annotations

import io

import numpy as np
import pytest
import headless_browser
from headless_browser import CHROMIUM, DRIVER, NO_BROWSER, until  # noqa: F401 (for tests)

SKIP_WHY = NO_BROWSER


def chromium(*extra: str, width: int = 1400, height: int = 1500):
    """A new headless Chromium (see :func:`headless_browser.chromium`); skips the test
    where selenium or the system browser is missing."""
    pytest.importorskip("selenium.webdriver", reason="selenium is not installed")
    if not (CHROMIUM and DRIVER):
        pytest.skip(NO_BROWSER)
    return headless_browser.chromium(*extra, width=width, height=height)


def browser(width: int = 1400, height: int = 1500):
    """A headless Chromium of that window size (its console kept, every level)."""
    return chromium(width=width, height=height)


def pixels(element) -> np.ndarray:
    """An element's pixels as shown (RGB in 0..1), from its screenshot."""
    import matplotlib.image as mpimg

    return mpimg.imread(io.BytesIO(element.screenshot_as_png), format="png")[..., :3]


def severe(driver) -> list[dict]:
    """The console's errors since the last call."""
    return [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
