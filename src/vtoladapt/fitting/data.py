"""Force-balance data: the CSV format, its reader/validator and writer.

The CSV format (``read_force_balance_csv`` / ``write_force_balance_csv``)
-----------------------------------------------------------------------
One row per tunnel point (a steady reading of the balance, averaged over the dwell). Lines that
start with ``#`` and blank lines are ignored; the first other line is the header. Column order
is free; every column named below must be spelled exactly so; any other column is an error (a
misspelled optional column must not be silently ignored).

Required columns

=================  ======  ===============================================================
column             unit    meaning and allowed values
=================  ======  ===============================================================
``airspeed_mps``   m/s     tunnel airspeed V, ``>= 0`` (0 for static thrust runs)
``alpha_deg``      deg     angle of attack of the body x axis, ``-90 < alpha < 90``
``beta_deg``       deg     sideslip, ``-90 < beta < 90``
``throttle_x_pct`` %       pusher throttle u_x, ``0 <= u_x <= 100``
``throttle_z_pct`` %       collective throttle u_z of the lift rotors, ``0 <= u_z <= 100``
``force_x_N``      N       measured force on the model, body FRD x (forward)
``force_y_N``      N       measured force, body FRD y (right)
``force_z_N``      N       measured force, body FRD z (down)
=================  ======  ===============================================================

Optional columns

=====================  ======  ==========================================================
``air_density_kgpm3``  kg/m^3  air density of the row, ``> 0``; default: the vehicle's
                               reference density (``[envelope] air_density_kgpm3``)
``mass_kg``            kg      the flight mass the per-unit-mass coefficients refer to,
                               ``> 0``; the same in every row; default: the vehicle's mass
``wing_on``            0 / 1   1 (default) if the wing is on the balance; 0 for a
                               propulsion-only test (rotors on the balance, no wing)
``label``              text    free text (run name); kept, not used by the fit
=====================  ======  ==========================================================

Conventions
-----------
* Forces are the aerodynamic and propulsive force only, in newtons, body FRD axes: tare the
  balance with the wind off and the motors off, so weight is not in the reading. The fit
  divides them by the flight mass to get the paper's per-unit-mass model (Table I, m/s^2).
* The incident velocity is ``v_i_B = V [cos(a) cos(b), sin(b), sin(a) cos(b)]`` (eq:alphabeta).
* Throttle is in percent, as in Table I. Rotor-speed data convert with ``u = 100 n / n_full``
  (``n_full`` the speed at full throttle): the model assumes rotor speed linear in throttle.
* The propulsion columns refer to the whole set: the four lift rotors at the collective
  ``throttle_z_pct`` and the pusher at ``throttle_x_pct``. A single-rotor test of one of four
  identical lift rotors is entered with its forces multiplied by 4.
* All forces in the model are proportional to air density (thrust eq:model_T, rotor side force
  eq:model_Fs, wing through the dynamic pressure), so a row measured at density rho counts with
  its regressor scaled by ``rho / rho_ref`` and the fitted coefficients refer to ``rho_ref``.

Example::

    # caltech_vtol virtual tunnel, seed 0
    airspeed_mps,alpha_deg,beta_deg,throttle_x_pct,throttle_z_pct,force_x_N,force_y_N,force_z_N,wing_on
    0,0,0,50,0,12.91,0.004,-0.011,1
    9,5,0,0,0,-0.83,0.012,-8.71,1
    9,-30,0,0,60,-0.94,-0.03,-17.6,0
"""
from __future__ import annotations

import csv
import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import ConfigError

REQUIRED_COLUMNS = ("airspeed_mps", "alpha_deg", "beta_deg", "throttle_x_pct", "throttle_z_pct",
                    "force_x_N", "force_y_N", "force_z_N")
OPTIONAL_COLUMNS = ("air_density_kgpm3", "mass_kg", "wing_on", "label")
ALL_COLUMNS = REQUIRED_COLUMNS + OPTIONAL_COLUMNS

FORCE_MAX_N = 1e4
"""Largest force-balance reading: a 150 kg aircraft (the heaviest vehicle) at 6 g is 8.8 kN. The other
columns take the vehicle file's ranges (mass 0.1-150 kg, air 0.3-2 kg/m^3) and a small UAS's
airspeeds (<= 100 m/s); a reading of 1e300 N overflowed the fit into an internal LinAlgError."""

