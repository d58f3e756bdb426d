"""Forward model of the five-hole conic/hemispherical probe tip: incident velocity -> pressures.

Port geometry (probe along body +x, FRD body axes)
--------------------------------------------------
Five ports on the tip plus a static reference:

=========  ==============================================  ===========================
port       surface normal (unit vector, body axes)          role
=========  ==============================================  ===========================
centre     ``[1, 0, 0]``                                     total-pressure port
bottom     ``[cos d, 0, +sin d]`` (towards body +z, down)    alpha pair, high side
top        ``[cos d, 0, -sin d]``                            alpha pair, low side
right      ``[cos d, +sin d, 0]`` (towards body +y)          beta pair, high side
left       ``[cos d, -sin d, 0]``                            beta pair, low side
static     (not on the tip)                                  reference of the q_inf sensor
=========  ==============================================  ===========================

``d`` is :attr:`ProbeTip.port_angle_deg`. The three differential pressure sensors read

* ``q_inf = p_centre - p_static``
* ``q_alpha = p_bottom - p_top``
* ``q_beta = p_right - p_left``

With positive angle of attack the vehicle moves down relative to the air (``v_iz > 0``), so the
air arrives from below and the bottom port faces it: ``q_alpha > 0``, as eq:aoa needs
(``v_iz`` proportional to ``k q_alpha``). Likewise positive sideslip (``v_iy > 0``) brings the
air from the right, so ``q_beta > 0``.

Pressure model
--------------
Potential flow over a sphere gives the surface pressure coefficient
``Cp = 1 - (9/4) sin^2(theta)`` where ``theta`` is the angle between the surface normal and the
direction the air comes from (the stagnation direction ``v_i_B / V``). We use
``Cp_j = 1 - K sin^2(theta_j)`` for every port ``j`` with ``K`` = :attr:`ProbeTip.pressure_factor`
(``9/4`` for a hemispherical tip in potential flow; a conic tip is approximated by the same law
applied to the cone's face normal, ``d = 90 deg - cone half-angle``, with ``K`` as an empirical
factor). Port pressures (gauge, relative to free-stream static) are ``p_j = q Cp_j`` with
``q = rho V^2 / 2``; the static reference reads ``q * C_ps`` (``C_ps`` =
:attr:`ProbeTip.static_port_coefficient`, 0 for a perfect static source).

A port facing away from the flow (``theta_j > 90 deg``) sits in the tip's separated wake, not in
a second potential-flow stagnation region: its ``Cp`` goes from the potential value ``1 - K`` at
90 deg to the wake's base pressure :data:`CP_WAKE` at 180 deg (weight ``cos^2 theta_j``; continuous
at 90 deg). The symmetric law alone made a flow from straight behind stagnate on the centre port
and read as a valid headwind of the same speed; in the wake every port reads about the base
pressure, ``q_inf`` is negative and the calibration flags the reading invalid, as a real probe's
would be. Inside the calibrated cone every port is windward (``theta_j <= d + cone < 90 deg``),
so the calibration and everything below are unchanged by it.

Closed forms that follow while every port is windward (used in the tests): with ``n = v_i_B / V``,
``q_alpha = 2 K sin(2 d) q n_x n_z``, ``q_beta = 2 K sin(2 d) q n_x n_y`` and
``q_inf = q (1 - K (1 - n_x^2) - C_ps)``; so eq:aoa is exact to first order in the flow angles
with ``k = 1 / (2 K sin 2d)`` (:meth:`ProbeTip.ideal_k`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from vtoladapt.config import setting
from vtoladapt.layout import BlockLayout, Field
from vtoladapt.probe.errors import require_number

TIP_PARAMS = BlockLayout("probe tip parameters", [
    Field("PORT_ANGLE", 1, "rad", "angle between the probe axis and each peripheral port's normal"),
    Field("PRESSURE_FACTOR", 1, "-", "K in Cp = 1 - K sin^2(theta)"),
    Field("STATIC_COEFFICIENT", 1, "-", "pressure coefficient of the q_inf sensor's static reference"),
])
"""Layout of the tip kernel array (:meth:`ProbeTip.to_kernel`)."""
TIP_PORT_ANGLE_RAD, TIP_PRESSURE_FACTOR, TIP_STATIC_COEFFICIENT = TIP_PARAMS.offsets(
    "PORT_ANGLE", "PRESSURE_FACTOR", "STATIC_COEFFICIENT")
TIP_KERNEL_SIZE = TIP_PARAMS.size

CP_WAKE = -0.3
"""Base pressure coefficient behind the tip, where the flow has separated: a sphere's base pressure
is -0.2 to -0.4 at the probe's Reynolds numbers (1e3-1e5; Achenbach 1972, J. Fluid Mech. 54)."""

