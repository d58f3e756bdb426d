"""Control surfaces in the plant: what a deflection does and how a servo moves.

A surface ``j`` (the vehicle file's ``[[surfaces]]``, :class:`vtoladapt.vehicle.Surface`) deflected by
``delta_j`` (rad) adds the body force and moment

    F = q S [CX, CY, CZ]_j delta_j,   M = q S [b Cl, c Cm, b Cn]_j delta_j,   q = rho |v_i|^2 / 2,

with ``v_i`` the incident flow at the aircraft (eq:vi): effectiveness is proportional to the dynamic
pressure of the free stream and linear in deflection (thin-airfoil flap theory below stall; the stall of
the surface itself is not modelled -- the deflection limits keep it small). **No slipstream counts.** The
pusher sits at the tail, behind every surface, so its slipstream leaves the airframe rearward (a pusher's
inflow ahead of the disk is a small fraction of its slipstream speed); the lift rotors' wakes go down,
on booms outboard of the fuselage and ahead of / behind the wing panels that carry the surfaces, and the
paper gives nothing to calibrate an interaction against (the plant models no rotor/wing interaction for
the wing either). So in hover the surfaces do nothing, as a real standard VTOL's do nearly nothing, and
the allocator must not lean on them there.

A servo follows its command (clipped to the deflection limit) as a first-order lag of time constant
``tau`` whose slew rate is limited to ``R``:

    d delta / dt = clip((c - delta) / tau, -R, R).

With the command held this has a closed form, used by the fixed-step plant at each RK4 stage time: while
``|c - delta| > R tau`` the surface slews at ``R`` (for ``t1 = (|e0| - R tau) / R``), then the gap decays
as ``e(t) = e1 exp(-(t - t1) / tau)`` from ``|e1| = R tau``. Exact, so the servo adds no integration error.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..layout import N_SURFACES

#: Rate limit used when the servo has none (the lag off or a file that states none): never binding.
NO_RATE_LIMIT = 1e12


@njit(cache=True, nogil=True, inline="always")
def servo_response(delta0, c, s, tau, rate) -> float:
    """Deflection ``s`` seconds after ``delta0`` of a servo held at command ``c`` (rad): the closed form of
    the module docstring (first-order lag ``tau`` with slew limit ``rate``)."""
    e = delta0 - c
    ae = abs(e)
    knee = rate * tau
    if ae > knee:
        t1 = (ae - knee) / rate
        sgn = 1.0 if e > 0.0 else -1.0
        if s <= t1:
            return delta0 - sgn * rate * s
        e = sgn * knee
        s = s - t1
    return c + e * np.exp(-s / tau)


def servo_response_reference(delta0: float, c: float, t_s: np.ndarray, tau: float, rate: float) -> np.ndarray:
    """The same servo integrated numerically (``scipy.integrate.solve_ivp``): the independent check of
    :func:`servo_response` (tests)."""
    from scipy.integrate import solve_ivp

    sol = solve_ivp(lambda _t, d: [min(max((c - d[0]) / tau, -rate), rate)], (0.0, float(t_s[-1])), [delta0],
                    t_eval=t_s, rtol=1e-11, atol=1e-13, max_step=tau / 20.0)
    return sol.y[0]


def surface_kernel_fields(vehicle, effectiveness, tau_factors, servo_lag: bool) -> dict:
    """The plant parameters of the vehicle's surfaces (fields ``SURF_*`` of the plant's parameter layout).

    ``effectiveness``: the true effectiveness of each surface slot over the vehicle file's (1 = as the
    file says); ``tau_factors``: each servo's true time constant over the file's. Unused slots get zero
    derivatives (they do nothing), a zero limit and a unit lag.
    """
    S = vehicle.geometry.wing_area_m2
    b = vehicle.geometry.wingspan_m
    c = vehicle.wing_chord_m
    F = np.zeros((N_SURFACES, 3))
    M = np.zeros((N_SURFACES, 3))
    limit = np.zeros(N_SURFACES)
    tau = np.ones(N_SURFACES)
    rate = np.full(N_SURFACES, NO_RATE_LIMIT)
    for j, sf in enumerate(vehicle.surfaces):
        cx, cy, cz, cl, cm, cn = sf.derivatives_per_rad
        k = float(effectiveness[j])
        F[j] = k * S * np.array([cx, cy, cz])
        M[j] = k * S * np.array([b * cl, c * cm, b * cn])
        limit[j] = math.radians(sf.limit_deg)
        tau[j] = sf.time_constant_s * float(tau_factors[j])
        rate[j] = math.radians(sf.rate_limit_degps)
    return {"SURF_F": F.ravel(), "SURF_M": M.ravel(), "SURF_LIMIT": limit, "SURF_TAU": tau, "SURF_RATE": rate,
            "SERVO_LAG_ON": float(servo_lag), "N_SURF": float(len(vehicle.surfaces))}


def surface_force_moment(vehicle, delta_rad, airspeed_mps: float, air_density_kgpm3: float) -> tuple:
    """``(F_B, M_B)``: the body force (N) and moment (N m) of the vehicle file's surfaces at deflections
    ``delta_rad`` and airspeed (the analytic formula of the module docstring, in Python; tests compare the
    compiled plant to it)."""
    q = 0.5 * air_density_kgpm3 * airspeed_mps**2
    S = vehicle.geometry.wing_area_m2
    b = vehicle.geometry.wingspan_m
    c = vehicle.wing_chord_m
    F = np.zeros(3)
    M = np.zeros(3)
    for sf, d in zip(vehicle.surfaces, delta_rad):
        cx, cy, cz, cl, cm, cn = sf.derivatives_per_rad
        F += q * S * d * np.array([cx, cy, cz])
        M += q * S * d * np.array([b * cl, c * cm, b * cn])
    return F, M
