"""Probe calibrations: the paper's single ``k`` and our spline calibration; fit, save, evaluate.

Two models behind one interface (``to_kernel()``, ``estimate(q, rho)``, ``to_dict()``), named in
files and metrics as:

``single_k`` -- :class:`SingleKCalibration`
    The paper's eq:aoa with its one coefficient ``k``, fitted by minimising the RMS flow-angle
    error over the calibration points. Its airspeed is ``sqrt(2 q_inf / rho)`` (not fitted).

``calibrated`` -- :class:`SplineCalibration`
    Ours. As in multi-hole probe practice, the flow angles and a pressure coefficient are
    functions of the non-dimensional pressure coefficients ``C_alpha = q_alpha / q_inf`` and
    ``C_beta = q_beta / q_inf``: ``alpha(C)``, ``beta(C)`` and ``C_q(C) = q_inf / (rho V^2 / 2)``,
    so that ``V = sqrt(2 q_inf / (rho C_q))``. Instead of a global polynomial we fit a
    smoothing thin-plate spline (with a linear polynomial part) through the calibration points,
    with the smoothing chosen by leave-one-out cross-validation. On the NASA probes global
    polynomials of degree 3-9 in ``(C_alpha, C_beta)`` (also with ``|C|``-times-polynomial terms)
    reached only 0.04-0.11 deg RMS on the test points of 16328-1 at Mach 0.05, against 0.031 deg
    for the spline: the probe responds more steeply inside about 2 deg of its axis (its
    zero-angle point sits 0.2 deg off any smooth surface through the calibration rings), which a
    spline honours and a low-order polynomial cannot. For flight the spline is sampled once on a
    grid in ``to_kernel()`` and the compiled kernel interpolates the grid (cubic convolution,
    within 0.002 deg of the spline), about 0.2 us per call.

Calibration files are small versioned JSON documents (:func:`save_calibration`,
:func:`load_calibration`)::

    {"format": "vtoladapt.probe.calibration", "version": 1, "source": "...",
     "models": {"single_k": {"kind": "single_k", "k": ..., ...},
                "calibrated": {"kind": "thin_plate_spline", ...}}}
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from vtoladapt.probe.points import ProbeCalibrationData
from vtoladapt.probe.errors import ProbeError, require_number
from vtoladapt.probe.estimation import (
    KIND_CALIBRATED,
    KIND_SINGLE_K,
    SINGLE_K_PARAMS,
    TABLE_HEADER,
    estimate_incident_velocity,
    tps_evaluate,
)
from vtoladapt.probe.flow import airspeed_angles_from_v_i, flow_angle_error_rad

CALIBRATION_FORMAT = "vtoladapt.probe.calibration"
CALIBRATION_VERSION = 1
MODEL_NAMES = ("single_k", "calibrated")
DEFAULT_Q_INF_MIN_PA = 2.0
"""Default low-dynamic-pressure limit (Pa): 10x the SDP33 noise, about 1.8 m/s at sea level."""
DEFAULT_ANGLE_MARGIN_DEG = 1.0
"""Readings are valid up to the largest calibrated cone angle plus this margin (deg)."""
SMOOTHING_CANDIDATES = (1e-8, 1e-6, 1e-4, 1e-2)


# --------------------------------------------------------------------------------------------
# single k (eq:aoa)
# --------------------------------------------------------------------------------------------

class _KernelEstimator:
    """What both calibration models share: estimation through their kernel array."""

    def estimate(self, q_Pa, rho):
        """Incident velocity and validity for measured pressures.

        Runs the compiled :func:`~vtoladapt.probe.estimation.incident_velocity_from_pressures`.

        Parameters
        ----------
        q_Pa : array_like, shape (3,) or (N, 3)
            ``[q_inf, q_alpha, q_beta]`` (Pa).
        rho : float or array_like, shape (N,)
            Air density (kg/m^3).

        Returns
        -------
        v_i_B : numpy.ndarray, shape (3,) or (N, 3)
        valid : bool or numpy.ndarray of bool
        """
        return estimate_incident_velocity(self.to_kernel(), q_Pa, rho)


@dataclass(frozen=True)
class SingleKCalibration(_KernelEstimator):
    """The paper's eq:aoa with one coefficient ``k``.

    Parameters
    ----------
    k : float
        eq:aoa's coefficient (> 0).
    q_inf_min_Pa : float
        Readings with ``q_inf`` below this are invalid (Pa, >= 0).
    angle_limit_deg : float
        Readings with an estimated cone angle above this are invalid (deg, in (0, 90]).
    """

    k: float
    q_inf_min_Pa: float = DEFAULT_Q_INF_MIN_PA
    angle_limit_deg: float = 25.0

    kind = "single_k"

    def __post_init__(self) -> None:
        where = "SingleKCalibration"
        require_number(where, "k", self.k, gt=0.0)
        require_number(where, "q_inf_min_Pa", self.q_inf_min_Pa, ge=0.0, unit="Pa")
        require_number(where, "angle_limit_deg", self.angle_limit_deg, gt=0.0, le=90.0,
                       unit="deg")

    def to_kernel(self) -> np.ndarray:
        """``[1.0, k, q_inf_min_Pa, angle_limit_rad]`` for the compiled estimator."""
        return SINGLE_K_PARAMS.pack(KIND=KIND_SINGLE_K, K=self.k, Q_MIN=self.q_inf_min_Pa,
                                    ANGLE_LIMIT=math.radians(self.angle_limit_deg))

    def to_dict(self) -> dict:
        """JSON-ready description."""
        return {"kind": self.kind, "k": self.k, "q_inf_min_Pa": self.q_inf_min_Pa,
                "angle_limit_deg": self.angle_limit_deg}

    @classmethod
    def from_dict(cls, d: Mapping, where: str = "SingleKCalibration") -> "SingleKCalibration":
        """Inverse of :meth:`to_dict`; errors name ``where`` and the field."""
        _check_keys(d, where, required=("kind", "k"),
                    optional=("q_inf_min_Pa", "angle_limit_deg"))
        kw = {"k": require_number(where, "k", d["k"], gt=0.0)}
        if "q_inf_min_Pa" in d:
            kw["q_inf_min_Pa"] = require_number(where, "q_inf_min_Pa", d["q_inf_min_Pa"], ge=0.0)
        if "angle_limit_deg" in d:
            kw["angle_limit_deg"] = require_number(where, "angle_limit_deg", d["angle_limit_deg"],
                                                   gt=0.0, le=90.0)
        return cls(**kw)


def fit_single_k(data: ProbeCalibrationData, *, q_inf_min_Pa: float = DEFAULT_Q_INF_MIN_PA,
                 angle_margin_deg: float = DEFAULT_ANGLE_MARGIN_DEG) -> SingleKCalibration:
    """Fit eq:aoa's ``k`` to the calibration points of ``data``.

    ``k`` minimises the mean squared angle between the eq:aoa direction
    ``[q_inf, k q_beta, k q_alpha]`` and the true flow direction (bounded scalar search around
    the linear least-squares estimate of ``tan(alpha) ~ k q_alpha / q_inf``).

    Parameters
    ----------
    data : ProbeCalibrationData
        Its calibration (non-test) points are used.
    q_inf_min_Pa : float
        Low-dynamic-pressure limit stored in the calibration (Pa).
    angle_margin_deg : float
        The angle limit is the largest calibrated cone angle plus this (deg).

    Returns
    -------
    SingleKCalibration
    """
    cal = _usable_calibration_points(data)
    q = cal.q_Pa
    n_true = cal.v_i_B / cal.V_mps[:, None]
    c = np.concatenate([q[:, 1] / q[:, 0], q[:, 2] / q[:, 0]])
    t = np.concatenate([n_true[:, 2] / n_true[:, 0], n_true[:, 1] / n_true[:, 0]])
    k0 = float(np.dot(c, t) / np.dot(c, c)) if np.dot(c, c) > 0 else 1.0
    k0 = abs(k0) if k0 != 0 and np.isfinite(k0) else 1.0

    def cost(k: float) -> float:
        d = np.column_stack([q[:, 0], k * q[:, 2], k * q[:, 1]])
        return float(np.mean(flow_angle_error_rad(d, n_true) ** 2))

    from scipy.optimize import minimize_scalar  # imported here: the simulator loads this module

    res = minimize_scalar(cost, bounds=(k0 / 4.0, k0 * 4.0), method="bounded",
                          options={"xatol": 1e-10 * k0})
    limit = min(90.0, float(np.max(cal.cone_angle_deg)) + angle_margin_deg)
    return SingleKCalibration(k=float(res.x), q_inf_min_Pa=q_inf_min_Pa, angle_limit_deg=limit)


# --------------------------------------------------------------------------------------------
# our calibration: thin-plate spline in the pressure-coefficient plane
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class SplineCalibration(_KernelEstimator):
    """Smoothing thin-plate spline ``C -> (alpha, beta, C_q)`` (see the module docstring).

    Parameters
    ----------
    c_scale : float
        ``C = [q_alpha, q_beta] / q_inf`` is divided by this before the spline (the largest
        ``|C|`` of the calibration points, so they fill the unit disk).
    centres : numpy.ndarray, shape (N, 2)
        Spline centres in scaled coordinates.
    weights : numpy.ndarray, shape (N, 3)
        Spline weights for ``alpha_rad``, ``beta_rad``, ``C_q``.
    poly : numpy.ndarray, shape (3, 3)
        Linear part: row 0 constant, rows 1-2 the ``x``, ``y`` coefficients, one column per output.
    smoothing : float
        The smoothing used in the fit (recorded for reference).
    radius_limit : float
        Readings with scaled ``|C|`` above this are invalid.
    q_inf_min_Pa : float
        Readings with ``q_inf`` below this are invalid (Pa).
    angle_limit_deg : float
        Readings with an estimated cone angle above this are invalid (deg).
    grid_size : int
        Nodes per side of the grid the kernel interpolates.
    """

    c_scale: float
    centres: np.ndarray = field(repr=False)
    weights: np.ndarray = field(repr=False)
    poly: np.ndarray = field(repr=False)
    smoothing: float = 0.0
    radius_limit: float = 1.05
    q_inf_min_Pa: float = DEFAULT_Q_INF_MIN_PA
    angle_limit_deg: float = 25.0
    grid_size: int = 201
    _kernel_cache: list = field(default_factory=list, init=False, repr=False, compare=False)

    kind = "thin_plate_spline"

    def __post_init__(self) -> None:
        where = "SplineCalibration"
        require_number(where, "c_scale", self.c_scale, gt=0.0)
        require_number(where, "smoothing", self.smoothing, ge=0.0)
        require_number(where, "radius_limit", self.radius_limit, gt=0.0, le=2.0)
        require_number(where, "q_inf_min_Pa", self.q_inf_min_Pa, ge=0.0, unit="Pa")
        require_number(where, "angle_limit_deg", self.angle_limit_deg, gt=0.0, le=90.0,
                       unit="deg")
        if isinstance(self.grid_size, bool) or not isinstance(self.grid_size, (int, np.integer)) \
                or not 16 <= int(self.grid_size) <= 1001:
            raise ProbeError(f"{where}: grid_size = {self.grid_size!r}: allowed: a whole number "
                             "16..1001")
        c = np.ascontiguousarray(self.centres, dtype=float)
        w = np.ascontiguousarray(self.weights, dtype=float)
        p = np.ascontiguousarray(self.poly, dtype=float)
        if c.ndim != 2 or c.shape[1] != 2 or c.shape[0] < 3:
            raise ProbeError(f"{where}: centres has shape {c.shape}; expected (N, 2), N >= 3")
        if w.shape != (c.shape[0], 3):
            raise ProbeError(f"{where}: weights has shape {w.shape}; expected ({c.shape[0]}, 3)")
        if p.shape != (3, 3):
            raise ProbeError(f"{where}: poly has shape {p.shape}; expected (3, 3)")
        for name, arr in (("centres", c), ("weights", w), ("poly", p)):
            if not np.all(np.isfinite(arr)):
                raise ProbeError(f"{where}: {name} contains a non-finite value")
        object.__setattr__(self, "centres", c)
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "poly", p)
        object.__setattr__(self, "grid_size", int(self.grid_size))

    # -- evaluation -----------------------------------------------------------------------
    def evaluate_exact(self, q_Pa) -> np.ndarray:
        """Spline outputs ``[alpha_rad, beta_rad, C_q]`` straight from the spline (no grid).

        Parameters
        ----------
        q_Pa : array_like, shape (N, 3)
            ``[q_inf, q_alpha, q_beta]`` with ``q_inf > 0`` (Pa).

        Returns
        -------
        numpy.ndarray, shape (N, 3)
        """
        q = np.atleast_2d(np.asarray(q_Pa, dtype=float))
        x = np.ascontiguousarray(q[:, 1:3] / q[:, :1] / self.c_scale)
        out = np.empty((x.shape[0], 3))
        tps_evaluate(x, self.centres, self.weights, self.poly, out)
        return out

    def grid_half_width(self) -> float:
        """Half-width of the square of scaled ``C`` the kernel's grid covers."""
        return self.radius_limit + 0.05

    def to_kernel(self) -> np.ndarray:
        """The calibration sampled on its grid, as the compiled estimator's array.

        Computed once per object (about 0.1-0.5 s for 500 centres) and cached.

        Returns
        -------
        numpy.ndarray
            Layout in :mod:`vtoladapt.probe.estimation` (``KIND_CALIBRATED``).
        """
        if self._kernel_cache:
            return self._kernel_cache[0].copy()
        n = self.grid_size
        L = self.grid_half_width()
        h = 2.0 * L / (n - 3)
        x0 = -L - h
        nodes = x0 + h * np.arange(n)
        X, Y = np.meshgrid(nodes, nodes, indexing="ij")
        pts = np.ascontiguousarray(np.column_stack([X.ravel(), Y.ravel()]))
        vals = np.empty((pts.shape[0], 3))
        tps_evaluate(pts, self.centres, self.weights, self.poly, vals)
        header = TABLE_HEADER.pack(KIND=KIND_CALIBRATED, Q_MIN=self.q_inf_min_Pa,
                                   ANGLE_LIMIT=math.radians(self.angle_limit_deg), SCALE=self.c_scale,
                                   RADIUS_LIMIT=self.radius_limit, N=n, X0=x0, H=h)
        out = np.concatenate((header, vals.T.ravel()))
        self._kernel_cache.append(out)
        return out.copy()

    # -- files --------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-ready description (floats written with full precision)."""
        return {
            "kind": self.kind,
            "inputs": "x = (q_alpha/q_inf)/c_scale, y = (q_beta/q_inf)/c_scale",
            "outputs": ["alpha_rad", "beta_rad", "C_q"],
            "basis": "phi(r) = r^2 log r, plus poly[0] + poly[1] x + poly[2] y",
            "c_scale": self.c_scale,
            "smoothing": self.smoothing,
            "radius_limit": self.radius_limit,
            "q_inf_min_Pa": self.q_inf_min_Pa,
            "angle_limit_deg": self.angle_limit_deg,
            "grid_size": self.grid_size,
            "centres": self.centres.tolist(),
            "weights": self.weights.tolist(),
            "poly": self.poly.tolist(),
        }

    @classmethod
    def from_dict(cls, d: Mapping, where: str = "SplineCalibration") -> "SplineCalibration":
        """Inverse of :meth:`to_dict`; errors name ``where`` and the field."""
        _check_keys(d, where, required=("kind", "c_scale", "centres", "weights", "poly"),
                    optional=("inputs", "outputs", "basis", "smoothing", "radius_limit",
                              "q_inf_min_Pa", "angle_limit_deg", "grid_size"))
        kw = {"c_scale": require_number(where, "c_scale", d["c_scale"], gt=0.0)}
        for name in ("smoothing", "radius_limit", "q_inf_min_Pa", "angle_limit_deg"):
            if name in d:
                kw[name] = require_number(where, name, d[name])
        if "grid_size" in d:
            kw["grid_size"] = d["grid_size"]
        for name in ("centres", "weights", "poly"):
            try:
                kw[name] = np.array(d[name], dtype=float)
            except (TypeError, ValueError):
                raise ProbeError(f"{where}: {name} is not a numeric array") from None
        try:
            return cls(**kw)
        except ProbeError as exc:
            msg = str(exc).replace("SplineCalibration", where, 1)
            raise ProbeError(msg) from None