# column -> (lower, lower inclusive, upper, upper inclusive, unit); None = unbounded
_RANGES = {
    "airspeed_mps": (0.0, True, 100.0, True, "m/s"),
    "alpha_deg": (-90.0, False, 90.0, False, "deg"),
    "beta_deg": (-90.0, False, 90.0, False, "deg"),
    "throttle_x_pct": (0.0, True, 100.0, True, "%"),
    "throttle_z_pct": (0.0, True, 100.0, True, "%"),
    "force_x_N": (-FORCE_MAX_N, True, FORCE_MAX_N, True, "N"),
    "force_y_N": (-FORCE_MAX_N, True, FORCE_MAX_N, True, "N"),
    "force_z_N": (-FORCE_MAX_N, True, FORCE_MAX_N, True, "N"),
    "air_density_kgpm3": (0.3, True, 2.0, True, "kg/m^3"),
    "mass_kg": (0.1, True, 150.0, True, "kg"),
}


class FitDataError(ConfigError):
    """A force-balance file or data set is invalid; the message names file, line, column and value.

    Subclasses :class:`vtoladapt.config.ConfigError` (a ``ValueError``).
    """


def _allowed(col: str) -> str:
    lo, lo_inc, hi, hi_inc, unit = _RANGES[col]
    parts = []
    if lo is not None:
        parts.append(f"{col} {'>=' if lo_inc else '>'} {lo:g}")
    if hi is not None:
        parts.append(f"{col} {'<=' if hi_inc else '<'} {hi:g}")
    return (" and ".join(parts) or "any finite number") + f" ({unit})"


def _in_range(col: str, value: float) -> bool:
    lo, lo_inc, hi, hi_inc, _ = _RANGES[col]
    if lo is not None and not (value >= lo if lo_inc else value > lo):
        return False
    if hi is not None and not (value <= hi if hi_inc else value < hi):
        return False
    return True


@dataclass(frozen=True, eq=False)
class ForceBalanceData:
    """Force-balance tunnel points (see the module docstring for the meaning of each field).

    Parameters
    ----------
    airspeed_mps, alpha_rad, beta_rad, throttle_x_pct, throttle_z_pct : numpy.ndarray, shape (N,)
        Operating point of each row (angles in radians here; degrees in the file).
    force_B_N : numpy.ndarray, shape (N, 3)
        Measured body FRD force, N.
    air_density_kgpm3 : numpy.ndarray, shape (N,), or None
        Per-row density; ``None`` means "the vehicle's reference density".
    mass_kg : float or None
        Flight mass the per-unit-mass model refers to; ``None`` means "the vehicle's mass".
    wing_on : numpy.ndarray of bool, shape (N,)
        False for propulsion-only rows.
    label : tuple of str, or None
    source : str
        File or description, used in messages.
    line_numbers : numpy.ndarray of int, shape (N,)
        Line of each row in the source file (1-based), for messages.
    comments : tuple of str
        The file's ``#`` lines (without the ``#``).
    """

    airspeed_mps: np.ndarray
    alpha_rad: np.ndarray
    beta_rad: np.ndarray
    throttle_x_pct: np.ndarray
    throttle_z_pct: np.ndarray
    force_B_N: np.ndarray
    air_density_kgpm3: np.ndarray | None = None
    mass_kg: float | None = None
    wing_on: np.ndarray | None = None
    label: tuple[str, ...] | None = None
    source: str = "<data>"
    line_numbers: np.ndarray | None = None
    comments: tuple[str, ...] = field(default=())

    def __post_init__(self):
        n = np.asarray(self.airspeed_mps).shape[0]
        for name in ("airspeed_mps", "alpha_rad", "beta_rad", "throttle_x_pct", "throttle_z_pct"):
            arr = np.asarray(getattr(self, name), dtype=float)
            if arr.shape != (n,):
                raise FitDataError(f"{self.source}: {name} must have shape ({n},), got {arr.shape}")
            object.__setattr__(self, name, arr)
        F = np.asarray(self.force_B_N, dtype=float)
        if F.shape != (n, 3):
            raise FitDataError(f"{self.source}: force_B_N must have shape ({n}, 3), got {F.shape}")
        object.__setattr__(self, "force_B_N", F)
        if self.air_density_kgpm3 is not None:
            rho = np.asarray(self.air_density_kgpm3, dtype=float)
            if rho.shape != (n,):
                raise FitDataError(f"{self.source}: air_density_kgpm3 must have shape ({n},)")
            object.__setattr__(self, "air_density_kgpm3", rho)
        wing = np.ones(n, bool) if self.wing_on is None else np.asarray(self.wing_on, bool)
        if wing.shape != (n,):
            raise FitDataError(f"{self.source}: wing_on must have shape ({n},)")
        object.__setattr__(self, "wing_on", wing)
        lines = (np.arange(n) + 2 if self.line_numbers is None
                 else np.asarray(self.line_numbers, dtype=int))
        object.__setattr__(self, "line_numbers", lines)
        if n == 0:
            raise FitDataError(f"{self.source}: no data rows")

    @property
    def n_rows(self) -> int:
        """Number of balance readings."""
        return int(self.airspeed_mps.shape[0])

    @property
    def v_i_B(self) -> np.ndarray:
        """Incident velocity in body axes (N, 3), m/s, from V, alpha, beta (eq:alphabeta)."""
        return incident_velocity_from_angles(self.airspeed_mps, self.alpha_rad, self.beta_rad)

    def density(self, rho_ref_kgpm3: float) -> np.ndarray:
        """Per-row density, ``rho_ref_kgpm3`` where the file gives none."""
        if self.air_density_kgpm3 is None:
            return np.full(self.n_rows, float(rho_ref_kgpm3))
        return self.air_density_kgpm3.copy()

    def subset(self, rows) -> "ForceBalanceData":
        """The rows selected by an index or boolean mask, as a new data set."""
        idx = np.arange(self.n_rows)[rows]
        return ForceBalanceData(
            airspeed_mps=self.airspeed_mps[idx], alpha_rad=self.alpha_rad[idx],
            beta_rad=self.beta_rad[idx], throttle_x_pct=self.throttle_x_pct[idx],
            throttle_z_pct=self.throttle_z_pct[idx], force_B_N=self.force_B_N[idx],
            air_density_kgpm3=None if self.air_density_kgpm3 is None else self.air_density_kgpm3[idx],
            mass_kg=self.mass_kg, wing_on=self.wing_on[idx],
            label=None if self.label is None else tuple(self.label[i] for i in idx),
            source=self.source, line_numbers=self.line_numbers[idx], comments=self.comments)


