"""Exit codes and the error classes every command shares.

One convention for every ``vtoladapt`` command (docs/reference/errors.md):

====  ==========================================================================================
code  meaning
====  ==========================================================================================
0     done
1     the run started but failed: it diverged, produced non-finite values, ran out of memory or
      disk, or hit an internal error (a bug: please report it with the ``--debug`` traceback)
2     bad input: a command-line flag, a configuration or data file, or an output path that is
      refused (also a path the system refuses: missing, no permission, name too long); nothing
      was run and nothing was written
3     ``fit --require-converged``: the fit finished but its convergence criteria were not met
130   interrupted (Ctrl-C); outputs completed before the interrupt are kept, no file is truncated
143   terminated (SIGTERM, e.g. a batch system's time limit): as 130, and the manifest says so
====  ==========================================================================================

Every error is reported as one line on stderr naming the file, the field and the value (see
:func:`one_line`); ``--debug`` adds the traceback.
"""
from __future__ import annotations

import errno
import signal
import sys
import threading
from contextlib import contextmanager
from enum import IntEnum
from typing import Iterator

from .config import ConfigError

__all__ = ["ConfigError", "ExitCode", "RunFailed", "Terminated", "check_interrupt", "exit_code_for",
           "interrupt_requested", "one_line", "sigint_handling"]


class ExitCode(IntEnum):
    """The process exit status of every ``vtoladapt`` command."""

    OK = 0
    RUN_FAILED = 1
    BAD_INPUT = 2
    NOT_CONVERGED = 3
    INTERRUPTED = 130
    TERMINATED = 143


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived (a batch system's time limit, ``kill``): handled as Ctrl-C is -- the run stops at
    its next chunk, completed outputs are kept and the manifest records it -- with exit code 143."""


class RunFailed(RuntimeError):
    """A run that started could not produce a valid result (e.g. it diverged); exit code 1.

    The message says what went wrong and where to look (which outputs were kept).
    """


# OSError numbers that describe the machine, not the user's input: the run failed (1), the
# input was fine.
_ENVIRONMENT_ERRNOS = {errno.ENOSPC, errno.EIO, errno.EDQUOT, errno.ENOMEM, errno.EROFS}

MAX_MESSAGE_CHARS = 600
"""Error lines are cut to this length (a pasted 100 kB value must not flood the terminal)."""


def exit_code_for(exc: BaseException) -> ExitCode:
    """The exit code an exception maps to under the convention above."""
    if isinstance(exc, Terminated):
        return ExitCode.TERMINATED
    if isinstance(exc, KeyboardInterrupt):
        return ExitCode.INTERRUPTED
    if isinstance(exc, ConfigError):
        return ExitCode.BAD_INPUT
    if isinstance(exc, OSError):
        return ExitCode.RUN_FAILED if exc.errno in _ENVIRONMENT_ERRNOS else ExitCode.BAD_INPUT
    if type(exc) is ValueError:  # the library's readers and checks flag bad values this way
        return ExitCode.BAD_INPUT
    return ExitCode.RUN_FAILED


def one_line(exc: BaseException) -> str:
    """``exc`` as a single line: what, where and the value, at most :data:`MAX_MESSAGE_CHARS`."""
    if isinstance(exc, (ConfigError, RunFailed)) or type(exc) is ValueError:
        text = str(exc)
    elif isinstance(exc, OSError):
        name = exc.filename if exc.filename is not None else ""
        name = str(name)
        if len(name) > 120:
            name = name[:60] + "..." + name[-40:]
        text = f"{name}: {exc.strerror or exc}" if name else str(exc.strerror or exc)
    elif isinstance(exc, MemoryError):
        text = "ran out of memory (a size or duration beyond what this machine holds)"
    elif isinstance(exc, KeyboardInterrupt):
        text = "interrupted"
    else:
        text = f"internal error {type(exc).__name__}: {exc} (rerun with --debug for the traceback " \
               "and please report it)"
    text = " ".join(text.split())  # one line: no newlines, tabs or runs of spaces
    if len(text) > MAX_MESSAGE_CHARS:
        text = text[:MAX_MESSAGE_CHARS - 3] + "..."
    return text


# --- Ctrl-C ----------------------------------------------------------------------------------------
# Python raises KeyboardInterrupt wherever the main thread happens to be when SIGINT arrives. Inside
# a callback from C -- llvmlite's object-cache notification during every Numba compile is one --
# the exception is printed as "Exception ignored" and dropped, and the command would go on to the
# end and exit 0. The request is therefore also kept here, and the simulator checks it between
# chunks (in every worker thread too), so a dropped interrupt stops the run at the next chunk.
_INTERRUPT = threading.Event()


def interrupt_requested() -> bool:
    """Whether Ctrl-C was pressed while :func:`sigint_handling` was active."""
    return _INTERRUPT.is_set()


def check_interrupt() -> None:
    """Raise :class:`KeyboardInterrupt` if Ctrl-C was pressed (call it between units of work)."""
    if _INTERRUPT.is_set():
        raise KeyboardInterrupt


def _on_sigint(signum, frame) -> None:
    _INTERRUPT.set()
    raise KeyboardInterrupt


def _on_sigterm(signum, frame) -> None:
    _INTERRUPT.set()
    raise Terminated


@contextmanager
def sigint_handling(ignore_after: bool = False) -> Iterator[None]:
    """Within the block, Ctrl-C raises KeyboardInterrupt *and* is remembered (:func:`check_interrupt`).

    After the block the previous handler is back, or, with ``ignore_after``, Ctrl-C is ignored
    for good: the console command's choice once its exit status is decided, because the
    interpreter's teardown (seconds of freeing compiled kernels) runs with SIGINT's default
    action restored, and a Ctrl-C then would kill the process by the signal (status -2 in place
    of the command's own); an ignored signal stays ignored through the teardown.
    SIGTERM is handled the same way (raising :class:`Terminated`), so a terminated command ends as an
    interrupted one does instead of leaving its manifest at "running"; after the block it is back
    to what it was (ignored too with ``ignore_after``).
    Only the main thread can own a signal handler; elsewhere the block changes nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous_term = signal.signal(signal.SIGTERM, _on_sigterm)
    previous = signal.signal(signal.SIGINT, _on_sigint)
    previous_hook = sys.unraisablehook

    def quiet_dropped_interrupt(unraisable) -> None:
        # the dropped KeyboardInterrupt's traceback is noise: the request is kept and honoured
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            previous_hook(unraisable)

    sys.unraisablehook = quiet_dropped_interrupt
    _INTERRUPT.clear()
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN if ignore_after else previous)
        signal.signal(signal.SIGTERM, signal.SIG_IGN if ignore_after else previous_term)
        sys.unraisablehook = previous_hook
        _INTERRUPT.clear()
