"""The probe package's exception class."""
from __future__ import annotations

import numpy as np

from vtoladapt.config import ConfigError


class ProbeError(ConfigError):
    """A probe data file, calibration file or probe setting is invalid.

    The message names the file (or object), the row or field, the offending value and what is
    allowed. It subclasses :class:`vtoladapt.config.ConfigError` (itself a ``ValueError``), so
    callers catching the project's configuration error also catch this one.
    """


def require_number(where: str, name: str, value, *, gt=None, ge=None, lt=None, le=None,
                   unit: str = "") -> float:
    """Check that ``value`` is a finite real number within bounds; return it as ``float``.

    Parameters
    ----------
    where : str
        The file or object the value belongs to (first part of the message).
    name : str
        The field name.
    value : object
        The value to check.
    gt, ge, lt, le : float, optional
        Strict / non-strict lower and upper bounds.
    unit : str
        Unit shown in the message.

    Raises
    ------
    ProbeError
        Naming ``where``, ``name``, the value and the allowed range.
    """
    parts = []
    for bound, sym in ((gt, ">"), (ge, ">="), (lt, "<"), (le, "<=")):
        if bound is not None:
            parts.append(f"{sym} {bound:g}")
    allowed = ("a finite number " + " and ".join(parts)).strip() + (f" ({unit})" if unit else "")
    if isinstance(value, bool):
        raise ProbeError(f"{where}: {name} = {value!r}: not allowed; allowed: {allowed}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ProbeError(f"{where}: {name} = {value!r}: not a number; allowed: {allowed}") from None
    ok = np.isfinite(x)
    ok = ok and (gt is None or x > gt) and (ge is None or x >= ge)
    ok = ok and (lt is None or x < lt) and (le is None or x <= le)
    if not ok:
        raise ProbeError(f"{where}: {name} = {value!r}: out of range; allowed: {allowed}")
    return x
