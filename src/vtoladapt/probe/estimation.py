"""Compiled estimation of the incident velocity from the probe's three differential pressures.

Two models share one kernel, :func:`incident_velocity_from_pressures`, selected by the first
element of the calibration array:

``single_k`` (kind 1.0), the paper's eq:aoa
    ``[1.0, k, q_inf_min_Pa, angle_limit_rad]``

``calibrated`` (kind 2.0), our calibration sampled on a grid of the non-dimensional pressure
coefficients ``C_alpha = q_alpha / q_inf``, ``C_beta = q_beta / q_inf`` (scaled by ``c_scale``)
    ``[2.0, q_inf_min_Pa, angle_limit_rad, c_scale, radius_limit, n, x0, h,``
    ``alpha_rad table (n*n), beta_rad table (n*n), C_q table (n*n)]``

    Node ``(i, j)`` is at ``x = x0 + i h`` (scaled ``C_alpha``), ``y = x0 + j h`` (scaled
    ``C_beta``), stored row-major ``i * n + j``. Values between nodes are interpolated with
    Keys' cubic convolution (``a = -1/2``, third-order accurate, continuous slope). The airspeed
    is ``V = sqrt(2 q_inf / (rho C_q))``.

Readings are flagged invalid (the kernel returns ``False``) when

* a pressure or the density is not finite, the density is not positive, ``q_inf`` is below
  ``q_inf_min_Pa`` (low dynamic pressure) or not positive, or the calibration array is malformed:
  the output is the zero vector;
* the flow is outside the calibrated range (estimated cone angle above ``angle_limit_rad``,
  or, for the calibrated model, ``|C| / c_scale`` above ``radius_limit``): the output is the
  finite estimate (for the calibrated model evaluated at the nearest point of the table).

The kernels never raise and never return NaN.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from vtoladapt.layout import BlockLayout, Field

KIND_SINGLE_K = 1.0
KIND_CALIBRATED = 2.0

SINGLE_K_PARAMS = BlockLayout("single-k calibration", [
    Field("KIND", 1, "-", "KIND_SINGLE_K"),
    Field("K", 1, "-", "eq:aoa's k"),
    Field("Q_MIN", 1, "Pa", "smallest q_inf accepted as valid"),
    Field("ANGLE_LIMIT", 1, "rad", "largest flow angle accepted as valid"),
])
"""Kernel array of a single-k calibration."""
SK_KIND, SK_K, SK_Q_MIN, SK_ANGLE_LIMIT = SINGLE_K_PARAMS.offsets("KIND", "K", "Q_MIN", "ANGLE_LIMIT")
SK_SIZE = SINGLE_K_PARAMS.size

TABLE_HEADER = BlockLayout("calibrated (table) calibration header", [
    Field("KIND", 1, "-", "KIND_CALIBRATED"),
    Field("Q_MIN", 1, "Pa", "smallest q_inf accepted as valid"),
    Field("ANGLE_LIMIT", 1, "rad", "largest flow angle accepted as valid"),
    Field("SCALE", 1, "-", "scale of the normalised pressure ratios"),
    Field("RADIUS_LIMIT", 1, "-", "largest radius in the ratio plane accepted as valid"),
    Field("N", 1, "-", "grid nodes per side n"),
    Field("X0", 1, "-", "first grid node"),
    Field("H", 1, "-", "grid spacing"),
])
"""Kernel array of a calibrated table: this header, then the 3 n^2 grid values."""
TB_KIND, TB_Q_MIN, TB_ANGLE_LIMIT, TB_SCALE, TB_RADIUS_LIMIT, TB_N, TB_X0, TB_H = TABLE_HEADER.offsets(
    "KIND", "Q_MIN", "ANGLE_LIMIT", "SCALE", "RADIUS_LIMIT", "N", "X0", "H")
TB_HEADER = TABLE_HEADER.size
CAL_KIND = SK_KIND
"""Where every calibration array holds its kind (both layouts declare ``KIND`` first)."""

# Smallest C_q accepted from the table (C_q = q_inf / (rho V^2 / 2), about 0.7..1.1 in practice).
_CQ_MIN = 1.0e-3


# inline="always" here and below: the simulator's airflow-probe channel calls these every tick, and
# as separate calls their array arguments' reference counting cost more than their arithmetic.
@njit(cache=True, inline="always")
def aoa_incident_velocity(q_inf, q_alpha, q_beta, rho, k, out_v_i_B):
    """The paper's eq:aoa: incident velocity from the three differential pressures.

    ``v_i = sqrt((2 q_inf / rho) / (q_inf^2 + (k q_beta)^2 + (k q_alpha)^2))
    [q_inf, k q_beta, k q_alpha]``; its magnitude is ``sqrt(2 q_inf / rho)``.

    Parameters
    ----------
    q_inf, q_alpha, q_beta : float
        Differential pressures (Pa); ``q_inf > 0`` and ``rho > 0`` are required (not checked).
    rho : float
        Air density (kg/m^3).
    k : float
        The single calibration coefficient.
    out_v_i_B : float64[3]
        Written: ``v_i_B`` (m/s).
    """
    a = k * q_alpha
    b = k * q_beta
    s = np.sqrt((2.0 * q_inf / rho) / (q_inf * q_inf + b * b + a * a))
    out_v_i_B[0] = s * q_inf
    out_v_i_B[1] = s * b
    out_v_i_B[2] = s * a


@njit(cache=True, _nrt=False)
def _keys_weights(t):
    """Keys' cubic-convolution weights (a = -1/2) of nodes i-1, i, i+1, i+2 at t in [0, 1)."""
    return (((-0.5 * t + 1.0) * t - 0.5) * t,
            (1.5 * t - 2.5) * t * t + 1.0,
            ((-1.5 * t + 2.0) * t + 0.5) * t,
            (0.5 * t - 0.5) * t * t)