def _tps_system(x: np.ndarray, smoothing: float) -> np.ndarray:
    n = x.shape[0]
    d2 = np.sum((x[:, None, :] - x[None, :, :]) ** 2, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(d2 > 0.0, 0.5 * d2 * np.log(np.where(d2 > 0.0, d2, 1.0)), 0.0)
    A = np.zeros((n + 3, n + 3))
    A[:n, :n] = phi + smoothing * np.eye(n)
    P = np.column_stack([np.ones(n), x])
    A[:n, n:] = P
    A[n:, :n] = P.T
    return A


_DEGENERATE_POINTS = ("calibration points are degenerate (repeated pressure coefficients); "
                      "use a smoothing > 0 (--smoothing) or more distinct points")
"""Why the thin-plate spline's system could not be solved (fit and leave-one-out alike)."""


def _tps_fit(x: np.ndarray, y: np.ndarray, smoothing: float) -> tuple[np.ndarray, np.ndarray]:
    n = x.shape[0]
    A = _tps_system(x, smoothing)
    rhs = np.zeros((n + 3, y.shape[1]))
    rhs[:n] = y
    try:
        sol = np.linalg.solve(A, rhs)
    except np.linalg.LinAlgError:
        raise ProbeError(_DEGENERATE_POINTS) from None
    return sol[:n], sol[n:]


def tps_loo_residuals(x: np.ndarray, y: np.ndarray, smoothing: float) -> np.ndarray:
    """Leave-one-out residuals of the smoothing thin-plate spline, without refitting.

    Rippa's rule (Rippa 1999, Adv. Comput. Math. 11; with the polynomial block as in Fasshauer,
    "Meshfree Approximation Methods with MATLAB", ch. 17): with ``A`` the spline's augmented
    system matrix and ``c = A^-1 [y; 0]``, the residual at point ``i`` of the spline fitted
    without point ``i`` is ``c_i / (A^-1)_ii``.

    Parameters
    ----------
    x : numpy.ndarray, shape (N, 2)
        Scaled pressure coefficients.
    y : numpy.ndarray, shape (N, K)
        Targets.
    smoothing : float
        Spline smoothing.

    Returns
    -------
    numpy.ndarray, shape (N, K)
        ``y_i - f_{-i}(x_i)``.
    """
    n = x.shape[0]
    try:
        Ainv = np.linalg.inv(_tps_system(x, smoothing))
    except np.linalg.LinAlgError:
        raise ProbeError(_DEGENERATE_POINTS) from None
    c = Ainv[:, :n] @ y
    return c[:n] / np.diag(Ainv)[:n, None]


def _angle_error_from_angles(alpha, beta, alpha_t, beta_t) -> np.ndarray:
    def unit(a, b):
        return np.column_stack([np.cos(a) * np.cos(b), np.sin(b), np.sin(a) * np.cos(b)])
    return flow_angle_error_rad(unit(alpha, beta), unit(alpha_t, beta_t))


def fit_spline_calibration(data: ProbeCalibrationData, *, smoothing: float | None = None,
                           q_inf_min_Pa: float = DEFAULT_Q_INF_MIN_PA,
                           angle_margin_deg: float = DEFAULT_ANGLE_MARGIN_DEG,
                           radius_limit: float = 1.05,
                           grid_size: int = 201) -> SplineCalibration:
    """Fit our calibration (:class:`SplineCalibration`) to the calibration points of ``data``.

    Parameters
    ----------
    data : ProbeCalibrationData
        Its calibration (non-test) points are used.
    smoothing : float, optional
        Spline smoothing; ``None`` picks, from :data:`SMOOTHING_CANDIDATES`, the one with the
        smallest leave-one-out RMS flow-angle error (:func:`tps_loo_residuals`).
    q_inf_min_Pa : float
        Low-dynamic-pressure limit stored in the calibration (Pa).
    angle_margin_deg : float
        The angle limit is the largest calibrated cone angle plus this (deg).
    radius_limit : float
        Validity limit on the scaled pressure-coefficient radius (1 = the calibration's largest).
    grid_size : int
        Nodes per side of the kernel's interpolation grid.

    Returns
    -------
    SplineCalibration
    """
    cal = _usable_calibration_points(data)
    q = cal.q_Pa
    C = q[:, 1:3] / q[:, :1]
    r = np.hypot(C[:, 0], C[:, 1])
    c_scale = float(np.max(r)) if np.max(r) > 0 else 1.0
    x = C / c_scale
    # the spline's affine part (1, C_alpha, C_beta) needs points spanning the plane; no smoothing
    # helps when they lie on one line (e.g. an alpha sweep at beta = 0) or at one point
    if np.linalg.matrix_rank(np.column_stack([np.ones(len(x)), x]), tol=1e-9) < 3:
        raise ProbeError(f"{data.source}: the {len(x)} calibration points' pressure coefficients "
                         "(q_alpha/q_inf, q_beta/q_inf) lie on one line or at one point; allowed: "
                         "points that vary in both alpha and beta (a cone or alpha-beta sweep)")
    alpha_t = np.radians(cal.alpha_deg)
    beta_t = np.radians(cal.beta_deg)
    cq = q[:, 0] / cal.q_dyn_Pa
    y = np.column_stack([alpha_t, beta_t, cq])
    if smoothing is None:
        best = (np.inf, SMOOTHING_CANDIDATES[0])
        for s in SMOOTHING_CANDIDATES:
            pred = y - tps_loo_residuals(x, y, s)
            err = _angle_error_from_angles(pred[:, 0], pred[:, 1], alpha_t, beta_t)
            rms = float(np.sqrt(np.mean(err ** 2)))
            if rms < best[0] * (1.0 - 1e-3):
                best = (rms, s)
        smoothing = best[1]
    smoothing = require_number("fit_spline_calibration", "smoothing", smoothing, ge=0.0)
    w, p = _tps_fit(x, y, smoothing)
    limit = min(90.0, float(np.max(cal.cone_angle_deg)) + angle_margin_deg)
    return SplineCalibration(c_scale=c_scale, centres=x, weights=w, poly=p, smoothing=smoothing,
                             radius_limit=radius_limit, q_inf_min_Pa=q_inf_min_Pa,
                             angle_limit_deg=limit, grid_size=grid_size)


def _usable_calibration_points(data: ProbeCalibrationData) -> ProbeCalibrationData:
    cal = data.calibration_points()
    ok = (cal.q_Pa[:, 0] > 0.0) & np.all(np.isfinite(cal.q_Pa), axis=1)
    if np.count_nonzero(ok) < 10:
        raise ProbeError(f"{data.source}: {np.count_nonzero(ok)} calibration points with "
                         "q_inf > 0; need at least 10")
    return cal.subset(ok) if not np.all(ok) else cal


def calibrate(data: ProbeCalibrationData, *, smoothing: float | None = None,
              q_inf_min_Pa: float = DEFAULT_Q_INF_MIN_PA) -> dict:
    """Fit both models to the calibration points of ``data``.

    Parameters
    ----------
    data : ProbeCalibrationData
        Its calibration (non-test) points are used.
    smoothing : float, optional
        Spline smoothing (``None``: cross-validated, see :func:`fit_spline_calibration`).
    q_inf_min_Pa : float
        Low-dynamic-pressure limit stored in both calibrations (Pa).

    Returns
    -------
    dict
        ``{"single_k": SingleKCalibration, "calibrated": SplineCalibration}``.
    """
    return {"single_k": fit_single_k(data, q_inf_min_Pa=q_inf_min_Pa),
            "calibrated": fit_spline_calibration(data, smoothing=smoothing,
                                                 q_inf_min_Pa=q_inf_min_Pa)}


def calibrate_tip(tip, *, cone_max_deg: float = 30.0, n_rings: int = 15, V_mps: float = 15.0,
                  rho: float = 1.225, q_inf_min_Pa: float = DEFAULT_Q_INF_MIN_PA) -> dict:
    """Both models for a simulated tip, fitted to its noise-free forward model.

    What a simulation's flight software uses as "the probe's calibration" (the tunnel
    calibration of the simulated probe). Deterministic: no randomness is involved.

    Parameters
    ----------
    tip : ProbeTip
        The simulated tip.
    cone_max_deg : float
        Largest cone angle of the simulated calibration grid (deg).
    n_rings : int
        Rings of the grid (:func:`~vtoladapt.probe.data.polar_grid_deg`).
    V_mps, rho : float
        Simulated tunnel airspeed (m/s) and density (kg/m^3); the models are non-dimensional,
        so these hardly matter.
    q_inf_min_Pa : float
        Low-dynamic-pressure limit stored in the calibrations (Pa).

    Returns
    -------
    dict
        ``{"single_k": SingleKCalibration, "calibrated": SplineCalibration}``.
    """
    from vtoladapt.probe.data import simulate_calibration_sweep

    data = simulate_calibration_sweep(tip, np.random.default_rng(0), sensor=None, V_mps=V_mps,
                                      rho=rho, cone_max_deg=cone_max_deg, n_rings=n_rings,
                                      n_test=0)
    return calibrate(data, smoothing=SMOOTHING_CANDIDATES[0], q_inf_min_Pa=q_inf_min_Pa)


# --------------------------------------------------------------------------------------------
# evaluation
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class CalibrationMetrics:
    """Errors of one calibration on a set of points.

    The statistics are over every point the estimator returned an estimate for (``n_used``):
    readings flagged only for being outside the calibrated range are included (their estimate
    is finite and is what a user would see), readings with no estimate (``q_inf`` too low or not
    finite: zero vector) are not.

    Attributes
    ----------
    model : str
        The model's name (``single_k``, ``calibrated``).
    points : str
        Which points: ``test``, ``calibration`` or ``all``.
    n_points, n_valid, n_used : int
        Points evaluated, readings flagged valid, and points with an estimate (used).
    angle_rms_deg, angle_max_deg : float
        RMS and maximum angle between estimated and true flow direction (deg).
    speed_rms_rel, speed_max_rel : float
        RMS and maximum of ``|V_est - V_true| / V_true``.
    alpha_rms_deg, beta_rms_deg : float
        RMS errors of the two flow angles (deg).
    alpha_true_deg, beta_true_deg, alpha_est_deg, beta_est_deg : numpy.ndarray
        Per-point angles (for the linearity figure); NaN estimates where there is none.
    valid : numpy.ndarray of bool
    """

    model: str
    points: str
    n_points: int
    n_valid: int
    n_used: int
    angle_rms_deg: float
    angle_max_deg: float
    speed_rms_rel: float
    speed_max_rel: float
    alpha_rms_deg: float
    beta_rms_deg: float
    alpha_true_deg: np.ndarray
    beta_true_deg: np.ndarray
    alpha_est_deg: np.ndarray
    beta_est_deg: np.ndarray
    valid: np.ndarray

    def to_dict(self) -> dict:
        """The scalar metrics, JSON-ready (NaN written as ``None``)."""
        def f(x):
            return None if not np.isfinite(x) else float(x)
        return {"angle_rms_deg": f(self.angle_rms_deg), "angle_max_deg": f(self.angle_max_deg),
                "speed_rms_rel": f(self.speed_rms_rel), "speed_max_rel": f(self.speed_max_rel),
                "alpha_rms_deg": f(self.alpha_rms_deg), "beta_rms_deg": f(self.beta_rms_deg),
                "n_points": int(self.n_points), "n_valid": int(self.n_valid),
                "n_used": int(self.n_used), "points": self.points}


def evaluate_calibration(calibration, data: ProbeCalibrationData, points: str = "auto",
                         name: str | None = None) -> CalibrationMetrics:
    """Errors of ``calibration`` on ``data`` through the compiled estimator.

    Parameters
    ----------
    calibration : SingleKCalibration or SplineCalibration
    data : ProbeCalibrationData
    points : {'auto', 'test', 'calibration', 'all'}
        ``auto``: the test points when ``data`` has them, else all points.
    name : str, optional
        Model name recorded in the result (default: from the calibration type).

    Returns
    -------
    CalibrationMetrics
    """
    sel = data.select(points)
    label = sel.info.get("subset", points)
    v_est, valid = calibration.estimate(sel.q_Pa, sel.rho)
    v_true = sel.v_i_B
    V_est, a_est, b_est = airspeed_angles_from_v_i(v_est)
    ang = np.degrees(flow_angle_error_rad(v_est, v_true))
    srel = np.abs(V_est - sel.V_mps) / sel.V_mps
    da = np.degrees(a_est) - sel.alpha_deg
    db = np.degrees(b_est) - sel.beta_deg

    # Statistics over every point the estimator gave an estimate for (valid or flagged out of
    # range); a zero vector means no estimate (low or non-finite pressures).
    used = V_est > 0.0

    def rms(x):
        return float(np.sqrt(np.mean(x[used] ** 2))) if np.any(used) else float("nan")

    def mx(x):
        return float(np.max(np.abs(x[used]))) if np.any(used) else float("nan")

    if name is None:
        name = "single_k" if isinstance(calibration, SingleKCalibration) else "calibrated"
    return CalibrationMetrics(
        model=name, points=label, n_points=len(sel), n_valid=int(np.count_nonzero(valid)),
        n_used=int(np.count_nonzero(used)),
        angle_rms_deg=rms(ang), angle_max_deg=mx(ang), speed_rms_rel=rms(srel),
        speed_max_rel=mx(srel), alpha_rms_deg=rms(da), beta_rms_deg=rms(db),
        alpha_true_deg=sel.alpha_deg.copy(), beta_true_deg=sel.beta_deg.copy(),
        alpha_est_deg=np.where(used, np.degrees(a_est), np.nan),
        beta_est_deg=np.where(used, np.degrees(b_est), np.nan), valid=np.asarray(valid))


# --------------------------------------------------------------------------------------------
# files
# --------------------------------------------------------------------------------------------

_KINDS = {"single_k": SingleKCalibration, "thin_plate_spline": SplineCalibration}


def _check_keys(d: Mapping, where: str, required: tuple, optional: tuple) -> None:
    if not isinstance(d, Mapping):
        raise ProbeError(f"{where}: expected a JSON object, got {type(d).__name__}")
    for key in d:
        if key not in required and key not in optional:
            raise ProbeError(f"{where}: unknown field {key!r}; allowed: "
                             f"{', '.join(required + optional)}")
    for key in required:
        if key not in d:
            raise ProbeError(f"{where}: missing field {key!r}")


def calibration_from_dict(d: Mapping, where: str):
    """Build a calibration from its ``to_dict()`` form, dispatching on ``kind``.

    Parameters
    ----------
    d : mapping
        The model's JSON object.
    where : str
        Prefix of error messages (file and JSON path).

    Returns
    -------
    SingleKCalibration or SplineCalibration
    """
    if not isinstance(d, Mapping):
        raise ProbeError(f"{where}: expected a JSON object, got {type(d).__name__}")
    kind = d.get("kind")
    if not isinstance(kind, str) or kind not in _KINDS:
        raise ProbeError(f"{where}: kind = {kind!r}: unknown model kind; allowed: "
                         f"{', '.join(repr(k) for k in _KINDS)}")
    return _KINDS[kind].from_dict(d, where)


def save_calibration(path: str | Path, models: Mapping, *, source: str = "",
                     notes: str = "") -> Path:
    """Write calibrations to a versioned JSON file.

    Parameters
    ----------
    path : str or pathlib.Path
    models : mapping of str to calibration
        Names (``single_k``, ``calibrated``) to :class:`SingleKCalibration` /
        :class:`SplineCalibration` objects.
    source : str
        Where the calibration data came from.
    notes : str
        Free text (e.g. the data citation).

    Returns
    -------
    pathlib.Path
    """
    from vtoladapt._version import __version__

    path = Path(path)
    for name in models:
        if name not in MODEL_NAMES:
            raise ProbeError(f"{path}: model name {name!r} unknown; allowed: "
                             f"{', '.join(MODEL_NAMES)}")
    doc = {"format": CALIBRATION_FORMAT, "version": CALIBRATION_VERSION,
           "created_by": f"vtoladapt {__version__}", "source": str(source), "notes": notes,
           "models": {name: m.to_dict() for name, m in models.items()}}
    path.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    return path


def load_calibration(path: str | Path, model: str | None = None):
    """Read a calibration file written by :func:`save_calibration`.

    Parameters
    ----------
    path : str or pathlib.Path
    model : str, optional
        Return only this model (``single_k`` or ``calibrated``).

    Returns
    -------
    dict or calibration
        ``{name: calibration}`` in file order, or the one named ``model``.

    Raises
    ------
    ProbeError
        Missing file, invalid JSON, wrong ``format`` or ``version``, an unknown model name or
        kind, or an invalid field; the message names the file and the field.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ProbeError(f"{path}: file not found") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ProbeError(f"{path}: not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise ProbeError(f"{path}: expected a JSON object at the top level")
    if doc.get("format") != CALIBRATION_FORMAT:
        raise ProbeError(f"{path}: format = {doc.get('format')!r}: not a probe calibration; "
                         f"expected {CALIBRATION_FORMAT!r}")
    version = doc.get("version")
    if version != CALIBRATION_VERSION or isinstance(version, bool):
        raise ProbeError(f"{path}: version = {version!r}: unsupported; this vtoladapt reads "
                         f"version {CALIBRATION_VERSION}")
    models = doc.get("models")
    if not isinstance(models, dict) or not models:
        raise ProbeError(f"{path}: models = {models!r}: expected a non-empty object of "
                         f"{' / '.join(MODEL_NAMES)}")
    out = {}
    for name, d in models.items():
        if name not in MODEL_NAMES:
            raise ProbeError(f"{path}: models.{name}: unknown model name; allowed: "
                             f"{', '.join(MODEL_NAMES)}")
        out[name] = calibration_from_dict(d, f"{path}: models.{name}")
    if model is None:
        return out
    if model not in MODEL_NAMES:
        raise ProbeError(f"{path}: model = {model!r}: unknown model name; allowed: "
                         f"{', '.join(MODEL_NAMES)}")
    if model not in out:
        raise ProbeError(f"{path}: model = {model!r}: not in this file (it has "
                         f"{', '.join(out)})")
    return out[model]
