"""Outcomes a farm can act on: exit statuses for an unmet target and for stale results,
`lumitrace check`, results that are never silently hidden, and a stage left untouched."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest
from pxr import Usd

from helpers.paths import REFERENCE


def _lumitrace(*args, cwd):
    return subprocess.run([sys.executable, "-m", "lumitrace.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture
def disc(tmp_path):
    stage = tmp_path / "disc.usda"
    shutil.copy(REFERENCE / "lambertian_disc.usda", stage)
    return stage


def test_an_unmet_target_error_exits_3_and_says_so(disc):
    run = _lumitrace("trace", disc, "--photons", "150000", "--target-error", "0.002",
                     "--no-progress", "--no-pictures", cwd=disc.parent)
    assert run.returncode == 3, run.stderr
    last = run.stdout.strip().splitlines()[-1]
    assert last.startswith("not converged: ") and "> 0.20%" in last
    run = _lumitrace("trace", disc, "--photons", "150000", "--target-error", "0.002", "--json",
                     "--no-progress", "--no-pictures", cwd=disc.parent)
    assert run.returncode == 3
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    assert summary["target_reached"] is False and summary["converged"] is False
    run = _lumitrace("trace", disc, "--photons", "150000", "--target-error", "0.5", "--json",
                     "--no-progress", "--no-pictures", cwd=disc.parent)
    assert run.returncode == 0
    assert json.loads(run.stdout.strip().splitlines()[-1])["target_reached"] is True


def test_a_target_the_estimate_meets_but_its_bound_does_not_is_not_reached(disc):
    """Judged on the map, convergence is judged on the error's bound (the bias term's
    spread added), not on the point estimate, which near the target is as often below the
    true error as above."""
    args = ("trace", disc, "--photons", "150000", "--json", "--no-progress", "--no-pictures")
    first = json.loads(_lumitrace(*args, cwd=disc.parent).stdout.strip().splitlines()[-1])
    error, bound = first["relative_error"], first["relative_error_bound"]
    assert bound > 1.1 * error > 0
    target = 0.5 * (error + bound)
    run = _lumitrace(*args, "--target-error", f"{target:.6f}", "--target-of", "map",
                     cwd=disc.parent)
    assert run.returncode == 3, run.stderr
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    assert summary["relative_error"] == error and summary["relative_error_bound"] == bound
    assert summary["target_reached"] is False and summary["converged"] is False


def test_check_gates_on_current_converged_results(disc):
    run = _lumitrace("check", disc, cwd=disc.parent)
    assert run.returncode == 1 and "missing" in run.stdout
    assert _lumitrace("trace", disc, "--photons", "200000", "--target-error", "0.5",
                      "--no-progress", "--no-pictures", cwd=disc.parent).returncode == 0
    run = _lumitrace("check", disc, "--json", cwd=disc.parent)
    verdict = json.loads(run.stdout)
    assert run.returncode == 0 and verdict["status"] == "current"
    assert verdict["sceneHash"] == verdict["currentSceneHash"]
    # an edit of the scene (a brighter source) makes them stale
    stage = Usd.Stage.Open(str(disc))
    stage.GetPrimAtPath("/Luminaire/Source").GetAttribute("lumitrace:luminousFlux").Set(1500.0)
    stage.GetRootLayer().Save()
    run = _lumitrace("check", disc, cwd=disc.parent)
    assert run.returncode == 1 and "stale" in run.stdout and "changed" in run.stdout
    # traced again with a target it does not reach: current but not converged
    assert _lumitrace("trace", disc, "--photons", "100000", "--target-error", "0.001",
                      "--no-progress", "--no-pictures", cwd=disc.parent).returncode == 3
    run = _lumitrace("check", disc, cwd=disc.parent)
    assert run.returncode == 3 and "not converged" in run.stdout


def test_a_flattened_stage_with_results_is_not_traced_into_hiding(disc):
    assert _lumitrace("trace", disc, "--photons", "100000", "--no-progress", "--no-pictures",
                      cwd=disc.parent).returncode in (0, 3)
    flat = disc.with_name("flat.usda")
    Usd.Stage.Open(str(disc)).Export(str(flat))
    before = flat.read_bytes()
    # the flattened copy's results are the last trace's: current (by their hash)
    assert _lumitrace("check", flat, cwd=disc.parent).returncode in (0, 3)
    run = _lumitrace("trace", flat, "--photons", "100000", "--no-progress", cwd=disc.parent)
    assert run.returncode == 2
    assert "stronger than the result layer" in run.stderr and str(flat) in run.stderr
    assert flat.read_bytes() == before and not flat.with_name("flat.ies").exists()
    # --no-sublayer writes the results beside it and leaves the stage file alone
    run = _lumitrace("trace", flat, "--photons", "100000", "--no-progress", "--no-pictures",
                     "--no-sublayer", cwd=disc.parent)
    assert run.returncode == 0, run.stderr
    assert flat.read_bytes() == before
    assert flat.with_name("flat.lumitrace.usda").exists() and flat.with_name("flat.ies").exists()


def test_a_flattened_stage_traced_again_with_replace_results_is_current(disc):
    assert _lumitrace("trace", disc, "--photons", "100000", "--target-error", "0.5",
                      "--no-progress", "--no-pictures", cwd=disc.parent).returncode == 0
    flat = disc.with_name("flat.usda")
    Usd.Stage.Open(str(disc)).Export(str(flat))
    # the stage changes after flattening: its copied results are stale
    stage = Usd.Stage.Open(str(flat))
    stage.GetPrimAtPath("/Luminaire/Source").GetAttribute("lumitrace:luminousFlux").Set(800.0)
    stage.GetRootLayer().Save()
    assert _lumitrace("check", flat, cwd=disc.parent).returncode == 1
    run = _lumitrace("trace", flat, "--photons", "200000", "--target-error", "0.5",
                     "--replace-results", "--no-progress", "--no-pictures", "--json",
                     cwd=disc.parent)
    assert run.returncode == 0, run.stderr
    assert "removed the stale lumitrace:result:* opinions on /Luminaire" in run.stderr
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    assert summary["escaped_lm"] == pytest.approx(800.0)
    check = _lumitrace("check", flat, "--json", cwd=disc.parent)
    assert check.returncode == 0, check.stdout
    stage.GetRootLayer().Reload()  # this process still holds the layer as it saved it
    composed_stage = Usd.Stage.Open(str(flat))
    composed = composed_stage.GetPrimAtPath("/Luminaire")
    assert composed.GetAttribute("lumitrace:result:photons").Get() == summary["photons"]
    assert composed.GetVariantSets().GetVariantSet("lumitraceRepresentation") \
        .GetVariantNames() == ["geometry", "photometric"]


def test_cli_conventions_for_logs_and_scripts(disc):
    """Piped stderr gets a line per iteration (no carriage returns); --quiet prints
    nothing; --luminaire and --time-code reach the reader; --version answers."""
    run = _lumitrace("trace", disc, "--photons", "100000", "--no-pictures", cwd=disc.parent)
    assert run.returncode == 0 and "\r" not in run.stderr
    lines = [ln for ln in run.stderr.splitlines() if ln.startswith("iteration ")]
    assert len(lines) >= 2 and "photons" in lines[-1] and "error" in lines[-1]
    run = _lumitrace("trace", disc, "--photons", "50000", "--no-pictures", "--quiet",
                     "--luminaire", "/Luminaire", "--time-code", "1", cwd=disc.parent)
    assert run.returncode == 0 and run.stdout == "" and run.stderr == ""
    run = _lumitrace("trace", disc, "--photons", "50000", "--luminaire", "/Nope",
                     cwd=disc.parent)
    assert run.returncode == 2 and "/Nope" in run.stderr
    run = _lumitrace("--version", cwd=disc.parent)
    assert run.returncode == 0 and run.stdout.startswith("lumitrace ")
