"""The service's security rules in raw HTTP against a real ``lumitrace serve`` process on a
free loopback port: ``Host`` names the service (421 otherwise, ``--allow-host`` adds names),
a browser's cross-origin request is refused (403) on every route that reveals the stage or
changes it, POST bodies are JSON (415 otherwise), a browser's POST carries the page's key,
a program's request (the stdlib client, a DCC's Python) works unchanged, ``/settings`` is
held to the command line's ranges, and the token is given without showing in ``ps``.
In each refused case the edits layer and the settings stay as they were."""
from __future__ import annotations

import http.client
import json
import os
import re
import shutil
import subprocess
import sys
import urllib.request
from pathlib import Path
from urllib.parse import urlsplit

import pytest
from service_process import Service

from lumitrace.client import Client, ServiceError
from helpers.paths import REFERENCE

SOURCE = "/Luminaire/Source"
FLUX = "lumitrace:luminousFlux"
FAST = ("--photons", 20_000, "--resolution", 8, "--threads", 1, "--seed", 3)
#: Every route that reveals the stage (its path, parts, triangles, map, results, events).
REVEALING = ("/status", "/scene", "/geometry", "/preview", "/results", "/settings",
             "/events?format=json", "/schema")


def _delta(flux: float) -> bytes:
    return json.dumps({"deltas": [{"op": "set", "path": SOURCE, "property": FLUX,
                                   "value": flux}]}).encode()


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    folder = tmp_path_factory.mktemp("security")
    stage = folder / "isotropic.usda"
    shutil.copy(REFERENCE / "isotropic.usda", stage)
    with Service(stage, *FAST) as s:
        s.wait_done(0)
        s.port = urlsplit(s.url).port
        s.edits = folder / "isotropic.lumitrace-edits.usda"
        yield s


def _raw(service, method: str, path: str, headers: dict[str, str] | None = None,
         body: bytes | None = None, host: str | None = None) -> tuple[int, bytes]:
    """One request with exactly these headers (``host``: the Host header, default the
    service's own address); (status, body)."""
    conn = http.client.HTTPConnection("127.0.0.1", service.port, timeout=30)
    try:
        conn.putrequest(method, path, skip_host=True, skip_accept_encoding=True)
        conn.putheader("Host", host if host is not None else f"127.0.0.1:{service.port}")
        for name, value in (headers or {}).items():
            conn.putheader(name, value)
        if body is not None:
            conn.putheader("Content-Length", str(len(body)))
        conn.endheaders(body)
        r = conn.getresponse()
        return r.status, r.read()
    finally:
        conn.close()


def _untouched(service, edits_before, revision: int = None) -> None:
    """Nothing was changed: the edits layer's bytes, the revision, the settings."""
    now = service.edits.read_bytes() if service.edits.exists() else None
    assert now == edits_before
    status = service.client.status()
    if revision is not None:
        assert status["revision"] == revision, status
    assert service.client._json("GET", "/settings")["paused"] is False


def _state(service):
    return (service.edits.read_bytes() if service.edits.exists() else None,
            service.client.status()["revision"])


def test_a_host_that_does_not_name_the_service_is_refused(served):
    """A rebinding page's requests carry its own name: every route, the page included,
    answers 421 for a Host that is no loopback name or address, not the bound address and
    not given with --allow-host (see the token test for one given); loopback spellings
    pass."""
    edits, revision = _state(served)
    port = served.port
    foreign = ("evil.example", f"evil.example:{port}", f"localhost.evil.example:{port}",
               f"127.0.0.1.nip.example:{port}", f"10.1.2.3:{port}", f"lamp.studio:{port}",
               f"[fe80::1]:{port}")
    for host in foreign:
        for path in (*REVEALING, "/", "/page/viewer.js"):
            code, body = _raw(served, "GET", path, host=host)
            assert code == 421, (host, path, code, body[:200])
            assert "--allow-host" in json.loads(body)["error"], body
        code, body = _raw(served, "POST", "/deltas", {"Content-Type": "application/json"},
                          _delta(10.0), host=host)
        assert code == 421, (host, code, body)
        code, _ = _raw(served, "POST", "/settings", {"Content-Type": "application/json"},
                       b'{"paused": true}', host=host)
        assert code == 421
    for host in ("", "a b", "x:port", "[::1"):
        assert _raw(served, "GET", "/status", host=host)[0] == 400, host
    _untouched(served, edits, revision)
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", "localhost", f"LOCALHOST.:{port}",
                 f"[::1]:{port}", f"127.0.0.2:{port}"):
        code, body = _raw(served, "GET", "/status", host=host)
        assert code == 200 and json.loads(body)["revision"] == revision, (host, code, body)


