"""The command line where users push it: fewer photons than lights, options that must not
be dropped or trusted blindly, deadlines, read-only and shared folders, closed streams,
signals through ``python -m``, and failures that still answer in JSON."""
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers.mounts import tmpfs
from helpers.paths import ROOT

DISC = ROOT / "stages" / "reference" / "lambertian_disc.usda"
SPHERE = ROOT / "stages" / "reference" / "integrating_sphere.usda"


def lumitrace(*args, **kw):
    kw.setdefault("capture_output", True)
    p = subprocess.run([sys.executable, "-m", "lumitrace", *map(str, args)], text=True,
                       timeout=300, **kw)
    return p.returncode, p.stdout, p.stderr


def trace(stage, *extra, photons=40_000, **kw):
    return lumitrace("trace", stage, "--photons", photons, "--resolution", 16,
                     "--no-progress", "--threads", 1, "--no-pictures", *extra, **kw)


@pytest.fixture
def dl(tmp_path):
    stage = tmp_path / "dl.usda"
    shutil.copy(DISC, stage)
    return stage


def _many_lights(path: Path, n: int, alike: bool = False) -> Path:
    """``n`` sphere lights of 1 lm in a row: each of its own size (so each is traced as
    itself), or all ``alike`` (traced as one group)."""
    from pxr import Sdf, Usd, UsdGeom, UsdLux

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Luminaire")
    stage.SetDefaultPrim(root.GetPrim())
    for i in range(n):
        light = UsdLux.SphereLight.Define(stage, f"/Luminaire/L{i}")
        light.CreateRadiusAttr(0.001 if alike else 0.001 * (1.0 + 1e-3 * i))
        UsdGeom.Xformable(light).AddTranslateOp().Set((0.001 * i, 0, 0))
        light.GetPrim().CreateAttribute("lumitrace:luminousFlux",
                                        Sdf.ValueTypeNames.Float).Set(1.0)
    stage.Save()
    return path


# -- 9. fewer photons than emitters --------------------------------------------------------

def test_fewer_photons_than_emitters_is_refused_and_every_emitter_counts(tmp_path):
    stage = _many_lights(tmp_path / "many.usda", 400)
    code, out, err = trace(stage, "--json", photons=300)
    assert code == 2 and "at least 400" in err and "emitters" in err, err
    assert json.loads(out.strip().splitlines()[-1])["exit_status"] == 2
    # one photon a light: every light's flux is there, and no error is claimed
    code, out, err = trace(stage, "--json", "--target-error", "0.5", photons=400)
    assert code == 3, err
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["emitted_lm"] == pytest.approx(400.0)
    assert summary["relative_error"] is None and summary.get("photometry_error") is None
    assert summary["converged"] is False
    # without a target too: the files written from one photon a light claim no accuracy
    code, out, err = trace(stage, "--json", photons=400)
    summary = json.loads(out.strip().splitlines()[-1])
    assert code == 0 and summary["converged"] is False, err
    assert summary["judged_error"] is None and summary.get("photometry_error") is None
    code, out, err = trace(stage, "--json", photons=1000)
    assert code == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["emitted_lm"] == pytest.approx(400.0)
    assert summary["relative_error"] > 0.1  # 2.5 photons a light: honest, and large


def test_many_identical_lights_are_one_group_that_needs_no_photon_each(tmp_path):
    """400 lights alike are traced as one group: 300 photons are enough, every light's flux
    is there."""
    stage = _many_lights(tmp_path / "alike.usda", 400, alike=True)
    code, out, err = trace(stage, "--json", photons=300)
    assert code == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["emitted_lm"] == pytest.approx(400.0) and summary["photons"] == 300


def test_allocation_gives_every_emitter_its_minimum_and_keeps_the_usual_split():
    from lumitrace.run.session import allocate

    assert allocate([1.0, 2.0, 1.0], 8) == [2, 4, 2]
    assert allocate([1000.0, 1e-6], 10, minimum=1) == [9, 1]
    assert allocate([1000.0, 1e-6], 10, minimum=2) == [8, 2]
    assert sum(allocate([1.0] * 5 + [1e6], 20, minimum=2)) == 20
    assert min(allocate([1.0] * 5 + [1e6], 20, minimum=2)) == 2
    with pytest.raises(ValueError):
        allocate([1.0] * 5, 4, minimum=1)


