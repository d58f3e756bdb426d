"""Probe calibration data: the CSV format, reading either format, and simulated calibration sweeps.

The container, :class:`~vtoladapt.probe.points.ProbeCalibrationData`, is in
:mod:`vtoladapt.probe.points` (and importable from here); the NASA/Aeroprobe reader in
:mod:`vtoladapt.probe.nasa`.

The CSV format (``read_probe_csv`` / ``write_probe_csv``)
---------------------------------------------------------
A plain comma-separated file for a user's own probe calibration, one row per tunnel point:

* lines starting with ``#`` and blank lines are ignored; the first other line is the header;
* required columns: ``alpha_deg``, ``beta_deg`` (true flow angles, deg, conventions of
  :mod:`vtoladapt.probe.flow`), ``q_inf_Pa``, ``q_alpha_Pa``, ``q_beta_Pa`` (the three
  differential pressures, Pa, port conventions of :mod:`vtoladapt.probe.tip`: ``q_inf = p_centre -
  p_static``, ``q_alpha = p_bottom - p_top``, ``q_beta = p_right - p_left``), ``rho_kgpm3``
  (air density, kg/m^3);
* exactly one of ``V_mps`` (true airspeed, m/s) or ``q_dyn_Pa`` (the tunnel's dynamic pressure
  ``rho V^2 / 2``, Pa);
* optional ``split``: ``calibration`` (also when empty) or ``test`` (held-out points);
* any other column is an error (so a misspelled ``split`` cannot silently be ignored).

Example::

    # my probe, tunnel run 2024-05-01
    alpha_deg,beta_deg,q_inf_Pa,q_alpha_Pa,q_beta_Pa,rho_kgpm3,V_mps,split
    0.0,0.0,137.8,0.02,-0.05,1.225,15.0,calibration
    5.0,0.0,135.1,24.60,0.03,1.225,15.0,test
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
from numba import njit

from vtoladapt.probe.errors import ProbeError
from vtoladapt.probe.flow import airspeed_angles_from_v_i, v_i_from_airspeed_angles
from vtoladapt.probe.nasa import read_nasa_pcf
from vtoladapt.probe.points import ProbeCalibrationData
from vtoladapt.probe.sensor import SDP33Sensor, sdp33_sensor_step
from vtoladapt.probe.tip import ProbeTip, probe_differential_pressures

CSV_REQUIRED = ("alpha_deg", "beta_deg", "q_inf_Pa", "q_alpha_Pa", "q_beta_Pa", "rho_kgpm3")
CSV_SPEED = ("V_mps", "q_dyn_Pa")
CSV_OPTIONAL = ("split",)
SPLITS = ("calibration", "test")


# --------------------------------------------------------------------------------------------
# CSV
# --------------------------------------------------------------------------------------------

def read_probe_csv(path: str | Path) -> ProbeCalibrationData:
    """Read a probe calibration in the documented CSV format (see the module docstring).

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    ProbeCalibrationData

    Raises
    ------
    ProbeError
        On a missing file, a missing or unknown column, a row with the wrong number of fields,
        a value that is not a finite number or is out of range, or an unknown split; the message
        names the file, the line, the column and the value.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise ProbeError(f"{path}: file not found") from None
    except UnicodeDecodeError as exc:
        raise ProbeError(f"{path}: not a UTF-8 text file ({exc.reason})") from None
    rows = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        rows.append((lineno, line))
    if not rows:
        raise ProbeError(f"{path}: no header line; expected columns "
                         f"{', '.join(CSV_REQUIRED)}, one of {' or '.join(CSV_SPEED)}, "
                         "optional split")
    parsed = list(csv.reader([line for _, line in rows]))
    header = [h.strip() for h in parsed[0]]
    allowed = CSV_REQUIRED + CSV_SPEED + CSV_OPTIONAL
    for name in header:
        if name not in allowed:
            raise ProbeError(f"{path}: line {rows[0][0]}: unknown column {name!r}; allowed "
                             f"columns: {', '.join(allowed)}")
    dup = {h for h in header if header.count(h) > 1}
    if dup:
        raise ProbeError(f"{path}: line {rows[0][0]}: column {sorted(dup)[0]!r} appears twice")
    for name in CSV_REQUIRED:
        if name not in header:
            raise ProbeError(f"{path}: missing column {name!r}; required columns: "
                             f"{', '.join(CSV_REQUIRED)} and one of {' or '.join(CSV_SPEED)}")
    speed_cols = [c for c in CSV_SPEED if c in header]
    if len(speed_cols) != 1:
        found = "neither" if not speed_cols else "both"
        raise ProbeError(f"{path}: give exactly one of the columns 'V_mps' (airspeed, m/s) or "
                         f"'q_dyn_Pa' (dynamic pressure, Pa); found {found}")
    speed_col = speed_cols[0]
    col = {name: i for i, name in enumerate(header)}
    numeric = list(CSV_REQUIRED) + [speed_col]
    values = {name: [] for name in numeric}
    is_test = []
    if len(parsed) == 1:
        raise ProbeError(f"{path}: header only, no data rows")
    for (lineno, _), fields in zip(rows[1:], parsed[1:]):
        if len(fields) != len(header):
            raise ProbeError(f"{path}: line {lineno}: {len(fields)} fields, expected "
                             f"{len(header)} ({', '.join(header)})")
        for name in numeric:
            raw = fields[col[name]].strip()
            try:
                x = float(raw)
            except ValueError:
                raise ProbeError(f"{path}: line {lineno}, column {name!r}: value {raw!r} is not "
                                 "a number") from None
            if not math.isfinite(x):
                raise ProbeError(f"{path}: line {lineno}, column {name!r}: value {raw!r} is not "
                                 "finite")
            values[name].append(x)
        _check_row_ranges(path, lineno, {n: values[n][-1] for n in numeric})
        if "split" in col:
            s = fields[col["split"]].strip().lower()
            if s in ("", "calibration"):
                is_test.append(False)
            elif s == "test":
                is_test.append(True)
            else:
                raise ProbeError(f"{path}: line {lineno}, column 'split': value "
                                 f"{fields[col['split']]!r} is unknown; allowed: "
                                 "'calibration' (or empty), 'test'")
        else:
            is_test.append(False)
    rho = np.array(values["rho_kgpm3"])
    if speed_col == "V_mps":
        V = np.array(values["V_mps"])
    else:
        V = np.sqrt(2.0 * np.array(values["q_dyn_Pa"]) / rho)
    q = np.column_stack([values["q_inf_Pa"], values["q_alpha_Pa"], values["q_beta_Pa"]])
    return ProbeCalibrationData(
        source=str(path), alpha_deg=np.array(values["alpha_deg"]),
        beta_deg=np.array(values["beta_deg"]), V_mps=V, rho=rho, q_Pa=q,
        is_test=np.array(is_test, dtype=bool), info={"format": "csv"})