def incident_velocity_from_angles(V_mps, alpha_rad, beta_rad) -> np.ndarray:
    """``v_i_B = V [cos a cos b, sin b, sin a cos b]`` (N, 3): the inverse of eq:alphabeta."""
    V = np.asarray(V_mps, float)
    a = np.asarray(alpha_rad, float)
    b = np.asarray(beta_rad, float)
    return np.stack([V * np.cos(a) * np.cos(b), V * np.sin(b), V * np.sin(a) * np.cos(b)], axis=-1)


def _parse_number(raw: str, col: str, where: str) -> float:
    text = raw.strip()
    if text == "":
        raise FitDataError(f"{where}, column '{col}': empty value; allowed: {_allowed(col)}")
    try:
        value = float(text)
    except ValueError:
        raise FitDataError(
            f"{where}, column '{col}': value {raw!r} is not a number; allowed: {_allowed(col)}"
        ) from None
    if not math.isfinite(value):
        raise FitDataError(
            f"{where}, column '{col}': value {raw!r} is not finite (NaN or infinite); "
            f"allowed: {_allowed(col)}")
    if not _in_range(col, value):
        raise FitDataError(f"{where}, column '{col}': value {raw!r} out of range; allowed: {_allowed(col)}")
    return value


def _parse_flag(raw: str, col: str, where: str) -> bool:
    text = raw.strip().lower()
    if text in ("1", "1.0", "true", "yes"):
        return True
    if text in ("0", "0.0", "false", "no"):
        return False
    raise FitDataError(f"{where}, column '{col}': value {raw!r} is not a flag; allowed: 0 or 1")


