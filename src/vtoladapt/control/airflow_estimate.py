"""The airflow the probe cannot see, estimated from the force the controller's model cannot explain.

Why (issue #11): with the wind from behind or from the side the airflow probe reports "invalid,
near zero" (the flow is outside its calibrated cone), the same as in still air. The front end
(:mod:`.frontend`) then flies ``v_i = R^T (v - w_hat)`` with a wind estimate ``w_hat`` learned only
while the probe was valid: for a wind that starts from behind it is ~0, so the controller turns
into a wind it cannot place and the regressor has no wind in it.

What: the model's body force ``f_b-hat(v_i, u, theta-hat)`` (:func:`vtoladapt.forces.body_force`) is
a known function of the incident velocity. Its body-horizontal part (x, y) is matched to the
filtered measured specific force ``a_m`` by choosing the horizontal wind ``w = (w_N, w_E)`` (world,
NED; ``w_D`` is kept), with ``v_i = R^T (v - w)``: two equations, two unknowns, solved by
Gauss-Newton with a small Levenberg damping on the model's analytic Jacobian
(:func:`vtoladapt.forces.body_force_jacobian`, tested against finite differences), chained with
``d v_i / d w = -R^T`` (its first two columns).

* **Start.** Warm: the last accepted solution. Cold (the estimate was off): along the unexplained
  force ``a_m - f_b-hat`` at the current ``v_i`` (drag points downwind, so the wind blows that
  way), at the best of :data:`COLD_START_AIRSPEEDS_MPS` (the model's force grows with airspeed,
  so the best of a few trial speeds starts Gauss-Newton on the right branch).
* **Steps.** At most :data:`MAX_ITERATIONS` per call (:data:`MAX_ITERATIONS_COLD` from a cold
  start), each limited to :data:`MAX_STEP_MPS` and
  halved (up to :data:`MAX_HALVINGS` times) until the residual does not grow.
* **Accepted only if** every input is finite, the Jacobian is not degenerate (``J^T J`` trace above
  :data:`MIN_CURVATURE`: the model's horizontal force must depend on the wind), the final residual
  is at most ``tol`` (the caller passes the unseen-flow "off" threshold: the estimate explains the
  force to within what the detector calls explained), and the airspeed ``|v_i|`` is at most
  ``airspeed_max`` (the probe's maximum). Otherwise "no estimate" (``ok = False``); the outputs are
  then the start values, never NaN.

Measured (README, envelope section): off by default. From behind at 3-4 m/s the model's horizontal force
matches the simulated aircraft's (0.27 against 0.28 m/s^2), but that force is only 0.1-0.3 m/s^2 at
2-5 m/s, the size of the accelerometer's bias and the filter's lag, and the force grows only like
``V^0.6`` there (the rotors' in-plane drag): the solved airspeed was off by a median 1.6 m/s at 3.4 m/s.
From the side the model has a fifth of the aircraft's side force. The estimate is kept as a tested option.

Limitation, stated: the fit makes the *horizontal* prediction error small by construction while it
is used; the vertical component, the tracking and the truth (``v_i`` in the simulator's log) are
the independent checks. The controller's model has no wing side force (C_Y = 0), so a flow from the
side is placed by the rotors' in-plane drag alone, whose size the model may not know well: the
direction is the robust part, the airspeed less so.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..forces import SIDESLIP_LINEAR_DEG, body_force, body_force_jacobian
from ..frames import rows_transpose_times

COLD_START_AIRSPEEDS_MPS = (1.5, 3.0, 5.0, 7.5, 10.0, 13.0)
"""Trial airspeeds along the unexplained force's direction for a cold start (m/s)."""
MAX_ITERATIONS = 6
"""Gauss-Newton iterations per call from a warm start (it converges in one or two)."""
MAX_ITERATIONS_COLD = 12
"""Gauss-Newton iterations per call from a cold start. A cold start that did not converge is not
kept, so the next call starts cold from the same point: with six, a flow from 139 deg at 11.75 m/s
stayed at 1.5x the tolerance on every call (found by the property test). On the test's grid of
flows from 70-290 deg at 2-13 m/s (9660 cases), caltech_vtol misses 12 with twelve iterations, 27
with six (px4_standard_vtol none); every miss is a refusal, at 10-13 m/s with u_z <= 0.5."""
MAX_STEP_MPS = 3.0
"""Largest change of the wind estimate per iteration (m/s)."""
MAX_HALVINGS = 4
"""Step halvings tried when a step makes the residual grow."""
MIN_CURVATURE = 1e-8
"""Smallest trace of ``J^T J`` ((m/s^2 per m/s)^2) taken as a solvable problem."""
SIN_SIDESLIP_MAX = float(np.sin(np.radians(SIDESLIP_LINEAR_DEG)))
"""Largest ``|sin beta|`` of an accepted estimate: the model's wing keeps the paper's dynamic pressure up to
:data:`vtoladapt.forces.SIDESLIP_LINEAR_DEG` (30 deg); beyond, its missing side force (C_Y = 0) makes the
inverted airspeed several times too large (a 3.5 m/s side flow feels ~0.5 m/s^2 on the simulated aircraft,
the model gives 0.1)."""
LEVENBERG_DAMPING = 1e-6
"""Relative damping added to ``J^T J`` (times its trace), so a nearly singular direction takes a short step."""


