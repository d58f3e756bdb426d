"""Which kind of vtoladapt TOML file a file is, so that one given where another kind is expected is
named as what it is, in one line (issue #37: a vehicle file given to ``vtoladapt run`` was reported
as ``basis = 'paper': unknown key``, a message about a key of a file the user never meant as a scenario).

Four kinds of TOML file: a scenario, a vehicle, a campaign and a tuned settings file. Each is
recognised by keys or tables only it has (:data:`MARKS`). A file is called another kind only if it
has marks of that kind and none of the expected kind's: a scenario with one misspelt key is still
reported as a scenario with an unknown key.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Optional

from .config import ConfigError

MARKS: dict[str, tuple[str, ...]] = {
    # top-level keys and tables each kind alone has ("[x]" a table, "[[x]]" a list of tables)
    "scenario": ("duration_s", "dt_control_s", "plant_substeps", "[initial]", "[reference]", "[wind]",
                 "[sensors]", "[controller]", "[controller_prior]", "[experiment]", "[allocation]", "[[faults]]",
                 "[output]"),
    "vehicle": ("basis", "effectiveness", "[mass]", "[geometry]", "[force_model]", "[force_model_std]",
                "[adaptation]", "[actuators]", "[uncertainty]", "[[surfaces]]", "[basis_settings]"),
    "campaign": ("[campaign]",),
    "tuned settings": ("[tuning]",),
}

USES: dict[str, str] = {
    "scenario": "run it with: vtoladapt run {path} --out DIR",
    "vehicle": "fly it with: vtoladapt run SCENARIO --vehicle {path} --out DIR",
    "campaign": "run it with: vtoladapt campaign {path} --out DIR",
    "tuned settings": "fly it with: vtoladapt run SCENARIO --tuned {path} --out DIR",
}
"""What to do with a file of each kind instead (``{path}``: the file)."""


def _marks_present(data: Mapping[str, Any], kind: str) -> list[str]:
    found = []
    for mark in MARKS[kind]:
        key = mark.strip("[]")
        if key in data:
            found.append(mark)
    return found


def file_kind(data: Mapping[str, Any], expected: Optional[str] = None) -> Optional[tuple[str, list[str]]]:
    """``(kind, the marks found)`` of a parsed file, or None if it is ``expected`` or no kind is clear.

    The campaign and tuned-settings tables decide alone (a tuned file also holds a ``[controller]``
    table, a scenario's mark); otherwise a file with marks of ``expected`` is taken to be one.
    """
    if not isinstance(data, Mapping):
        return None
    for kind in ("campaign", "tuned settings"):
        marks = _marks_present(data, kind)
        if marks:
            return None if kind == expected else (kind, marks)
    if expected in MARKS and _marks_present(data, expected):
        return None
    for kind in ("scenario", "vehicle"):
        marks = _marks_present(data, kind)
        if marks and kind != expected:
            return kind, marks
    return None


def check_file_kind(path: str | Path, data: Mapping[str, Any], expected: str, takes: str) -> None:
    """A one-line :class:`ConfigError` if ``data`` (parsed from ``path``) is plainly a file of another
    kind than ``expected``: ``FILE: this is a vehicle file (it has basis, [mass]); <takes> takes a
    scenario file; fly it with: ...``. ``takes`` names what was given the file (``vtoladapt run``,
    ``--vehicle``, ``load_scenario``)."""
    found = file_kind(data, expected)
    if found is None:
        return
    kind, marks = found
    shown = ", ".join(marks[:4]) + (", ..." if len(marks) > 4 else "")
    raise ConfigError(f"{path}: this is a {kind} file (it has {shown}); {takes} takes a {expected} file; "
                      + USES[kind].format(path=path))


__all__ = ["MARKS", "USES", "check_file_kind", "file_kind"]