# Order of the ports in probe_port_pressures' output.
PORT_NAMES = ("centre", "bottom", "top", "right", "left", "static")


@dataclass(frozen=True)
class ProbeTip:
    """Geometry and pressure law of the probe tip (see the module docstring).

    Parameters
    ----------
    port_angle_deg : float
        Angle between the probe axis and each peripheral port's surface normal (deg), in (0, 90).
    pressure_factor : float
        ``K`` in ``Cp = 1 - K sin^2(theta)``; 9/4 is potential flow over a sphere.
    static_port_coefficient : float
        Pressure coefficient of the q_inf sensor's static reference (0 = free-stream static).
    """

    port_angle_deg: float = setting(
        "deg", "angle between the probe axis and each peripheral port's surface normal",
        default=45.0, gt=0.0, lt=90.0)
    pressure_factor: float = setting(
        "-", "K in Cp = 1 - K sin^2(theta); 9/4 = potential flow over a sphere",
        default=2.25, gt=0.0, le=10.0)
    static_port_coefficient: float = setting(
        "-", "pressure coefficient of the static reference of the q_inf sensor",
        default=0.0, gt=-1.0, lt=1.0)

    def __post_init__(self) -> None:
        where = "ProbeTip"
        require_number(where, "port_angle_deg", self.port_angle_deg, gt=0.0, lt=90.0, unit="deg")
        require_number(where, "pressure_factor", self.pressure_factor, gt=0.0, le=10.0)
        require_number(where, "static_port_coefficient", self.static_port_coefficient,
                       gt=-1.0, lt=1.0)

    def to_kernel(self) -> np.ndarray:
        """Tip parameters as the float64 array the kernels take.

        Returns
        -------
        numpy.ndarray
            ``[port_angle_rad, pressure_factor, static_port_coefficient]``.
        """
        return TIP_PARAMS.pack(PORT_ANGLE=math.radians(self.port_angle_deg),
                               PRESSURE_FACTOR=self.pressure_factor,
                               STATIC_COEFFICIENT=self.static_port_coefficient)

    def ideal_k(self) -> float:
        """eq:aoa's ``k`` that is exact to first order in the flow angles: ``1/(2 K sin 2d)``."""
        d = math.radians(self.port_angle_deg)
        return 1.0 / (2.0 * self.pressure_factor * math.sin(2.0 * d))

    def port_pressures(self, v_i_B, rho) -> np.ndarray:
        """Port pressures (Pa, gauge re free-stream static) for one or many incident velocities.

        Parameters
        ----------
        v_i_B : array_like, shape (3,) or (N, 3)
            Incident velocity in body axes (m/s).
        rho : float or array_like, shape (N,)
            Air density (kg/m^3).

        Returns
        -------
        numpy.ndarray, shape (6,) or (N, 6)
            In the order of :data:`PORT_NAMES`.
        """
        v, r, single = _as_batch(v_i_B, rho)
        out = np.empty((v.shape[0], 6))
        _port_pressures_batch(v, r, self.to_kernel(), out)
        return out[0] if single else out

    def differential_pressures(self, v_i_B, rho) -> np.ndarray:
        """``[q_inf, q_alpha, q_beta]`` (Pa) for one or many incident velocities (no sensor).

        Parameters
        ----------
        v_i_B : array_like, shape (3,) or (N, 3)
            Incident velocity in body axes (m/s).
        rho : float or array_like, shape (N,)
            Air density (kg/m^3).

        Returns
        -------
        numpy.ndarray, shape (3,) or (N, 3)
        """
        v, r, single = _as_batch(v_i_B, rho)
        out = np.empty((v.shape[0], 3))
        _differential_pressures_batch(v, r, self.to_kernel(), out)
        return out[0] if single else out


def _as_batch(v_i_B, rho) -> tuple[np.ndarray, np.ndarray, bool]:
    v = np.asarray(v_i_B, dtype=float)
    single = v.ndim == 1
    v = np.ascontiguousarray(np.atleast_2d(v))
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"v_i_B must have shape (3,) or (N, 3), got {np.shape(v_i_B)}")
    r = np.ascontiguousarray(np.broadcast_to(np.asarray(rho, dtype=float), (v.shape[0],)))
    return v, r, single