# -- 10. --edits keeps --luminaire and --time-code --------------------------------------

def test_edits_keeps_the_luminaire_and_the_time_code(dl, tmp_path):
    from pxr import Sdf

    edits = tmp_path / "empty.usda"
    Sdf.Layer.CreateNew(str(edits)).Save()
    code, _, err = trace(dl, "--edits", edits, "--luminaire", "/Nope")
    assert code == 2 and "/Nope" in err, err
    layer = Sdf.Layer.FindOrOpen(str(dl))
    path = Sdf.Path("/Luminaire/Source.lumitrace:luminousFlux")
    assert layer.GetAttributeAtPath(path) is not None
    layer.SetTimeSample(path, 0.0, 1000.0)
    layer.SetTimeSample(path, 10.0, 500.0)
    layer.Save()
    outs = []
    for extra in ((), ("--edits", edits)):
        code, out, err = trace(dl, "--time-code", 10, "--json", "--out", tmp_path / "o",
                               "--no-sublayer", *extra)
        assert code == 0, err
        outs.append(json.loads(out.strip().splitlines()[-1])["emitted_lm"])
    assert outs == [pytest.approx(500.0)] * 2


# -- 11. frames that do not fit ----------------------------------------------------------

@pytest.mark.parametrize("frame", ["1e308,0,0,1", "0,0,0,1e9", "0,0,0,1e-9"])
def test_a_frame_that_does_not_fit_the_luminaire_is_refused(dl, frame):
    code, _, err = trace(dl, f"--frame={frame}")
    assert code == 2 and "--frame" in err and "Traceback" not in err, err


def test_the_frame_a_service_reports_is_accepted(dl):
    assert trace(dl, "--frame=0,0,0,0.05")[0] == 0


# -- 12. --time is a deadline --------------------------------------------------------------

def test_time_is_a_deadline_counted_from_the_start(tmp_path):
    stage = tmp_path / "sphere.usda"
    shutil.copy(SPHERE, stage)
    code, out, err = lumitrace("trace", stage, "--time", 3, "--no-progress", "--no-pictures",
                               "--threads", 2, "--json")
    assert code == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    # the tracing ends by the deadline, which counts the start: its own seconds are fewer
    # (the whole command's wall time depends on the machine's load, so it is not asserted)
    assert 0 < summary["seconds"] < 3.0


# -- 13. read-only stage folders and shared folders ----------------------------------------

@pytest.fixture
def read_only_folder(tmp_path):
    """A real read-only file system holding the stage (a tmpfs remounted read-only)."""
    with tmpfs(tmp_path / "ro", "4m", lambda m: shutil.copy(DISC, m / "dl.usda"),
               read_only=True) as mount:
        yield mount


def test_a_stage_in_a_read_only_folder_traces_to_an_out_folder(read_only_folder, tmp_path):
    stage = read_only_folder / "dl.usda"
    code, _, err = trace(stage, "--out", tmp_path / "results", "--no-sublayer")
    assert code == 0, err
    assert (tmp_path / "results" / "dl.ies").exists()
    code, _, err = trace(stage)
    assert code == 2 and "not writable" in err and "--out" in err


def test_a_lock_file_left_by_another_user_does_not_lock_anyone_out(dl):
    """Another user's killed run left its lock file (theirs, mode 0644) in a shared
    folder: a run that may not write that file still takes the lock, traces, publishes,
    and leaves no lock file behind. (Root without its permission-override capabilities
    stands in for the other user.)"""
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv(1) to give up the permission overrides")
    lock = dl.with_name(".dl.lumitrace.lock")
    lock.write_text("12345")
    os.chown(lock, 65534, 65534)
    os.chmod(lock, 0o644)
    drop = ["setpriv", "--inh-caps=-dac_override,-dac_read_search",
            "--bounding-set=-dac_override,-dac_read_search", "--"]
    p = subprocess.run(drop + [sys.executable, "-m", "lumitrace", "trace", str(dl),
                               "--photons", "40000", "--resolution", "16", "--no-progress",
                               "--no-pictures"], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert not lock.exists()  # no lock outlives its run
    assert dl.with_name("dl.ies").exists()


def test_a_run_leaves_no_lock_file(dl):
    assert trace(dl)[0] == 0
    assert not list(dl.parent.glob(".*lock*"))


# -- 14. --json on failure -----------------------------------------------------------------

@pytest.mark.parametrize("command", ["trace", "check"])
def test_json_answers_a_failure_with_one_object(tmp_path, command):
    code, out, err = lumitrace(command, tmp_path / "missing.usda", "--json")
    assert code == 2
    last = json.loads(out.strip().splitlines()[-1])
    assert last["exit_status"] == 2 and "missing.usda" in last["error"]
    assert last["command"] == command


# -- 15. one line, never a traceback ---------------------------------------------------------

@pytest.mark.parametrize("quiet", [True, False])
def test_a_closed_stdout_is_not_a_crash(dl, quiet):
    p = subprocess.run([sys.executable, "-m", "lumitrace", "trace", str(dl), "--photons",
                        "20000", "--resolution", "16", "--no-progress", "--no-pictures",
                        *(["--quiet"] if quiet else [])],
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                       timeout=300, pass_fds=(), close_fds=True,
                       preexec_fn=lambda: os.close(1))
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr


def test_garbage_edits_layers_are_one_line(dl, tmp_path):
    garbage = tmp_path / "garbage.usda"
    garbage.write_text("this is not USD\n")
    code, _, err = trace(dl, "--edits", garbage)
    assert code == 2 and "garbage.usda" in err and "Traceback" not in err, err
    shutil.copy(garbage, dl.with_name("dl.lumitrace-edits.usda"))
    code, _, err = lumitrace("edits", "merge", dl)
    assert code == 2 and "lumitrace-edits.usda" in err and "Traceback" not in err, err


@pytest.mark.parametrize("flaw, words", [("nan", "direction that is not finite"),
                                         ("zero", "zero length"),
                                         ("inf", "start point that is not finite")])
def test_a_ray_file_with_a_bad_ray_is_one_line_naming_the_ray(tmp_path, flaw, words):
    from pxr import Sdf, Usd, UsdGeom, UsdLux

    from lumitrace import tm25

    n = 64
    rays = tm25.RayFile(positions=np.zeros((n, 3), np.float32),
                        directions=np.tile(np.float32([0, 0, 1]), (n, 1)),
                        flux=np.full(n, 0.01, np.float32))
    {"nan": lambda: rays.directions.__setitem__((5, 0), np.nan),
     "zero": lambda: rays.directions.__setitem__(5, 0.0),
     "inf": lambda: rays.positions.__setitem__((5, 2), np.inf)}[flaw]()
    (tmp_path / "led.TM25RAY").write_bytes(tm25.format_tm25(rays))
    path = tmp_path / "led.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 0.001)
    UsdGeom.SetStageUpAxis(stage, "Z")
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/Luminaire").GetPrim())
    light = UsdLux.SphereLight.Define(stage, "/Luminaire/LED").GetPrim()
    light.AddAppliedSchema("LumitraceEmitterAPI")
    light.CreateAttribute("lumitrace:rayFile", Sdf.ValueTypeNames.Asset).Set("./led.TM25RAY")
    stage.Save()
    code, _, err = trace(path)
    assert code == 2 and words in err and "ray 5" in err and "Traceback" not in err, err


# -- 16. the polar curve of a luminaire no light leaves -------------------------------------

def test_the_polar_curve_of_no_light_is_not_a_circle(tmp_path):
    import matplotlib.image as mpimg

    from lumitrace.photometry.diagrams import polar_diagram
    from lumitrace.photometry.grid import CGammaGrid

    c, g = np.arange(0.0, 360.0, 15.0), np.arange(0.0, 180.1, 5.0)
    lit = CGammaGrid(c, g, np.full((len(c), len(g)), 100.0))
    dark = CGammaGrid(c, g, np.zeros((len(c), len(g))))

    def red_spread(grid, name):
        img = mpimg.imread(polar_diagram(tmp_path / name, grid, 1000.0))[..., :3]
        img = img[:int(0.88 * len(img))]  # the plot, not the legend under it
        red = (img[..., 0] > 0.6) & (img[..., 1] < 0.35) & (img[..., 2] < 0.35)
        ys, xs = np.nonzero(red)
        return 0 if len(xs) == 0 else max(np.ptp(xs), np.ptp(ys))

    assert red_spread(lit, "lit.png") > 200  # a circle of 100 cd/klm fills the plot
    assert red_spread(dark, "dark.png") < 20  # zeros stay at the centre


def test_a_signal_a_finalizer_swallows_is_not_printed_as_a_traceback():
    """A signal's :class:`Interrupted` raised inside a weakref callback (a plotting library's,
    during the write) cannot propagate: the command acts on the recorded signal, so the
    ignored exception is not printed; any other ignored exception still is."""
    code = (
        "import sys, weakref\n"
        "from lumitrace import cli\n"
        "from lumitrace.errors import Interrupted\n"
        "class A: pass\n"
        "def stop(_): raise Interrupted(15)\n"
        "def fail(_): raise ValueError('kept')\n"
        "def dispatch(args):\n"  # the command's work, within main's hooks
        "    a, b = A(), A()\n"
        "    r, s = weakref.ref(a, stop), weakref.ref(b, fail)\n"
        "    del a, b\n"
        "    print('ran on')\n"
        "    return 0\n"
        "cli._dispatch = dispatch\n"
        "sys.exit(cli.main(['check', 'any.usda']))\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=60, env={**os.environ, "PYTHONPATH": str(ROOT / "service")})
    assert p.returncode == 0 and p.stdout == "ran on\n", p.stderr
    assert "Interrupted" not in p.stderr
    assert "ValueError: kept" in p.stderr and p.stderr.count("Exception ignored") == 1


def test_a_signal_a_library_wraps_is_still_the_signal():
    """A signal's :class:`Interrupted` that a library wraps in its own exception (a class
    body's ``__set_name__`` during an import turns it into a RuntimeError) ends the run as
    the signal does: its exit status and one line, no traceback; another RuntimeError is
    raised as it is."""
    code = (
        "import sys\n"
        "from lumitrace import cli\n"
        "from lumitrace.errors import Interrupted\n"
        "class Hook:\n"
        "    def __set_name__(self, owner, name): raise Interrupted(15)\n"
        "def dispatch(args):\n"
        "    if sys.argv[1] == 'other': raise RuntimeError('not a signal')\n"
        "    class Axes:\n"
        "        x = Hook()\n"
        "cli._dispatch = dispatch\n"
        "sys.exit(cli.main(['check', 'any.usda']))\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT / "service")}
    p = subprocess.run([sys.executable, "-c", code, "signal"], capture_output=True, text=True,
                       timeout=60, env=env)
    assert p.returncode == 128 + signal.SIGTERM, p.stderr
    assert "Traceback" not in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    p = subprocess.run([sys.executable, "-c", code, "other"], capture_output=True, text=True,
                       timeout=60, env=env)
    assert p.returncode == 1 and "RuntimeError: not a signal" in p.stderr


def test_an_argument_of_the_wrong_kind_is_said_in_the_users_words(capsys):
    """Every option of every command that takes a value, given one that is not a value of
    its kind, exits 2 with a line naming the option, never a function of ours."""
    import argparse

    from lumitrace.cli import build_parser

    top = build_parser()
    commands = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    checked = 0
    for name, parser in commands.choices.items():
        for action in parser._actions:
            if not action.option_strings or action.nargs == 0 or action.choices \
                    or action.type in (None, str, Path):
                continue
            with pytest.raises(SystemExit) as stop:
                parser.parse_args(["a.usda", action.option_strings[0], "zz"]
                                  if name not in ("bench",) else
                                  [action.option_strings[0], "zz"])
            line = capsys.readouterr().err.strip().splitlines()[-1]
            assert stop.value.code == 2 and action.option_strings[0] in line, line
            assert "invalid _" not in line and "function" not in line, line
            checked += 1
    assert checked > 20
