"""Exit codes and the error classes every command shares.

One convention for every ``vtoladapt`` command (README "When things go wrong"):

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
====  ==========================================================================================

Every error is reported as one line on stderr naming the file, the field and the value (see
:func:`one_line`); ``--debug`` adds the traceback.
"""
from __future__ import annotations

import errno
from enum import IntEnum

from .config import ConfigError

__all__ = ["ConfigError", "ExitCode", "RunFailed", "exit_code_for", "one_line"]


class ExitCode(IntEnum):
    """The process exit status of every ``vtoladapt`` command."""

    OK = 0
    RUN_FAILED = 1
    BAD_INPUT = 2
    NOT_CONVERGED = 3
    INTERRUPTED = 130


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