def _check_row_ranges(path: Path, lineno: int, row: dict) -> None:
    checks = (
        ("alpha_deg", -180.0, 180.0, "-180..180 deg"),
        ("beta_deg", -90.0, 90.0, "-90..90 deg"),
    )
    for name, lo, hi, text in checks:
        if not lo <= row[name] <= hi:
            raise ProbeError(f"{path}: line {lineno}, column {name!r}: value {row[name]!r} is out "
                             f"of range; allowed: {text}")
    for name in ("rho_kgpm3", "V_mps", "q_dyn_Pa"):
        if name in row and not row[name] > 0.0:
            raise ProbeError(f"{path}: line {lineno}, column {name!r}: value {row[name]!r} is out "
                             "of range; allowed: > 0")


def write_probe_csv(path: str | Path, data: ProbeCalibrationData, comment: str = "") -> Path:
    """Write ``data`` in the CSV format :func:`read_probe_csv` reads (with ``V_mps``, ``split``).

    Parameters
    ----------
    path : str or pathlib.Path
    data : ProbeCalibrationData
    comment : str
        Written as ``#`` comment lines at the top.

    Returns
    -------
    pathlib.Path
    """
    path = Path(path)
    with path.open("w", newline="", encoding="utf-8") as fh:
        for line in comment.splitlines():
            fh.write(f"# {line}\n")
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(list(CSV_REQUIRED) + ["V_mps", "split"])
        for i in range(len(data)):
            w.writerow([repr(float(data.alpha_deg[i])), repr(float(data.beta_deg[i])),
                        repr(float(data.q_Pa[i, 0])), repr(float(data.q_Pa[i, 1])),
                        repr(float(data.q_Pa[i, 2])), repr(float(data.rho[i])),
                        repr(float(data.V_mps[i])), "test" if data.is_test[i] else "calibration"])
    return path


def is_nasa_pcf(path: str | Path) -> bool:
    """Whether ``path`` starts like an Aeroprobe PCF file (``FileType=PCF``)."""
    try:
        with Path(path).open("r", encoding="utf-8", errors="replace") as fh:
            first = fh.readline()
    except OSError:
        return False
    return first.strip().replace(" ", "").upper().startswith("FILETYPE=PCF")


def read_probe_data(path: str | Path, fmt: str = "auto") -> ProbeCalibrationData:
    """Read probe calibration data: a NASA/Aeroprobe PCF file or the CSV format.

    Parameters
    ----------
    path : str or pathlib.Path
    fmt : {'auto', 'nasa', 'csv'}
        ``auto`` recognises a PCF file by its first line ``FileType=PCF``.

    Returns
    -------
    ProbeCalibrationData
    """
    if fmt == "auto":
        fmt = "nasa" if is_nasa_pcf(path) else "csv"
    if fmt == "nasa":
        return read_nasa_pcf(path)
    if fmt == "csv":
        return read_probe_csv(path)
    raise ProbeError(f"format = {fmt!r}: unknown; allowed: 'auto', 'nasa', 'csv'")