@njit(cache=True, inline="always")
def _single_k(q_inf, q_alpha, q_beta, rho, cal, out):
    if cal.shape[0] < SK_SIZE:
        return False
    k = cal[SK_K]
    q_min = cal[SK_Q_MIN]
    if not (np.isfinite(k) and np.isfinite(q_min)):
        return False
    if not (q_inf > 0.0) or q_inf < q_min:
        return False
    aoa_incident_velocity(q_inf, q_alpha, q_beta, rho, k, out)
    V = np.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2])
    if not (np.isfinite(V) and V > 0.0):
        out[0] = 0.0
        out[1] = 0.0
        out[2] = 0.0
        return False
    return out[0] >= V * np.cos(cal[SK_ANGLE_LIMIT])


@njit(cache=True, _nrt=False)
def _table(q_inf, q_alpha, q_beta, rho, cal, out):
    if cal.shape[0] < TB_HEADER:
        return False
    if not (cal[TB_N] >= 4.0 and cal[TB_N] <= 4096.0):
        return False
    n = int(cal[TB_N])
    if cal.shape[0] != TB_HEADER + 3 * n * n:
        return False
    q_min = cal[TB_Q_MIN]
    scale = cal[TB_SCALE]
    x0 = cal[TB_X0]
    h = cal[TB_H]
    if not (np.isfinite(q_min) and scale > 0.0 and h > 0.0 and np.isfinite(x0)):
        return False
    if not (q_inf > 0.0) or q_inf < q_min:
        return False
    x = q_alpha / q_inf / scale
    y = q_beta / q_inf / scale
    if not (np.isfinite(x) and np.isfinite(y)):
        return False
    valid = np.sqrt(x * x + y * y) <= cal[TB_RADIUS_LIMIT]
    # keep the 4 x 4 stencil inside the table: i in [1, n - 3]
    lo = x0 + h
    hi = x0 + (n - 2) * h * (1.0 - 1e-12)
    if x < lo:
        x = lo
    elif x > hi:
        x = hi
    if y < lo:
        y = lo
    elif y > hi:
        y = hi
    fx = (x - x0) / h
    fy = (y - x0) / h
    i = int(np.floor(fx))
    j = int(np.floor(fy))
    if i < 1:
        i = 1
    elif i > n - 3:
        i = n - 3
    if j < 1:
        j = 1
    elif j > n - 3:
        j = n - 3
    wx = _keys_weights(fx - i)
    wy = _keys_weights(fy - j)
    alpha = 0.0
    beta = 0.0
    cq = 0.0
    nn = n * n
    for a in range(4):
        row = TB_HEADER + (i - 1 + a) * n + (j - 1)
        sa = 0.0
        sb = 0.0
        sc = 0.0
        for b in range(4):
            sa += wy[b] * cal[row + b]
            sb += wy[b] * cal[row + nn + b]
            sc += wy[b] * cal[row + 2 * nn + b]
        alpha += wx[a] * sa
        beta += wx[a] * sb
        cq += wx[a] * sc
    if not (cq > _CQ_MIN and np.isfinite(alpha) and np.isfinite(beta) and np.isfinite(cq)):
        return False
    V = np.sqrt(2.0 * q_inf / (rho * cq))
    if not np.isfinite(V):
        return False
    ca = np.cos(alpha)
    cb = np.cos(beta)
    out[0] = V * ca * cb
    out[1] = V * np.sin(beta)
    out[2] = V * np.sin(alpha) * cb
    if ca * cb < np.cos(cal[TB_ANGLE_LIMIT]):
        valid = False
    return valid


