"""Web pages elsewhere cannot drive the service: real pages in the system's headless
Chromium against a real ``lumitrace serve`` on a free loopback port. A page served from
another loopback origin tries every request a browser lets it send without asking (a
text/plain form, ``fetch`` in no-cors mode, a form to the settings) and a rebinding-style
name that resolves to loopback loads the service under a foreign Host: each fails, and
the edits layer, the revision and the settings stay as they were. The service's own page
still edits."""
from __future__ import annotations

import json
import shutil
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import urlsplit

import pytest
from service_process import Service

from helpers.browser import chromium, until
from helpers.paths import REFERENCE

FAST = ("--photons", 20_000, "--resolution", 8, "--threads", 1, "--seed", 3)
SOURCE = "/Luminaire/Source"
FLUX = "lumitrace:luminousFlux"
#: A name the browser resolves to loopback, as a rebinding attacker's name does once its
#: DNS answer flips.
REBOUND = "rebound.test"

#: The attacker's page: every request a page may send to another origin without a CORS
#: preflight, each awaited (its response came back: the service has handled it), then
#: ``window.done``. Forms post into frames of their own; the text/plain form's body is
#: valid JSON (``name=value`` with the ``=`` inside a string).
ATTACK = """<!doctype html><meta charset="utf-8"><title>a page elsewhere</title>
<iframe name="sink1"></iframe><iframe name="sink2"></iframe>
<form id="f1" method="post" enctype="text/plain" action="{svc}deltas" target="sink1">
<input name='{{"deltas": [{{"op": "set", "path": "{source}", "property": "{flux}",
 "value": 21}}, {{"op": "set", "path": "{source}", "property": "my:note", "type": "string",
 "value": "' value='"}}]}}'></form>
<form id="f2" method="post" action="{svc}deltas" target="sink2">
<input name="deltas" value="[]"></form>
<script>
const SVC = "{svc}";
const delta = (v) => JSON.stringify({{deltas: [{{op: "set", path: "{source}",
  property: "{flux}", value: v}}]}});
window.outcome = {{}};
async function attempt(name, f) {{
  try {{ const r = await f(); window.outcome[name] = r.type + " " + r.status; }}
  catch (e) {{ window.outcome[name] = "failed: " + e.message; }}
}}
function submit(id, frame) {{
  return new Promise((done) => {{
    document.querySelector(`iframe[name=${{frame}}]`).addEventListener(
      "load", () => done({{type: "form", status: "answered"}}), {{once: true}});
    document.getElementById(id).submit();
  }});
}}
(async () => {{
  await attempt("no-cors text/plain", () => fetch(SVC + "deltas", {{method: "POST",
    mode: "no-cors", headers: {{"Content-Type": "text/plain"}}, body: delta(11)}}));
  await attempt("no-cors typed json", () => fetch(SVC + "deltas", {{method: "POST",
    mode: "no-cors", headers: {{"Content-Type": "application/json"}}, body: delta(12)}}));
  await attempt("no-cors keepalive", () => fetch(SVC + "deltas", {{method: "POST",
    mode: "no-cors", keepalive: true, body: delta(13)}}));
  await attempt("no-cors settings", () => fetch(SVC + "settings", {{method: "POST",
    mode: "no-cors", body: '{{"paused": true}}'}}));
  await attempt("cors json", () => fetch(SVC + "deltas", {{method: "POST",
    headers: {{"Content-Type": "application/json"}}, body: delta(14)}}));
  await attempt("cors read", () => fetch(SVC + "status"));
  await attempt("text/plain form", () => submit("f1", "sink1"));
  await attempt("urlencoded form", () => submit("f2", "sink2"));
  window.done = true;
}})();
</script>"""


class _Attacker(BaseHTTPRequestHandler):
    page = b""

    def do_GET(self):  # noqa: N802 (the standard library's name)
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(self.page)))
        self.end_headers()
        self.wfile.write(self.page)

    def log_message(self, *args):
        pass


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cross-origin")
    stage = folder / "isotropic.usda"
    shutil.copy(REFERENCE / "isotropic.usda", stage)
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        s.edits = folder / "isotropic.lumitrace-edits.usda"
        yield s


@pytest.fixture(scope="module")
def browser():
    driver = chromium(f"--host-resolver-rules=MAP {REBOUND} 127.0.0.1")
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture(scope="module")
def attacker(served):
    """Another origin on loopback (its own port) serving the attacker's page."""
    handler = type("Attacker", (_Attacker,), {"page": ATTACK.format(
        svc=served.url, source=SOURCE, flux=FLUX).encode()})
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()