# --------------------------------------------------------------------------------------------
# Simulated calibration sweep
# --------------------------------------------------------------------------------------------

@njit(cache=True)
def _simulate_points(v, rho, tip, sensor, use_sensor, n_average, dt, rng, out_q):
    q_true = np.empty(3)
    reading = np.empty(3)
    state = np.empty(3)
    for i in range(v.shape[0]):
        probe_differential_pressures(v[i], rho[i], tip, q_true)
        if not use_sensor:
            for c in range(3):
                out_q[i, c] = q_true[c]
            continue
        for c in range(3):
            state[c] = q_true[c]
            out_q[i, c] = 0.0
        for _ in range(n_average):
            sdp33_sensor_step(q_true, state, sensor, dt, rng, reading)
            for c in range(3):
                out_q[i, c] += reading[c] / n_average


def polar_grid_deg(cone_max_deg: float, n_rings: int) -> tuple[np.ndarray, np.ndarray]:
    """A cone/roll calibration grid: the axis plus rings of ``6 k`` points at ``k`` steps out.

    Parameters
    ----------
    cone_max_deg : float
        Cone angle of the outer ring (deg).
    n_rings : int
        Number of rings (>= 1) besides the axis point.

    Returns
    -------
    theta_deg, phi_deg : numpy.ndarray
        ``1 + 3 n (n + 1)`` points.
    """
    theta = [0.0]
    phi = [0.0]
    for k in range(1, n_rings + 1):
        m = 6 * k
        theta += [cone_max_deg * k / n_rings] * m
        phi += list(-180.0 + 360.0 * (np.arange(m) + 0.5) / m)
    return np.array(theta), np.array(phi)


def simulate_calibration_sweep(tip: ProbeTip, rng: np.random.Generator, *,
                               sensor: SDP33Sensor | None = None, V_mps: float = 15.0,
                               rho: float = 1.225, cone_max_deg: float = 20.0,
                               n_rings: int = 12, n_test: int = 100, n_average: int = 25,
                               dt: float = 0.004) -> ProbeCalibrationData:
    """Simulate a wind-tunnel calibration of the probe with the forward model.

    Calibration points lie on :func:`polar_grid_deg`; ``n_test`` test points are drawn uniformly
    (by solid angle, approximately) inside the same cone from ``rng``. With a ``sensor``, each
    point is the mean of ``n_average`` sensor readings taken every ``dt`` after the lag settled.

    Parameters
    ----------
    tip : ProbeTip
    rng : numpy.random.Generator
        Source of the test points and the sensor noise.
    sensor : SDP33Sensor, optional
        Sensor model; ``None`` gives the exact pressures.
    V_mps, rho : float
        Tunnel airspeed (m/s) and density (kg/m^3).
    cone_max_deg : float
        Largest cone angle (deg).
    n_rings : int
        Rings of the calibration grid.
    n_test : int
        Number of test points.
    n_average : int
        Readings averaged per point when ``sensor`` is given.
    dt : float
        Time between readings (s).

    Returns
    -------
    ProbeCalibrationData
    """
    from vtoladapt.probe.flow import cone_roll_to_alpha_beta

    th_c, ph_c = polar_grid_deg(cone_max_deg, n_rings)
    u = rng.random(n_test)
    th_t = cone_max_deg * np.sqrt(u)
    ph_t = rng.uniform(-180.0, 180.0, n_test)
    th = np.concatenate([th_c, th_t])
    ph = np.concatenate([ph_c, ph_t])
    alpha, beta = cone_roll_to_alpha_beta(np.radians(th), np.radians(ph))
    n = th.size
    Vs = np.full(n, float(V_mps))
    rhos = np.full(n, float(rho))
    v = np.ascontiguousarray(v_i_from_airspeed_angles(Vs, alpha, beta))
    q = np.empty((n, 3))
    sens = sensor.to_kernel() if sensor is not None else np.zeros(7)
    _simulate_points(v, rhos, tip.to_kernel(), sens, sensor is not None, max(1, int(n_average)),
                     float(dt), rng, q)
    # recompute the angles from v so that they are exactly the ones used
    _, a2, b2 = airspeed_angles_from_v_i(v)
    is_test = np.zeros(n, dtype=bool)
    is_test[th_c.size:] = True
    return ProbeCalibrationData(
        source="simulated", alpha_deg=np.degrees(a2), beta_deg=np.degrees(b2), V_mps=Vs,
        rho=rhos, q_Pa=q, is_test=is_test,
        info={"format": "simulated", "tip": repr(tip), "sensor": repr(sensor),
              "V_mps": float(V_mps), "rho": float(rho)})