@njit(cache=True, inline="always")
def incident_velocity_from_pressures(q, rho, calibration, out_v_i_B):
    """Incident velocity ``v_i_B`` from ``[q_inf, q_alpha, q_beta]`` with a validity flag.

    Parameters
    ----------
    q : float64[3]
        Measured ``[q_inf, q_alpha, q_beta]`` (Pa): ``q_inf = p_centre - p_static``,
        ``q_alpha = p_bottom - p_top``, ``q_beta = p_right - p_left`` (see
        :mod:`vtoladapt.probe.tip`).
    rho : float
        Air density (kg/m^3).
    calibration : float64[:]
        ``to_kernel()`` of a :class:`~vtoladapt.probe.calibration.SingleKCalibration` or
        :class:`~vtoladapt.probe.calibration.SplineCalibration` (layouts in the module
        docstring).
    out_v_i_B : float64[3]
        Written: the estimated incident velocity in body axes FRD (m/s); always finite, the zero
        vector when the pressures cannot be used.

    Returns
    -------
    bool
        ``True`` when the reading is valid (enough dynamic pressure, inside the calibrated
        range); see the module docstring.
    """
    out_v_i_B[0] = 0.0
    out_v_i_B[1] = 0.0
    out_v_i_B[2] = 0.0
    if calibration.shape[0] < 1 or q.shape[0] < 3:
        return False
    q_inf = q[0]
    q_alpha = q[1]
    q_beta = q[2]
    if not (np.isfinite(q_inf) and np.isfinite(q_alpha) and np.isfinite(q_beta)):
        return False
    if not (np.isfinite(rho) and rho > 0.0):
        return False
    kind = calibration[CAL_KIND]
    if kind == KIND_SINGLE_K:
        valid = _single_k(q_inf, q_alpha, q_beta, rho, calibration, out_v_i_B)
    elif kind == KIND_CALIBRATED:
        valid = _table(q_inf, q_alpha, q_beta, rho, calibration, out_v_i_B)
    else:
        valid = False
    if not (np.isfinite(out_v_i_B[0]) and np.isfinite(out_v_i_B[1])
            and np.isfinite(out_v_i_B[2])):
        out_v_i_B[0] = 0.0
        out_v_i_B[1] = 0.0
        out_v_i_B[2] = 0.0
        return False
    return valid


@njit(cache=True)
def incident_velocity_batch(q, rho, calibration, out_v_i_B, out_valid):
    """:func:`incident_velocity_from_pressures` over many readings.

    Parameters
    ----------
    q : float64[N, 3]
        Pressures (Pa).
    rho : float64[N]
        Densities (kg/m^3).
    calibration : float64[:]
        A calibration's ``to_kernel()``.
    out_v_i_B : float64[N, 3]
        Written: estimates (m/s).
    out_valid : bool[N]
        Written: validity flags.
    """
    for i in range(q.shape[0]):
        out_valid[i] = incident_velocity_from_pressures(q[i], rho[i], calibration, out_v_i_B[i])


def estimate_incident_velocity(calibration_kernel: np.ndarray, q_Pa, rho):
    """Vectorised call of the compiled estimator (the same code the simulator runs).

    Parameters
    ----------
    calibration_kernel : numpy.ndarray
        A calibration's ``to_kernel()``.
    q_Pa : array_like, shape (3,) or (N, 3)
        ``[q_inf, q_alpha, q_beta]`` (Pa).
    rho : float or array_like, shape (N,)
        Air density (kg/m^3).

    Returns
    -------
    v_i_B : numpy.ndarray, shape (N, 3) (or (3,))
    valid : numpy.ndarray of bool, shape (N,) (or a bool)
    """
    q = np.asarray(q_Pa, dtype=float)
    single = q.ndim == 1
    q = np.ascontiguousarray(np.atleast_2d(q))
    if q.shape[-1] != 3 or q.ndim != 2:
        raise ValueError(f"q_Pa must have shape (3,) or (N, 3), got {np.shape(q_Pa)}")
    r = np.ascontiguousarray(np.broadcast_to(np.asarray(rho, dtype=float), (q.shape[0],)))
    v = np.zeros((q.shape[0], 3))
    ok = np.zeros(q.shape[0], dtype=np.bool_)
    incident_velocity_batch(q, r, np.ascontiguousarray(calibration_kernel, dtype=float), v, ok)
    if single:
        return v[0], bool(ok[0])
    return v, ok


@njit(cache=True)
def tps_evaluate(points, centres, weights, poly, out):
    """Evaluate a thin-plate spline with a linear polynomial part at ``points``.

    ``f_m(x) = sum_i w_im phi(|x - c_i|) + p_0m + p_1m x_0 + p_2m x_1``, ``phi(r) = r^2 log r``.

    Parameters
    ----------
    points : float64[M, 2]
    centres : float64[N, 2]
    weights : float64[N, K]
    poly : float64[3, K]
    out : float64[M, K]
        Written.
    """
    n_out = weights.shape[1]
    for p in range(points.shape[0]):
        x = points[p, 0]
        y = points[p, 1]
        for m in range(n_out):
            out[p, m] = poly[0, m] + poly[1, m] * x + poly[2, m] * y
        for i in range(centres.shape[0]):
            dx = x - centres[i, 0]
            dy = y - centres[i, 1]
            r2 = dx * dx + dy * dy
            if r2 > 0.0:
                phi = 0.5 * r2 * np.log(r2)
                for m in range(n_out):
                    out[p, m] += weights[i, m] * phi
