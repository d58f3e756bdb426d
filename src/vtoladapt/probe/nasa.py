"""Reader for the NASA five-hole probe calibration files (Aeroprobe "PCF" format).

Source
------
NASA multihole-probe-calibration repository, https://github.com/nasa/multihole-probe-calibration
(``dataset/5Hole-Probe2 Aeroprobe/From Aaron-Set1/``), NASA Open Source Agreement 1.3.
Reference: Mirhashemi, Juangphanich & Miki, "Application of Machine Learning Techniques in
Calibration and Data Reduction of Multi-Hole Probes", ASME Turbo Expo 2024. Three files are vendored
in the repository's ``data/nasa-multihole-probe/`` with their SOURCE.md (origin, commit, licence).

Format
------
Tab-separated text; ``NHL`` header lines (``key=value``, the last one the column names), then
``CalPts`` calibration rows followed by ``TstPts`` test rows with the columns ``Theta[deg]``
(cone angle), ``Phi[deg]`` (roll angle), ``P1..P6[Torr]`` (P1 centre hole, P2..P5 peripheral
holes, P6 the probe's static port; gauge relative to free-stream static), ``Pt[Torr]``
(free-stream total minus static, the compressible dynamic pressure ``q_c``), ``Ps[Abs,Torr]``
and ``Ts[C]`` (static pressure and temperature).

Mapping to the probe's three differential pressures and to alpha/beta (verified from the data)
------------------------------------------------------------------------------------------------
* ``q_inf = P1 - P6`` (centre hole against the probe's own static port: what a sensor between
  the centre port and a static port reads in flight, where no free-stream static exists),
  ``q_alpha = P2 - P3``, ``q_beta = P4 - P5``.
* ``alpha``, ``beta`` from ``tan(alpha) = tan(Theta) cos(Phi)``, ``sin(beta) = sin(Theta)
  sin(Phi)`` (:func:`vtoladapt.probe.flow.cone_roll_to_alpha_beta`).

Why: with ``n = v_i / V`` from that mapping and ``q_dyn = rho V^2 / 2``, a least-squares fit
over the points with ``Theta < 6 deg`` gives, for probe 16328-1 at Mach 0.05,
``q_alpha / q_dyn = 0.018 + 3.311 n_z + 0.028 n_y`` and
``q_beta / q_dyn = -0.022 - 0.018 n_z + 3.317 n_y`` (16328-1 at Mach 0.10: 3.391, 0.051 and
-0.031, 3.410; 16328-2 at Mach 0.05: 3.392, 0.057 and -0.021, 3.366). Hole P2 faces the flow at
``Phi = 0`` and P3 at ``Phi = 180 deg``, P4 at ``Phi = +90 deg`` and P5 at ``Phi = -90 deg``;
the cross-talk is 0.5-1.7 % (a roll misalignment of the port pairs of 0.3-1 deg) and the
zero-angle offsets up to about 0.5 deg, both of which a calibration absorbs (eq:aoa's single ``k``
cannot). Also, ``sign(q_alpha) = sign(alpha)`` and ``sign(q_beta) = sign(beta)`` at every point
more than 1 deg from zero, in all three files. So the P2-P3 pair responds to the
``cos(Phi)`` component with positive sign and the P4-P5 pair to the ``sin(Phi)`` component with
positive sign. Mounting the probe with P2 at the bottom (body +z) and P4 on the right (body +y)
makes ``Phi = 0`` a positive angle of attack (air from below) and ``Phi = +90 deg`` a positive
sideslip (air from the right), i.e. the mapping above, with ``q_alpha``, ``q_beta`` having the
signs eq:aoa needs. The handedness of the AP numbering (whether P4 is clockwise or
anticlockwise of P2 seen from the front) cannot be seen in the pressures of an axisymmetric
probe; the mapping defines the mounting rather than assuming it. ``tests/test_probe_nasa.py``
checks these signs and the cross-talk on all three files.

True airspeed and density: ``rho = Ps / (R T)`` with ``R = 287.05 J/(kg K)``; the Mach number
from the isentropic relation ``Pt / Ps = (1 + 0.2 M^2)^3.5 - 1`` and ``V = M sqrt(1.4 R T)``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from vtoladapt.probe.points import ProbeCalibrationData
from vtoladapt.probe.errors import ProbeError
from vtoladapt.probe.flow import cone_roll_to_alpha_beta

TORR_PA = 101325.0 / 760.0
"""One Torr in pascal."""
R_AIR = 287.05
"""Specific gas constant of dry air, J/(kg K)."""
GAMMA_AIR = 1.4
"""Ratio of specific heats of air."""

NASA_COLUMNS = ("Theta[deg]", "Phi[deg]", "P1[Torr]", "P2[Torr]", "P3[Torr]", "P4[Torr]",
                "P5[Torr]", "P6[Torr]", "Pt[Torr]", "Ps[Abs,Torr]", "Ts[C]")
NASA_CITATION = ("NASA multihole-probe-calibration (github.com/nasa/multihole-probe-calibration, "
                 "NOSA 1.3); Mirhashemi, Juangphanich & Miki, ASME Turbo Expo 2024")


def _header_int(path: Path, header: dict, key: str, lineno: dict) -> int:
    if key not in header:
        raise ProbeError(f"{path}: header key {key!r} missing (a PCF file lists FileType, NHL, "
                         "..., CalPts, TstPts before the column names)")
    raw = header[key]
    try:
        value = int(raw.strip())
    except ValueError:
        raise ProbeError(f"{path}: line {lineno[key]}: {key} = {raw!r} is not a whole "
                         "number") from None
    if value < 0:
        raise ProbeError(f"{path}: line {lineno[key]}: {key} = {value}: must be >= 0")
    return value


def read_nasa_pcf(path: str | Path) -> ProbeCalibrationData:
    """Read one NASA/Aeroprobe five-hole probe calibration file (PCF) into probe data.

    Data: NASA multihole-probe-calibration repository (NOSA 1.3), Mirhashemi et al. 2024; see
    the module docstring for the format and the verified cone/roll -> alpha/beta and hole ->
    ``q_inf, q_alpha, q_beta`` mapping.

    Parameters
    ----------
    path : str or pathlib.Path
        A ``<serial>_M<mach*1000>.csv`` (or ``.pcf``) file.

    Returns
    -------
    ProbeCalibrationData
        ``is_test`` marks the last ``TstPts`` rows; ``info`` holds the serial number, the Mach
        number, the date and the citation.

    Raises
    ------
    ProbeError
        If the file is missing, is not a PCF file, lacks a column, or has a malformed row (the
        message names the file, the line and the value).
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8", errors="strict").splitlines()
    except FileNotFoundError:
        raise ProbeError(f"{path}: file not found") from None
    except UnicodeDecodeError as exc:
        raise ProbeError(f"{path}: not a text file ({exc.reason})") from None
    if not lines or not lines[0].replace(" ", "").upper().startswith("FILETYPE=PCF"):
        first = lines[0] if lines else ""
        raise ProbeError(f"{path}: line 1 = {first!r}: not an Aeroprobe PCF file (expected "
                         "'FileType=PCF')")
    header: dict[str, str] = {}
    lineno: dict[str, int] = {}
    for i, line in enumerate(lines[:64]):
        if "=" in line and "\t" not in line.split("=", 1)[0]:
            key, value = line.split("=", 1)
            header.setdefault(key.strip(), value.strip())
            lineno.setdefault(key.strip(), i + 1)
    nhl = _header_int(path, header, "NHL", lineno)
    if nhl < 2 or nhl > len(lines):
        raise ProbeError(f"{path}: line {lineno['NHL']}: NHL = {nhl}: outside 2..{len(lines)}")
    n_cal = _header_int(path, header, "CalPts", lineno)
    n_test = _header_int(path, header, "TstPts", lineno)
    names = [c.strip() for c in lines[nhl - 1].split("\t") if c.strip()]
    for name in NASA_COLUMNS:
        if name not in names:
            raise ProbeError(f"{path}: line {nhl}: missing column {name!r}; found "
                             f"{', '.join(names)}")
    idx = [names.index(c) for c in NASA_COLUMNS]
    rows = []
    for i, line in enumerate(lines[nhl:], start=nhl + 1):
        if not line.strip():
            continue
        fields = line.split()
        if len(fields) != len(names):
            raise ProbeError(f"{path}: line {i}: {len(fields)} values, expected {len(names)} "
                             f"({', '.join(names)})")
        try:
            values = [float(f) for f in fields]
        except ValueError:
            bad = next(f for f in fields if not _is_float(f))
            col = names[fields.index(bad)]
            raise ProbeError(f"{path}: line {i}, column {col!r}: value {bad!r} is not a "
                             "number") from None
        if not all(np.isfinite(values)):
            col = names[int(np.argmin(np.isfinite(values)))]
            raise ProbeError(f"{path}: line {i}, column {col!r}: value is not finite")
        rows.append([values[j] for j in idx])
    if len(rows) != n_cal + n_test:
        raise ProbeError(f"{path}: {len(rows)} data rows, but the header says CalPts = {n_cal} "
                         f"+ TstPts = {n_test}")
    d = np.array(rows, dtype=float).reshape(-1, len(NASA_COLUMNS))
    theta = np.radians(d[:, 0])
    phi = np.radians(d[:, 1])
    P = d[:, 2:8] * TORR_PA
    qc = d[:, 8] * TORR_PA
    ps = d[:, 9] * TORR_PA
    T = d[:, 10] + 273.15
    for name, arr, col in (("Pt", qc, 8), ("Ps", ps, 9), ("Ts", T, 10)):
        bad = np.flatnonzero(~(arr > 0.0))
        if bad.size:
            raise ProbeError(f"{path}: line {nhl + 1 + bad[0]}, column {NASA_COLUMNS[col]!r}: "
                             f"value {d[bad[0], col]!r} must be > 0 (absolute)")
    rho = ps / (R_AIR * T)
    mach = np.sqrt(2.0 / (GAMMA_AIR - 1.0)
                   * ((qc / ps + 1.0) ** ((GAMMA_AIR - 1.0) / GAMMA_AIR) - 1.0))
    V = mach * np.sqrt(GAMMA_AIR * R_AIR * T)
    alpha, beta = cone_roll_to_alpha_beta(theta, phi)
    q = np.column_stack([P[:, 0] - P[:, 5], P[:, 1] - P[:, 2], P[:, 3] - P[:, 4]])
    is_test = np.zeros(len(rows), dtype=bool)
    is_test[n_cal:] = True
    info = {"format": "nasa-pcf", "serial": header.get("Serial", ""),
            "mach": header.get("Mach", ""), "date": header.get("Date", ""),
            "citation": NASA_CITATION,
            "mapping": "q_inf=P1-P6, q_alpha=P2-P3, q_beta=P4-P5; "
                       "tan(alpha)=tan(Theta)cos(Phi), sin(beta)=sin(Theta)sin(Phi)"}
    return ProbeCalibrationData(source=str(path), alpha_deg=np.degrees(alpha),
                                beta_deg=np.degrees(beta), V_mps=V, rho=rho, q_Pa=q,
                                is_test=is_test, info=info)


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True
