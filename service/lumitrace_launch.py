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
    from lumitrace.cli import main as cli_main
    from lumitrace.quick_exit import finish

    return finish(cli_main(early_signals=_early))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
