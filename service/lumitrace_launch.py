"""The ``lumitrace`` command's entry point: signals are caught from the first instant.

Importing lumitrace loads USD, which takes a few tenths of a second and can swallow a
KeyboardInterrupt raised meanwhile (the run would then go on and publish). So this small
module, which imports only the standard library, records SIGINT, SIGTERM and SIGHUP before
lumitrace is imported, and hands them to :func:`lumitrace.cli.main`.

The recorders are set by the module's first statement, with the interpreter's built-in
``_signal`` (nothing to import): a process started with SIGINT ignored (a background job
of a shell script) loses a SIGINT only until then, during the interpreter's own start-up
(``tools/early_interrupt.py`` measures that window).
"""
import _signal

_early: list[int] = []


def _record(signum, _frame) -> None:
    _early.append(signum)


for _s in (_signal.SIGINT, _signal.SIGTERM, _signal.SIGHUP):
    _signal.signal(_s, _record)

import functools  # noqa: E402  (after the recorders: nothing comes before them)
import os  # noqa: E402
import signal  # noqa: E402
import sys  # noqa: E402


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
    before lumitrace and USD load, so that loading VTK overlaps all of the run (by
    default forked from this process, see lumitrace.photometry.solid_render.mode)."""
    if argv[1:2] != ["trace"] or any(a in ("--no-pictures", "-h", "--help") for a in argv):
        return
    module = _load_early("photometry.solid_render")
    plots = _load_early("pyplot")  # (the renderer may load pyplot before it forks)
    if module is not None:
        try:
            if plots is not None:
                plots.short_setter_docs()  # as the command line has it
            module.start_renderer(fork=True)
        except Exception:  # the command starts it itself, or draws in its own process
            pass


def _load_early(name: str):
    """The lumitrace module ``name`` (standard library only at import), loaded by its file
    under its own name before the package, which then finds it there (or the one loaded
    already); None where it cannot be."""
    full = f"lumitrace.{name}"
    if full in sys.modules:
        return sys.modules[full]
    folder = _package_folder()
    if folder is None:
        return None
    path = os.path.join(folder, *name.split(".")) + ".py"
    try:
        import importlib.util

        module_spec = importlib.util.spec_from_file_location(full, path)
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[full] = module
        module_spec.loader.exec_module(module)
        return module
    except Exception:
        sys.modules.pop(full, None)
        return None


@functools.lru_cache(maxsize=1)
def _package_folder() -> str | None:
    """lumitrace's folder, found once (without importing it)."""
    import importlib.util

    spec = importlib.util.find_spec("lumitrace")
    return os.path.dirname(spec.origin) if spec is not None and spec.origin else None


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