def read_force_balance_csv(path: str | Path) -> ForceBalanceData:
    """Read and validate a force-balance CSV file (format in the module docstring).

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    ForceBalanceData

    Raises
    ------
    FitDataError
        On a missing, duplicated or unknown column, a row with the wrong number of fields, an
        empty, non-numeric, NaN or out-of-range value, or a ``mass_kg`` that differs between rows.
        The message names the file, the line (and data row) and the column.
    """
    path = Path(path)
    src = str(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise FitDataError(f"{src}: file not found") from None
    except UnicodeDecodeError as exc:
        raise FitDataError(f"{src}: not a UTF-8 text file ({exc})") from None
    comments: list[str] = []
    header: list[str] | None = None
    header_line = 0
    rows: list[tuple[int, list[str]]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            if header is None:
                comments.append(stripped[1:].strip())
            continue
        fields = next(csv.reader([line]))
        if header is None:
            header, header_line = [f.strip() for f in fields], lineno
        else:
            rows.append((lineno, fields))
    if header is None:
        raise FitDataError(f"{src}: no header line; required columns: {', '.join(REQUIRED_COLUMNS)}")
    seen = set()
    for col in header:
        if col in seen:
            raise FitDataError(f"{src}: line {header_line}: column '{col}' appears twice in the header")
        seen.add(col)
        if col not in ALL_COLUMNS:
            close = difflib.get_close_matches(col, ALL_COLUMNS, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise FitDataError(
                f"{src}: line {header_line}: unknown column '{col}'{hint}; allowed columns: "
                f"{', '.join(ALL_COLUMNS)}")
    missing = [c for c in REQUIRED_COLUMNS if c not in seen]
    if missing:
        raise FitDataError(
            f"{src}: line {header_line}: missing required column '{missing[0]}'"
            + (f" (also missing: {', '.join(missing[1:])})" if len(missing) > 1 else "")
            + f"; header has: {', '.join(header)}")
    if not rows:
        raise FitDataError(f"{src}: no data rows after the header (line {header_line})")
    col_index = {c: i for i, c in enumerate(header)}
    numeric = [c for c in header if c in _RANGES]
    values = {c: np.empty(len(rows)) for c in numeric}
    wing = np.ones(len(rows), bool)
    labels: list[str] = []
    lines = np.empty(len(rows), int)
    for k, (lineno, fields) in enumerate(rows):
        where = f"{src}: line {lineno} (data row {k + 1})"
        if len(fields) != len(header):
            raise FitDataError(
                f"{where}: has {len(fields)} fields, the header (line {header_line}) has "
                f"{len(header)}")
        lines[k] = lineno
        for c in numeric:
            values[c][k] = _parse_number(fields[col_index[c]], c, where)
        if "wing_on" in col_index:
            wing[k] = _parse_flag(fields[col_index["wing_on"]], "wing_on", where)
        if "label" in col_index:
            labels.append(fields[col_index["label"]].strip())
    mass = None
    if "mass_kg" in values:
        m = values["mass_kg"]
        bad = np.nonzero(m != m[0])[0]
        if bad.size:
            j = int(bad[0])
            raise FitDataError(
                f"{src}: line {lines[j]} (data row {j + 1}), column 'mass_kg': value {m[j]:g} differs "
                f"from {m[0]:g} on line {lines[0]}; the per-unit-mass model refers to one flight "
                "mass, so mass_kg must be the same in every row")
        mass = float(m[0])
    deg = np.pi / 180.0
    return ForceBalanceData(
        airspeed_mps=values["airspeed_mps"], alpha_rad=values["alpha_deg"] * deg,
        beta_rad=values["beta_deg"] * deg, throttle_x_pct=values["throttle_x_pct"],
        throttle_z_pct=values["throttle_z_pct"],
        force_B_N=np.stack([values["force_x_N"], values["force_y_N"], values["force_z_N"]], axis=1),
        air_density_kgpm3=values.get("air_density_kgpm3"), mass_kg=mass, wing_on=wing,
        label=tuple(labels) if "label" in col_index else None, source=src, line_numbers=lines,
        comments=tuple(comments))


def write_force_balance_csv(path: str | Path, data: ForceBalanceData,
                            comments: tuple[str, ...] | list[str] = ()) -> Path:
    """Write ``data`` in the CSV format of this module (optional columns only when present).

    Numbers are written with 10 significant digits (well below any balance's resolution).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cols = list(REQUIRED_COLUMNS)
    if data.air_density_kgpm3 is not None:
        cols.append("air_density_kgpm3")
    if data.mass_kg is not None:
        cols.append("mass_kg")
    cols.append("wing_on")
    if data.label is not None:
        cols.append("label")
    rad = 180.0 / np.pi
    with path.open("w", newline="", encoding="utf-8") as fh:
        for c in comments:
            fh.write(f"# {c}\n")
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(cols)
        for i in range(data.n_rows):
            row = {
                "airspeed_mps": data.airspeed_mps[i], "alpha_deg": data.alpha_rad[i] * rad,
                "beta_deg": data.beta_rad[i] * rad, "throttle_x_pct": data.throttle_x_pct[i],
                "throttle_z_pct": data.throttle_z_pct[i], "force_x_N": data.force_B_N[i, 0],
                "force_y_N": data.force_B_N[i, 1], "force_z_N": data.force_B_N[i, 2],
            }
            if data.air_density_kgpm3 is not None:
                row["air_density_kgpm3"] = data.air_density_kgpm3[i]
            if data.mass_kg is not None:
                row["mass_kg"] = data.mass_kg
            row["wing_on"] = int(bool(data.wing_on[i]))
            out = []
            for c in cols:
                v = row.get(c)
                if c == "label":
                    out.append(data.label[i])
                elif c == "wing_on":
                    out.append(str(v))
                else:
                    out.append(f"{float(v):.10g}")
            writer.writerow(out)
    return path


__all__ = ["ALL_COLUMNS", "FitDataError", "ForceBalanceData", "OPTIONAL_COLUMNS", "REQUIRED_COLUMNS",
           "incident_velocity_from_angles", "read_force_balance_csv", "write_force_balance_csv"]