@njit(cache=True)
def horizontal_residual(v_W, R, w_N, w_E, w_D, u_x, u_z, theta, model, a_x, a_y) -> tuple:
    """Model minus measured body-horizontal force for the wind ``(w_N, w_E, w_D)``, and that ``v_i``.

    ``v_i = R^T (v_W - w)`` (eq:vi, ``R`` = ``R_WB`` as three row 3-tuples); the model is
    :func:`vtoladapt.forces.body_force` at ``(v_i, u_x, u_z, theta)``. Returns ``(r_x, r_y, v_i)``
    in m/s^2 (body) and m/s (body).
    """
    v_i = rows_transpose_times(R, (v_W[0] - w_N, v_W[1] - w_E, v_W[2] - w_D))
    f = body_force(v_i, u_x, u_z, theta, model)
    return f[0] - a_x, f[1] - a_y, v_i


# Compiled with reference counting whatever its caller: it allocates its Jacobian scratch, and
# Numba compiles a callee with its caller's setting unless the callee states its own (the
# controller step that reaches it is compiled without, see vtoladapt.sim.loop).
@njit(cache=True, _nrt=True)
def estimate_horizontal_wind(v_W, R, w_D, w_N0, w_E0, cold, u_x, u_z, theta, model, a_x, a_y, tol,
                             airspeed_max, sin_sideslip_max) -> tuple:
    """The horizontal wind that makes the model's body-horizontal force match the measured one.

    Parameters
    ----------
    v_W : 3-tuple, m/s NED
        Vehicle velocity.
    R : three row 3-tuples
        ``R_WB`` (body to world).
    w_D : float, m/s
        Vertical wind, kept.
    w_N0, w_E0 : float, m/s
        Start (the last solution; with ``cold`` only the fallback if the cold start finds no direction).
    cold : bool
        Start along the unexplained force instead of at ``(w_N0, w_E0)`` (module notes).
    u_x, u_z : float
        Throttles (fractions) that produced the measured force.
    theta, model : tuples
        theta-hat (adaptation scaling) and the model constants (:mod:`vtoladapt.forces`).
    a_x, a_y : float, m/s^2
        Measured (filtered) specific force, body x and y.
    tol : float, m/s^2
        Largest accepted residual norm.
    airspeed_max : float, m/s
        Largest accepted ``|v_i|``.
    sin_sideslip_max : float
        Largest accepted ``|v_iy| / |v_i|`` (the front end passes :data:`SIN_SIDESLIP_MAX`; 1 accepts any).

    Returns
    -------
    (ok, w_N, w_E, residual_mps2)
        Whether the estimate is accepted; the wind (the start values when not accepted); the final
        residual norm (inf when the inputs are not finite or the problem is degenerate).
    """
    inputs_finite = (np.isfinite(v_W[0]) and np.isfinite(v_W[1]) and np.isfinite(v_W[2]) and np.isfinite(w_D)
                     and np.isfinite(w_N0) and np.isfinite(w_E0) and np.isfinite(u_x) and np.isfinite(u_z)
                     and np.isfinite(a_x) and np.isfinite(a_y) and np.isfinite(tol)
                     and np.isfinite(airspeed_max) and np.isfinite(sin_sideslip_max))
    for k in range(len(theta)):
        inputs_finite = inputs_finite and np.isfinite(theta[k])
    for i in range(3):
        for j in range(3):
            inputs_finite = inputs_finite and np.isfinite(R[i][j])
    if not inputs_finite:
        return False, 0.0, 0.0, np.inf
    w_N, w_E = w_N0, w_E0
    if cold:
        # the unexplained force a_m - f at the start points downwind (drag): try a few airspeeds of a
        # wind blowing that way (v_i = v - w, so an airspeed V needs |w| ~ V when hovering)
        r_x, r_y, _ = horizontal_residual(v_W, R, w_N0, w_E0, w_D, u_x, u_z, theta, model, a_x, a_y)
        d_N = -(R[0][0] * r_x + R[0][1] * r_y)
        d_E = -(R[1][0] * r_x + R[1][1] * r_y)
        d = np.sqrt(d_N * d_N + d_E * d_E)
        if d > 0.0:
            best = np.inf
            for V in COLD_START_AIRSPEEDS_MPS:
                cN, cE = v_W[0] + V * d_N / d, v_W[1] + V * d_E / d
                s_x, s_y, _ = horizontal_residual(v_W, R, cN, cE, w_D, u_x, u_z, theta, model, a_x, a_y)
                n2 = s_x * s_x + s_y * s_y
                if n2 < best:
                    best, w_N, w_E = n2, cN, cE
    J_v = np.zeros((3, 3))
    J_u = np.zeros((3, 2))
    r_x, r_y, v_i = horizontal_residual(v_W, R, w_N, w_E, w_D, u_x, u_z, theta, model, a_x, a_y)
    n2 = r_x * r_x + r_y * r_y
    for _ in range(MAX_ITERATIONS_COLD if cold else MAX_ITERATIONS):
        if n2 <= 1e-3 * tol * tol:
            break
        body_force_jacobian(v_i, u_x, u_z, theta, model, J_v, J_u)
        # d r_i / d w_k = sum_j J_v[i, j] d v_i,j / d w_k, with d v_i,j / d w_k = -R[k][j]
        a11 = -(J_v[0, 0] * R[0][0] + J_v[0, 1] * R[0][1] + J_v[0, 2] * R[0][2])
        a12 = -(J_v[0, 0] * R[1][0] + J_v[0, 1] * R[1][1] + J_v[0, 2] * R[1][2])
        a21 = -(J_v[1, 0] * R[0][0] + J_v[1, 1] * R[0][1] + J_v[1, 2] * R[0][2])
        a22 = -(J_v[1, 0] * R[1][0] + J_v[1, 1] * R[1][1] + J_v[1, 2] * R[1][2])
        # normal equations (J^T J + mu I) dw = -J^T r
        h11 = a11 * a11 + a21 * a21
        h12 = a11 * a12 + a21 * a22
        h22 = a12 * a12 + a22 * a22
        trace = h11 + h22
        if not trace > MIN_CURVATURE:
            return False, w_N0, w_E0, np.inf
        mu = LEVENBERG_DAMPING * trace
        h11 += mu
        h22 += mu
        g1 = -(a11 * r_x + a21 * r_y)
        g2 = -(a12 * r_x + a22 * r_y)
        det = h11 * h22 - h12 * h12
        if not det > 0.0:
            return False, w_N0, w_E0, np.inf
        s_N = (h22 * g1 - h12 * g2) / det
        s_E = (h11 * g2 - h12 * g1) / det
        s = np.sqrt(s_N * s_N + s_E * s_E)
        if not np.isfinite(s):
            return False, w_N0, w_E0, np.inf
        if s > MAX_STEP_MPS:
            s_N, s_E = s_N * MAX_STEP_MPS / s, s_E * MAX_STEP_MPS / s
        improved = False
        for _h in range(MAX_HALVINGS + 1):
            tN, tE = w_N + s_N, w_E + s_E
            t_x, t_y, t_v = horizontal_residual(v_W, R, tN, tE, w_D, u_x, u_z, theta, model, a_x, a_y)
            t2 = t_x * t_x + t_y * t_y
            if t2 < n2:
                w_N, w_E, r_x, r_y, v_i, n2 = tN, tE, t_x, t_y, t_v, t2
                improved = True
                break
            s_N, s_E = 0.5 * s_N, 0.5 * s_E
        if not improved:
            break
    residual = np.sqrt(n2)
    V = np.sqrt(v_i[0] * v_i[0] + v_i[1] * v_i[1] + v_i[2] * v_i[2])
    # a flow with more sideslip than the model's wing is written for is placed too far out: the model
    # has no wing or fuselage side force (C_Y = 0), an aircraft does (module notes)
    sideslip_ok = abs(v_i[1]) <= sin_sideslip_max * V
    ok = (residual <= tol and V <= airspeed_max and sideslip_ok and np.isfinite(w_N) and np.isfinite(w_E))
    if not ok:
        return False, w_N0, w_E0, residual if np.isfinite(residual) else np.inf
    return True, w_N, w_E, residual