def test_a_browsers_cross_origin_request_is_refused_on_every_route(served):
    """Another origin (another port of loopback included) and a cross-site or same-site
    fetch are refused with 403 on every route that reveals the stage or changes it, even
    with a JSON body; the request a browser marks as the user's own (Sec-Fetch-Site: none)
    and the service's own origin read."""
    edits, revision = _state(served)
    port = served.port
    foreign = [{"Origin": "http://evil.example"}, {"Origin": f"http://127.0.0.1:{port + 1}"},
               {"Origin": f"http://localhost:{port}"}, {"Origin": "null"},
               {"Origin": f"https://127.0.0.1:{port + 1}"}, {"Origin": "file://"},
               {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "no-cors"},
               {"Sec-Fetch-Site": "same-site", "Sec-Fetch-Mode": "cors"}]
    for headers in foreign:
        for path in REVEALING:
            code, body = _raw(served, "GET", path, headers)
            assert code == 403, (headers, path, code, body[:200])
            assert "cross-origin" in json.loads(body)["error"]
        for path, body in (("/deltas", _delta(10.0)), ("/settings", b'{"paused": true}')):
            code, _ = _raw(served, "POST", path,
                           {**headers, "Content-Type": "application/json"}, body)
            assert code == 403, (headers, path, code)
    _untouched(served, edits, revision)
    for headers in ({"Origin": f"http://127.0.0.1:{port}"}, {"Sec-Fetch-Site": "none"},
                    {"Sec-Fetch-Site": "same-origin", "Origin": f"http://127.0.0.1:{port}"}):
        code, body = _raw(served, "GET", "/status", headers)
        assert code == 200 and json.loads(body)["revision"] == revision, (headers, body)
    # a link from anywhere opens the page itself (no other origin can read it)
    code, body = _raw(served, "GET", "/", {"Sec-Fetch-Site": "cross-site",
                                           "Sec-Fetch-Mode": "navigate"})
    assert code == 200 and b"<canvas" in body


def test_a_post_body_is_json_and_nothing_else(served):
    """The bodies a page may send to another origin without a preflight (text/plain, a
    form's, multipart) and a body of no type are 415, even when they hold valid JSON; the
    deltas and settings they carry change nothing."""
    edits, revision = _state(served)
    for kind in ("text/plain", "text/plain;charset=UTF-8", "application/x-www-form-urlencoded",
                 "multipart/form-data; boundary=x", "application/jsonp", None):
        headers = {"Content-Type": kind} if kind else {}
        for path, body in (("/deltas", _delta(10.0)), ("/settings", b'{"paused": true}')):
            code, raw = _raw(served, "POST", path, headers, body)
            assert code == 415, (kind, path, code, raw)
            assert "application/json" in json.loads(raw)["error"]
    _untouched(served, edits, revision)
    code, raw = _raw(served, "POST", "/deltas",
                     {"Content-Type": "application/json; charset=utf-8"}, _delta(900.0))
    assert code == 200 and json.loads(raw)["revision"] == revision + 1, raw


def _page_key(service) -> str:
    code, body = _raw(service, "GET", "/")
    assert code == 200
    return re.search(rb'name="lumitrace-key" content="([^"]+)"', body).group(1).decode()


def test_a_browsers_post_needs_the_page_key_and_a_programs_does_not(served):
    """A same-origin POST from a browser (it carries Origin or Sec-Fetch-*) without the
    page's key, or with another, is 403; with the key its page was given it goes through.
    The stdlib client and a DCC's plain urllib (no Origin, JSON) need no key."""
    edits, revision = _state(served)
    key = _page_key(served)
    assert key != "LUMITRACE-KEY" and len(key) >= 32
    assert key.encode() not in (Path(__file__).parents[2] / "service" / "lumitrace" / "serve"
                                / "page" / "index.html").read_bytes()
    own = {"Origin": f"http://127.0.0.1:{served.port}", "Content-Type": "application/json"}
    for headers in (own, {**own, "X-Lumitrace-Key": key[:-1]},
                    {**own, "X-Lumitrace-Key": ""}, {**own, "X-Lumitrace-Key": "\u00e9"},
                    {"Sec-Fetch-Site": "same-origin", "Content-Type": "application/json"}):
        code, raw = _raw(served, "POST", "/deltas", headers, _delta(10.0))
        assert code == 403 and "key" in json.loads(raw)["error"], (headers, code, raw)
    _untouched(served, edits, revision)
    code, raw = _raw(served, "POST", "/deltas", {**own, "X-Lumitrace-Key": key}, _delta(700.0))
    assert code == 200 and json.loads(raw)["revision"] == revision + 1, raw
    # a program: the stdlib client, and a DCC's own urllib request
    assert Client(served.url).set(SOURCE, FLUX, 800.0)["revision"] == revision + 2
    request = urllib.request.Request(served.url + "deltas", data=_delta(850.0),
                                     headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=30) as r:
        assert json.loads(r.read())["revision"] == revision + 3
    assert "= 850" in served.edits.read_text()