@njit(cache=True, inline="always")
def port_pressure_coefficient(cos_theta, K):
    """``Cp`` of a port whose normal makes ``theta`` with the direction the air comes from.

    Windward (``cos theta >= 0``): ``1 - K sin^2 theta``; leeward: from ``1 - K`` at 90 deg to
    :data:`CP_WAKE` at 180 deg with weight ``cos^2 theta`` (see the module notes).
    """
    c2 = cos_theta * cos_theta
    if cos_theta >= 0.0:
        return 1.0 - K * (1.0 - c2)
    return (1.0 - K) * (1.0 - c2) + CP_WAKE * c2


# inline="always" here and below: the simulator's airflow-probe channel calls these every tick, and
# as separate calls their array arguments' reference counting cost more than their arithmetic.
@njit(cache=True, inline="always")
def _ports(v_i_B, rho, tip):
    """(centre, bottom, top, right, left, static) pressures; see probe_port_pressures."""
    vx = v_i_B[0]
    vy = v_i_B[1]
    vz = v_i_B[2]
    V2 = vx * vx + vy * vy + vz * vz
    q = 0.5 * rho * V2
    if not np.isfinite(q):
        return (np.nan, np.nan, np.nan, np.nan, np.nan, np.nan)
    if V2 == 0.0:
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    K = tip[TIP_PRESSURE_FACTOR]
    V = np.sqrt(V2)
    nx = vx / V
    ny = vy / V
    nz = vz / V
    c = np.cos(tip[TIP_PORT_ANGLE_RAD])
    s = np.sin(tip[TIP_PORT_ANGLE_RAD])
    # cos(theta_j) = n_j . (v_i / V): the air arrives from the direction +v_i.
    cos_b = c * nx + s * nz
    cos_t = c * nx - s * nz
    cos_r = c * nx + s * ny
    cos_l = c * nx - s * ny
    return (q * port_pressure_coefficient(nx, K),
            q * port_pressure_coefficient(cos_b, K),
            q * port_pressure_coefficient(cos_t, K),
            q * port_pressure_coefficient(cos_r, K),
            q * port_pressure_coefficient(cos_l, K),
            q * tip[TIP_STATIC_COEFFICIENT])


@njit(cache=True)
def probe_port_pressures(v_i_B, rho, tip, out_p):
    """Port pressures of the tip for incident velocity ``v_i_B`` (potential flow; the wake law on leeward ports).

    Parameters
    ----------
    v_i_B : float64[3]
        Incident velocity in body axes FRD (m/s).
    rho : float
        Air density (kg/m^3).
    tip : float64[3]
        :meth:`ProbeTip.to_kernel`.
    out_p : float64[6]
        Written: pressures (Pa, gauge re free-stream static) at the centre, bottom (+z), top
        (-z), right (+y), left (-y) ports and the static reference. All zero when ``V == 0``;
        NaN when an input is not finite.
    """
    p = _ports(v_i_B, rho, tip)
    for j in range(6):
        out_p[j] = p[j]


@njit(cache=True, inline="always")
def probe_differential_pressures(v_i_B, rho, tip, out_q):
    """The three differential pressures the probe's sensors see (no sensor effects).

    ``q_inf = p_centre - p_static``, ``q_alpha = p_bottom - p_top``, ``q_beta = p_right -
    p_left`` (see the module docstring for the port geometry and the pressure law).

    Parameters
    ----------
    v_i_B : float64[3]
        Incident velocity in body axes FRD (m/s).
    rho : float
        Air density (kg/m^3).
    tip : float64[3]
        :meth:`ProbeTip.to_kernel`.
    out_q : float64[3]
        Written: ``[q_inf, q_alpha, q_beta]`` (Pa).
    """
    p = _ports(v_i_B, rho, tip)
    out_q[0] = p[0] - p[5]
    out_q[1] = p[1] - p[2]
    out_q[2] = p[3] - p[4]


@njit(cache=True)
def _port_pressures_batch(v, rho, tip, out):
    for i in range(v.shape[0]):
        probe_port_pressures(v[i], rho[i], tip, out[i])


@njit(cache=True)
def _differential_pressures_batch(v, rho, tip, out):
    for i in range(v.shape[0]):
        probe_differential_pressures(v[i], rho[i], tip, out[i])
