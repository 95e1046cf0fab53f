"""How every gngdt process starts and stops: the first SIGINT, SIGTERM or SIGHUP stops it, and a
process started by `gngdt run` (or by a service, like the logger's rerun server) dies with its
parent, so that no signal and no crash ever leaves an orphan behind.

Until a service enters :func:`graceful` (its main loop, which polls :data:`STOP`), a signal
interrupts start-up where it stands (``KeyboardInterrupt``, exit 130); inside, it only sets
:data:`STOP` and the loop winds down cleanly. A SIGHUP that ``nohup`` asked to ignore stays
ignored. Loops must wait with a timeout: a signal that one of zenoh's threads received runs its
Python handler only once the main thread wakes up.
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from typing import NoReturn

# PARENT_ENV names the parent a child of `gngdt run` must not outlive (its pid)
from gngdt.services.plumbing.environment import PARENT_ENV

#: set by the first stop signal; every service loop polls it
STOP = threading.Event()
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
_PR_SET_PDEATHSIG = 1
#: how long a finished command waits for threads it did not start to end (zenoh's callbacks)
THREADS_GRACE_S = 5.0

_graceful = False
_signals_received: list[int] = []
_wake_write = -1


def _on_signal(signum: int, _frame: object) -> None:
    _signals_received.append(signum)
    # STOP is set by the relay thread: Event.set() here could take the lock of an Event.wait()
    # the main thread is inside of, and deadlock
    os.write(_wake_write, b"\0")
    if not _graceful:
        raise KeyboardInterrupt


def _relay_stop(wake_read: int) -> None:
    os.read(wake_read, 1)
    STOP.set()


def install(parent_pid: int | None = None) -> None:
    """Install the stop handlers and die with ``parent_pid`` (``GNGDT_PARENT_PID``, read by
    the CLI) when given; the CLI calls this first."""
    global _wake_write
    if _wake_write < 0:
        wake_read, _wake_write = os.pipe()
        threading.Thread(target=_relay_stop, args=(wake_read,), name="stop-signal",
                         daemon=True).start()
    for signum in STOP_SIGNALS:
        if signum == signal.SIGHUP and signal.getsignal(signum) == signal.SIG_IGN:
            continue  # started under nohup: the user asked to survive the terminal
        signal.signal(signum, _on_signal)
    os.environ.pop(PARENT_ENV, None)  # our own children get ours (`child_environment`)
    if parent_pid is not None:
        die_with_parent(parent_pid)


def die_with_parent(parent_pid: int) -> None:
    """Get SIGTERM when ``parent_pid`` (our parent) exits; exit now if it already has."""
    if sys.platform.startswith("linux"):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    if os.getppid() != parent_pid:  # the parent died before the prctl took effect
        raise SystemExit(1)


def child_environment() -> dict[str, str]:
    """The environment of a gngdt child of this process (it will die with us)."""
    return {**os.environ, PARENT_ENV: str(os.getpid())}


@contextlib.contextmanager
def graceful() -> Iterator[threading.Event]:
    """Inside, a stop signal only sets :data:`STOP` (yielded) for the service loop to see."""
    global _graceful
    _graceful = True
    try:
        yield STOP
    finally:
        _graceful = False


def stop_reason() -> str:
    """The first stop signal's name, or ``""`` if none came."""
    return signal.Signals(_signals_received[0]).name if _signals_received else ""


def _waited_for_threads() -> list[threading.Thread]:
    """The running threads Python's own exit would wait for: non-daemon, but this one."""
    return [thread for thread in threading.enumerate()
            if thread is not threading.current_thread() and not thread.daemon
            and thread.is_alive()]


def exit_process(code: int, grace_s: float = THREADS_GRACE_S) -> NoReturn:
    """Exit with ``code`` once the other threads have ended, or after ``grace_s`` seconds without
    the ones left.

    zenoh-python runs each subscriber's callback on a non-daemon thread of its own. Those end when
    the session drops the callback; a session whose router died can keep one (seen: a learner idle
    for 77 minutes after its router was killed, waiting at exit for four such threads). Python
    would wait for them forever, so the ones left after the grace are named and abandoned, once
    the ``atexit`` handlers (logging's flush among them) have run.
    """
    deadline = time.monotonic() + grace_s
    for thread in _waited_for_threads():
        thread.join(max(0.0, deadline - time.monotonic()))
    left = [thread.name for thread in _waited_for_threads()]  # any started meanwhile too
    if not left:
        sys.exit(code)
    logging.getLogger(__name__).warning(
        "exiting without %d thread(s) still running after %.0f s: %s (zenoh callbacks of a "
        "session that did not close)", len(left), grace_s, ", ".join(left))
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