def _state(service) -> tuple:
    """What a forged request would change: the edits layer's bytes, the revision, the
    settings."""
    edits = service.edits.read_bytes() if service.edits.exists() else None
    return edits, service.client.status()["revision"], \
        service.client._json("GET", "/settings")


def test_a_page_on_another_loopback_origin_cannot_post_deltas_or_settings(
        served, browser, attacker):
    before = _state(served)
    assert urlsplit(attacker).port != urlsplit(served.url).port
    browser.get(attacker)
    until(browser, "window.done === true", timeout=90)
    outcome = browser.execute_script("return window.outcome")
    assert len(outcome) == 8, outcome
    # each request was sent and answered (a no-cors answer is opaque to the page)
    for name in ("no-cors text/plain", "no-cors typed json", "no-cors keepalive",
                 "no-cors settings"):
        assert outcome[name] == "opaque 0", (name, outcome)
    assert outcome["text/plain form"] == "form answered", outcome
    assert _state(served) == before, outcome
    assert "my:note" not in (served.edits.read_text() if served.edits.exists() else "")


def test_a_rebound_name_gets_no_page_no_status_and_no_edit(served, browser):
    """The service under a name of the attacker's (resolving to loopback): the page, the
    status and a POST with a JSON body from that same origin are all 421."""
    before = _state(served)
    port = urlsplit(served.url).port
    rebound = f"http://{REBOUND}:{port}/"
    browser.get(rebound)
    assert "does not name this service" in browser.page_source
    assert browser.execute_script("return window.lumitrace") is None
    codes = browser.execute_async_script("""
        const done = arguments[arguments.length - 1];
        const body = JSON.stringify({deltas: [{op: "set", path: arguments[0],
          property: arguments[1], value: 31}]});
        Promise.all([
          fetch("/status").then((r) => r.status),
          fetch("/scene").then((r) => r.status),
          fetch("/geometry").then((r) => r.status),
          fetch("/deltas", {method: "POST", headers: {"Content-Type": "application/json"},
                            body}).then((r) => r.status),
          fetch("/settings", {method: "POST", headers: {"Content-Type": "application/json"},
                              body: '{"paused": true}'}).then((r) => r.status),
        ]).then(done, (e) => done(String(e)));""", SOURCE, FLUX)
    assert codes == [421] * 5, codes
    assert _state(served) == before


def test_the_services_own_page_still_edits_and_sets(served, browser):
    """The live view, loaded from the service, holds its key and sends it: a request of
    that origin without the key is refused, an emitter's flux typed in the page is a delta
    written to the edits layer, and its session panel sets the filter threshold."""
    revision = served.client.status()["revision"]
    browser.get_log("browser")  # what the pages before logged
    browser.get(served.url)
    until(browser, "window.lumitrace && lumitrace.scene && lumitrace.status")
    key = browser.execute_script(
        "return document.querySelector('meta[name=\"lumitrace-key\"]').content")
    assert len(key) >= 32 and key != "LUMITRACE-KEY"
    keyless = browser.execute_async_script("""
        const done = arguments[arguments.length - 1];
        fetch("/deltas", {method: "POST", headers: {"Content-Type": "application/json"},
          body: JSON.stringify({deltas: [{op: "set", path: arguments[0],
                                          property: arguments[1], value: 41}]})})
          .then((r) => done(r.status), (e) => done(String(e)));""", SOURCE, FLUX)
    assert keyless == 403
    assert served.client.status()["revision"] == revision
    browser.get_log("browser")  # the refusal's line; none after this
    browser.execute_script(
        "const el = document.querySelector('#emitter-box input[data-emitter=\"0\"]');"
        "el.value = '640'; el.dispatchEvent(new Event('change'));")
    until(browser, f"lumitrace.status && lumitrace.status.revision > {revision}")
    assert served.client.status()["revision"] == revision + 1
    assert f"float {FLUX} = 640" in served.edits.read_text()
    assert browser.execute_script("return lumitrace.problems") == []
    served.wait_done(revision + 1, pictures=False)
    # the session panel's settings: a POST /settings of the page
    browser.execute_script("document.getElementById('threshold').value = '5000';"
                           "document.getElementById('apply-session').click();")
    until(browser, "lumitrace.settings && lumitrace.settings.threshold === 5000", timeout=30)
    assert served.client._json("GET", "/settings")["threshold"] == 5000
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors
