"""The ``lumitrace`` command's entry point: signals are caught from the first instant.

Importing lumitrace loads USD, which takes a few tenths of a second and can swallow a
KeyboardInterrupt raised meanwhile (the run would then go on and publish). So this small
module, which imports only the standard library, records SIGINT, SIGTERM and SIGHUP before
lumitrace is imported, and hands them to :func:`lumitrace.cli.main`.
"""
import os
import signal
import sys

_early: list[int] = []


def _record(signum, _frame) -> None:
    _early.append(signum)


def main() -> int:
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(s, _record)
    # numpy's small matrix products gain nothing from OpenBLAS threads, whose idle spinning
    # costs CPU next to the tracer's own threads (set before numpy loads; worker processes
    # inherit it). A value the user set wins.
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    _start_renderer(sys.argv)
    from lumitrace.cli import main as cli_main
    from lumitrace.quick_exit import finish

    return finish(cli_main(early_signals=_early))


def _start_renderer(argv: list[str]) -> None:
    """A ``trace`` that will draw pictures starts the photometric solid's renderer now,
    before lumitrace and USD load, so that loading VTK overlaps all of the run: the
    renderer's module (standard library only at import) is loaded by its file under its
    own name, and the package finds it there."""
    if argv[1:2] != ["trace"] or any(a in ("--no-pictures", "-h", "--help") for a in argv):
        return
    import importlib.util

    spec = importlib.util.find_spec("lumitrace")
    if spec is None or not spec.origin:
        return
    name = "lumitrace.photometry.solid_render"
    path = os.path.join(os.path.dirname(spec.origin), "photometry", "solid_render.py")
    try:
        module_spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[name] = module
        module_spec.loader.exec_module(module)
        module.start_renderer()
    except Exception:  # the command starts it itself, or draws in its own process
        sys.modules.pop(name, None)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
