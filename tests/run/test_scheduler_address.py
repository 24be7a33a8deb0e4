"""``--scheduler`` takes Dask's TCP addresses only: an address without a scheme or with
another one (``127.0.0.1``, ``http://``, ``tls://``, ``inproc://``) is refused at once with
exit status 2 naming the accepted form, by every command that takes it, before anything is
read, traced or connected to."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.paths import ROOT

from lumitrace.cli import main
from lumitrace.run.settings import SCHEDULER_FORM, SettingsError, TraceSettings

BAD = ["127.0.0.1", "127.0.0.1:8786", "http://127.0.0.1:8786", "tls://127.0.0.1:8786",
       "inproc://192.168.1.5/123/1", "tcp://127.0.0.1", "tcp://127.0.0.1:0",
       "tcp://127.0.0.1:99999", "tcp:// :8786"]
STAGE = str(ROOT / "stages" / "downlight.usda")
COMMANDS = {"trace": ["trace", STAGE], "serve": ["serve", STAGE], "sweep": ["sweep", STAGE],
            "fit": ["fit", STAGE, "--vary", "/Luminaire/Led.lumitrace:luminousFlux=100:2000",
                    "--objective", "peak=1000"]}


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("address", BAD)
def test_a_bad_scheduler_address_is_exit_2_naming_the_accepted_form(command, address,
                                                                      capsys):
    with pytest.raises(SystemExit) as exited:
        main([*COMMANDS[command], "--scheduler", address])
    err = capsys.readouterr().err
    assert exited.value.code == 2
    line = err.strip().splitlines()[-1]
    assert line.startswith(f"lumitrace {command}: error: argument --scheduler: "), err
    assert SCHEDULER_FORM in line and "Traceback" not in err


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:8786", "tcp://[::1]:8786",
                                     "tcp://scheduler.example:1"])
def test_tcp_addresses_are_taken(address):
    assert TraceSettings(scheduler=address).scheduler == address


def test_the_settings_refuse_it_too_and_the_command_exits_at_once():
    with pytest.raises(SettingsError, match="no scheme: give the scheduler's address as "
                                            "tcp://HOST:PORT"):
        TraceSettings(scheduler="127.0.0.1")
    entry = Path(sys.executable).with_name("lumitrace")
    command = [str(entry)] if entry.exists() else [sys.executable, "-m", "lumitrace"]
    p = subprocess.run([*command, "trace", STAGE, "--scheduler", "inproc://x"],
                       capture_output=True, text=True, timeout=60,
                       env={**os.environ, "PYTHONPATH": str(ROOT / "service")})
    assert p.returncode == 2 and "inproc://" in p.stderr and SCHEDULER_FORM in p.stderr
    assert "Traceback" not in p.stderr
