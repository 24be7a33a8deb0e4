"""A command's process ends without the interpreter's teardown (:mod:`lumitrace.quick_exit`):
its exit status, its output and its exit handlers as the usual exit has them, and the usual
exit where a thread still runs."""
import subprocess
import sys
import textwrap


def _run(body: str) -> subprocess.CompletedProcess:
    code = textwrap.dedent("""
        import atexit, sys, threading, time
        from lumitrace.quick_exit import finish
        atexit.register(lambda: print("handler ran", flush=True))
    """) + textwrap.dedent(body)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)


def test_the_status_the_output_and_the_exit_handlers_are_kept():
    p = _run("""
        print("unflushed", end="")
        sys.stderr.write("said")
        sys.exit(finish(3))
        print("never")
    """)
    assert p.returncode == 3
    assert p.stdout == "unflushedhandler ran\n"
    assert p.stderr == "said"


def test_it_exits_at_once_with_the_status():
    p = _run("""
        import os
        class Late:
            def __del__(self):  # a module's teardown: not reached on the quick way out
                os.write(1, b"teardown")
        keep = Late()
        sys.exit(finish(0))
    """)
    assert (p.returncode, p.stdout) == (0, "handler ran\n")


def test_a_running_thread_is_waited_for_as_by_the_usual_exit():
    p = _run("""
        threading.Thread(target=lambda: (time.sleep(0.3), print("thread done", flush=True))
                         ).start()
        sys.exit(finish(4))
    """)
    assert p.returncode == 4
    assert p.stdout == "thread done\nhandler ran\n"


def test_a_daemon_thread_does_not_hold_the_quick_exit_and_the_handlers_still_run():
    p = _run("""
        import os
        class Late:
            def __del__(self):
                os.write(1, b"teardown")
        keep = Late()
        threading.Thread(target=time.sleep, args=(30,), daemon=True).start()
        joined = threading.Thread(target=lambda: (time.sleep(0.3), print("joined", flush=True)),
                                  daemon=True)
        joined.start()
        atexit.register(joined.join)  # as the schema registry's build is
        sys.exit(finish(5))
    """)
    assert (p.returncode, p.stdout) == (5, "joined\nhandler ran\n")
