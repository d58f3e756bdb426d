"""Progress bars: one tqdm configuration for every long command (campaign, reproduce, fit-validate).

On a terminal the bar redraws ten times a second. When stderr is a file or a CI log, tqdm still
rewrites its line with carriage returns, so every redraw lands in the log: there the bar redraws at
most every 30 s, which keeps a ten-minute job's log to about twenty progress lines.
"""
from __future__ import annotations

import sys

NON_TTY_MININTERVAL_S = 30.0


def progress_bar(**kwargs):
    """A ``tqdm`` bar on stderr; ``kwargs`` go to tqdm (``total``, ``unit``, ``desc``, ...)."""
    from tqdm import tqdm

    stream = kwargs.setdefault("file", sys.stderr)
    isatty = getattr(stream, "isatty", None)
    if not (callable(isatty) and isatty()):
        kwargs.setdefault("mininterval", NON_TTY_MININTERVAL_S)
    return tqdm(**kwargs)
