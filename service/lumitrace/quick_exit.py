"""The end of a command's process: exit without the interpreter's teardown once the
command is done (the ``lumitrace`` command, ``python -m lumitrace``)."""
import atexit
import os
import sys
import threading


def finish(code: int) -> int:
    """End the process with ``code`` once the command is done, without the interpreter's
    teardown: the streams are flushed and the exit handlers run, then the process exits
    at once. Finalising USD's and numpy's modules takes about 30 ms and writes nothing.
    Where a thread the usual exit waits for (not a daemon) still runs, or a stream cannot
    be flushed, ``code`` is returned, to exit the usual way (which waits for the thread, or
    reports the stream). A daemon thread is left as the usual exit leaves it, but for what
    the exit handlers wait for (the schema registry's build, :mod:`lumitrace.schema`)."""
    if any(not t.daemon for t in threading.enumerate() if t is not threading.main_thread()):
        return code
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):
        return code
    atexit._run_exitfuncs()
    os._exit(code)