def test_settings_are_held_to_the_command_lines_ranges(served):
    """A budget above --max-photons and a target below --min-target-error (their defaults
    here: 1e10 and 0.002) are 422 naming the field, and change nothing; values inside the
    ranges are taken."""
    client = served.client
    before = client._json("GET", "/settings")
    for body, field in (({"photons": 10_000_000_001}, "photons"),
                        ({"photons": 2 ** 53}, "photons"),
                        ({"target_error": 0.0019}, "target_error"),
                        ({"target_error": 1e-300}, "target_error")):
        with pytest.raises(ServiceError) as err:
            client._json("POST", "/settings", body)
        assert err.value.status == 422 and err.value.message.startswith(f"{field}:"), \
            err.value
        assert ("--max-photons" if field == "photons" else "--min-target-error") in \
            err.value.message
        assert client._json("GET", "/settings") == before
    assert client._json("POST", "/settings", {"photons": 100_000})["photons"] == 100_000
    taken = client._json("POST", "/settings", {"target_error": 0.5})
    assert taken["target_error"] == 0.5 and taken["photons"] is None


def _serve(stage: Path, *args, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lumitrace.cli", "serve", str(stage),
                           "--port", "0", *map(str, args)], capture_output=True, text=True,
                          timeout=120, env=env)


def test_the_command_lines_own_budget_is_held_to_its_ranges(tmp_path):
    """The command line's --photons and --target-error lie within its own limits: exit 2
    naming the option, before anything starts."""
    stage = tmp_path / "isotropic.usda"
    shutil.copy(REFERENCE / "isotropic.usda", stage)
    for args, option in ((("--photons", 2_000_000, "--max-photons", 1_000_000), "--photons"),
                         (("--target-error", 0.001), "--target-error")):
        run = _serve(stage, *args)
        assert run.returncode == 2 and option in run.stderr, run.stderr
        assert "lumitrace: serving" not in run.stdout
    for args, said in ((("--allow-host", "lamp.studio:8650"), "--allow-host"),
                       (("--token-file", tmp_path / "missing"), "cannot read the token")):
        run = _serve(stage, *args)
        assert run.returncode == 2 and said in run.stderr, run.stderr
    empty = tmp_path / "empty"
    empty.write_text("\n")
    run = _serve(stage, "--token-file", empty)
    assert run.returncode == 2 and "empty" in run.stderr, run.stderr


def _command_line(pid: int) -> bytes:
    return Path(f"/proc/{pid}/cmdline").read_bytes()


@pytest.mark.skipif(not Path("/proc/self/cmdline").exists(), reason="no /proc")
def test_a_token_from_a_file_or_the_environment_never_shows_in_ps(tmp_path):
    """--token-file FILE and LUMITRACE_TOKEN give the token; the process's command line
    holds no trace of it, requests without it are 401 and with it answered. A name given
    with --allow-host is taken as Host (and only that name)."""
    stage = tmp_path / "isotropic.usda"
    shutil.copy(REFERENCE / "isotropic.usda", stage)
    secret = "tok-" + os.urandom(12).hex()
    token_file = tmp_path / "token"
    token_file.write_text(secret + "\n")
    token_file.chmod(0o600)
    with Service(stage, *FAST, "--token-file", token_file, "--allow-host", "lamp.studio") as s:
        assert secret.encode() not in _command_line(s.proc.pid)
        with pytest.raises(ServiceError) as err:
            Client(s.url).status()
        assert err.value.status == 401
        assert Client(s.url, token=secret).status()["revision"] == 0
        s.port = urlsplit(s.url).port
        auth = {"Authorization": f"Bearer {secret}"}
        for host, code in ((f"lamp.studio:{s.port}", 200), ("LAMP.studio", 200),
                           (f"lamp.studio.evil:{s.port}", 421), (f"studio:{s.port}", 421)):
            assert _raw(s, "GET", "/status", auth, host=host)[0] == code, host
        s.kill()
    with Service(stage, *FAST, token=secret) as s:  # the helper gives LUMITRACE_TOKEN
        assert secret.encode() not in _command_line(s.proc.pid)
        assert secret.encode() in Path(f"/proc/{s.proc.pid}/environ").read_bytes()
        with pytest.raises(ServiceError) as err:
            Client(s.url, token=secret + "x").status()
        assert err.value.status == 401
        assert Client(s.url, token=secret).status()["revision"] == 0
