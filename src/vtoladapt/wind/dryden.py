"""Dryden turbulence (MIL-F-8785C): spectra, the low-altitude model and its exact discretisation.

Frozen turbulence convected past the aircraft at airspeed ``V``: a spatial frequency ``Omega``
(rad/m) is met at the temporal frequency ``omega = V Omega`` (rad/s). The one-sided spatial
spectra, with ``int_0^inf Phi(Omega) dOmega = sigma^2``, are

    Phi_u(Omega) = sigma_u^2 (2 L_u / pi) / (1 + (L_u Omega)^2)
    Phi_v(Omega) = sigma_v^2 (L_v / pi) (1 + 3 (L_v Omega)^2) / (1 + (L_v Omega)^2)^2
    Phi_w(Omega) = sigma_w^2 (L_w / pi) (1 + 3 (L_w Omega)^2) / (1 + (L_w Omega)^2)^2

(in Hz: ``S(f) = (2 pi / V) Phi(2 pi f / V)``, see :func:`dryden_psd`), whose autocorrelations in
time are ``R_u(tau) = sigma_u^2 exp(-|tau| / T_u)`` and
``R_v(tau) = sigma_v^2 exp(-|tau| / T_v) (1 - |tau| / (2 T_v))`` with ``T = L / V``.

Low-altitude model (h < 1000 ft, h in feet, W20 = wind speed at 20 ft)::

    L_w = h,   L_u = L_v = h / (0.177 + 0.000823 h)^1.2
    sigma_w = 0.1 W20,   sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4

(see :func:`dryden_low_altitude`). W20 is 15 / 30 / 45 kt for light / moderate / severe
turbulence. The intensities may instead be given directly, or as a fraction of the mean wind speed
(the turbulence intensity of a wind tunnel, so a fan array that is off gives no turbulence).

Components: ``u`` along the horizontal mean wind direction (fixed once from the fan-array direction
and the constant wind), ``v`` horizontal and 90 degrees to its right, ``w`` down.
``V`` is the magnitude of the mean wind (fan plus constant; for a vehicle holding position this is
its airspeed) with a floor, or a fixed ``convection_speed_mps``.

Discretisation (exact at the sample instants for ``V``, ``sigma``, ``L`` held over a step): every
filter state is normalised to unit stationary variance and the output is scaled by ``sigma``.
With ``x = V dt / L``:

* ``u``: ``s <- exp(-x) s + sqrt(1 - exp(-2x)) n``.
* ``v`` and ``w``: two cascaded first-order stages ``s2' = -a s2 + 2 sqrt(a) n(t)``,
  ``s1' = -a s1 + a s2`` (``a = V / L``), output ``c1 s1 + c2 s2`` with
  ``c1 = (1 - sqrt 3) / 2``, ``c2 = sqrt 3 / 2``. This realises the transfer function
  ``(1 + sqrt 3 T s) / (1 + T s)^2`` with unit variance and the autocorrelation above. The state
  transition is ``exp(-x) [[1, x], [0, 1]]`` and the noise covariance over a step is
  ``[[1 - e^{-2x}(1 + 2x + 2x^2), 1 - e^{-2x}(1 + 2x)], [., 2 (1 - e^{-2x})]]`` (series for small
  ``x``, where these cancel), drawn through its Cholesky factor.

The sampled sequence therefore has exactly the Dryden autocorrelation at multiples of ``dt``; its
spectrum is the continuous Dryden spectrum folded at the Nyquist frequency. :func:`initial_state`
draws the filter states from their stationary distribution, so the turbulence
is statistically stationary from t = 0. The step coefficients are kept in the state and
recomputed only when ``V dt`` changes (while the fan spins up, or when ``dt`` changes).

A wind part (:mod:`vtoladapt.wind.registry`, the interface of :mod:`vtoladapt.parts`), after the
steady ones, whose mean wind it reads: :func:`pack_turbulence` lays the configuration out as
:data:`TURBULENCE_PARAMS`, the filter state is :data:`TURBULENCE_STATE`, :func:`initial_state` draws
the stationary start (``TURBULENCE_DRAWS_INITIAL`` standard normals), and :func:`step` consumes
``TURBULENCE_DRAWS_PER_STEP`` standard normals per step, whether turbulence is on or not.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..config import ConfigError, Validated, setting
from ..layout import W_MEAN_W, W_V_W, BlockLayout, Field
from .registry import wind_step

FT_M = 0.3048
"""One foot in metres."""
KNOT_MPS = 1852.0 / 3600.0
"""One knot in m/s."""

TURBULENCE_DRAWS = BlockLayout("Dryden draws per step (standard normals)", [
    Field("U", 1, "-", "u filter"),
    Field("V", 2, "-", "v filter, two stages"),
    Field("W", 2, "-", "w filter, two stages"),
])
_D_U, _D_V, _D_W = TURBULENCE_DRAWS.offsets("U", "V", "W")
TURBULENCE_DRAWS_PER_STEP = TURBULENCE_DRAWS.size
"""Standard normals every step consumes."""
TURBULENCE_DRAWS_INITIAL = TURBULENCE_DRAWS.size
"""Standard normals :func:`initial_state` draws (the stationary initial state: one per filter state,
as many as a step's)."""

TURBULENCE_PARAMS = BlockLayout("Dryden parameters", [
    Field("ON", 1, "-", "1.0 if turbulence is on"),
    Field("FRACTION", 1, "-", "1.0: sigma = SIGMA x |mean wind|; 0.0: sigma = SIGMA (m/s)"),
    Field("SIGMA", 3, "m/s or -", "sigma_u, sigma_v, sigma_w, or fractions of the mean wind"),
    Field("L", 3, "m", "length scales L_u, L_v, L_w"),
    Field("V_FIXED", 1, "m/s", "convection speed if >= 0; < 0: use |mean wind|"),
    Field("V_MIN", 1, "m/s", "floor of the convection speed"),
    Field("AXIS", 2, "-", "unit vector (N, E) of the turbulence u axis"),
])
"""Dryden's block of the wind parameter array."""
_ON, _FRACTION, _SIGMA, _L, _V_FIXED, _V_MIN, _AXIS = TURBULENCE_PARAMS.offsets(
    "ON", "FRACTION", "SIGMA", "L", "V_FIXED", "V_MIN", "AXIS")

TWO_POLE_COEFFICIENTS = BlockLayout("two-pole filter step coefficients", [
    Field("X", 1, "-", "x = V dt / L"),
    Field("DECAY", 1, "-", "exp(-x)"),
    Field("L11", 1, "-", "Cholesky factor of the step noise covariance"),
    Field("L21", 1, "-", "Cholesky factor of the step noise covariance"),
    Field("L22", 1, "-", "Cholesky factor of the step noise covariance"),
])
"""The cached step coefficients of the v or w filter."""
_TP_X, _TP_DECAY, _TP_L11, _TP_L21, _TP_L22 = TWO_POLE_COEFFICIENTS.offsets("X", "DECAY", "L11", "L21", "L22")

TURBULENCE_STATE = BlockLayout("Dryden state", [
    Field("U", 1, "-", "normalised u filter state"),
    Field("V", 2, "-", "normalised v filter states s1, s2"),
    Field("W", 2, "-", "normalised w filter states s1, s2"),
    Field("KEY", 1, "m", "V dt the cached coefficients below were computed for (-1: none yet)"),
    Field("COEF_U", 2, "-", "u filter: exp(-x), sqrt(1 - exp(-2x))"),
    Field("COEF_V", TWO_POLE_COEFFICIENTS.size, "-", "v filter step coefficients"),
    Field("COEF_W", TWO_POLE_COEFFICIENTS.size, "-", "w filter step coefficients"),
])
"""Dryden's block of the wind state array."""
_S_U, _S_V, _S_W, _S_KEY, _S_COEF_U, _S_COEF_V, _S_COEF_W = TURBULENCE_STATE.offsets(
    "U", "V", "W", "KEY", "COEF_U", "COEF_V", "COEF_W")

_C1 = 0.5 * (1.0 - math.sqrt(3.0))
_C2 = 0.5 * math.sqrt(3.0)
_SERIES_X = 0.1


@dataclass(frozen=True)
class TurbulenceConfig(Validated):
    """Dryden turbulence (MIL-F-8785C); give exactly one intensity and at most one length source.

    Intensity: ``w20_mps`` (low-altitude model with ``altitude_m``), ``sigma_mps`` directly, or
    ``mean_wind_fraction`` (sigma = fraction x ``|mean wind|``, a wind tunnel's turbulence
    intensity). Length scales: ``length_scale_m`` directly, else the low-altitude model at
    ``altitude_m``.
    """

    config_section = "wind.turbulence"

    enabled: bool = setting("-", "add Dryden turbulence", default=False)
    w20_mps: float | None = setting(
        "m/s", "wind speed at 20 ft (light 7.7, moderate 15.4, severe 23.2 m/s)", default=None,
        ge=0.0, le=60.0)
    sigma_mps: tuple[float, ...] | None = setting(
        "m/s", "intensities sigma_u, sigma_v, sigma_w", default=None, ge=0.0, le=30.0, length=3)
    mean_wind_fraction: tuple[float, ...] | None = setting(
        "-", "intensities as fractions of the mean wind speed (u, v, w)", default=None, ge=0.0,
        le=1.0, length=3)
    altitude_m: float = setting(
        "m", "height above ground for the low-altitude length scales and W20 intensities",
        default=2.0, ge=1.0, le=1000.0 * FT_M)
    length_scale_m: tuple[float, ...] | None = setting(
        "m", "length scales L_u, L_v, L_w (overrides the altitude model)", default=None, ge=1.0,
        le=10000.0, length=3)
    convection_speed_mps: float | None = setting(
        "m/s", "airspeed at which the frozen field is convected (default: |mean wind|)",
        default=None, ge=0.0, le=100.0)
    min_convection_speed_mps: float = setting(
        "m/s", "floor on |mean wind| as convection speed (0: turbulence freezes in still air)",
        default=0.5, ge=0.0, le=100.0)

    def _check(self, source: str) -> None:
        given = [k for k in ("w20_mps", "sigma_mps", "mean_wind_fraction")
                 if getattr(self, k) is not None]
        if self.enabled and len(given) != 1:
            raise ConfigError(
                f"{source}: [wind.turbulence] enabled = true needs exactly one of w20_mps, "
                f"sigma_mps, mean_wind_fraction; got {', '.join(given) if given else 'none'}")
        if len(given) > 1:
            raise ConfigError(
                f"{source}: [wind.turbulence] {', '.join(given)}: give only one intensity source")

    def intensities_and_lengths(self) -> tuple[np.ndarray, np.ndarray]:
        """``(sigma, L)``: sigma in m/s (or fractions, for ``mean_wind_fraction``) and L in m."""
        sigma_lo, length_lo = dryden_low_altitude(self.altitude_m, self.w20_mps or 0.0)
        if self.sigma_mps is not None:
            sigma = np.array(self.sigma_mps, dtype=float)
        elif self.mean_wind_fraction is not None:
            sigma = np.array(self.mean_wind_fraction, dtype=float)
        else:
            sigma = sigma_lo
        length = (np.array(self.length_scale_m, dtype=float) if self.length_scale_m is not None
                  else length_lo)
        return sigma, length


def pack_turbulence(turbulence: TurbulenceConfig, axis_NE) -> np.ndarray:
    """Turbulence as its kernel block (layout :data:`TURBULENCE_PARAMS`); ``axis_NE`` is the unit
    (N, E) vector of the ``u`` axis (the mean wind's horizontal direction)."""
    sigma, length = turbulence.intensities_and_lengths()
    return TURBULENCE_PARAMS.pack(
        ON=1.0 if turbulence.enabled else 0.0,
        FRACTION=1.0 if turbulence.mean_wind_fraction is not None else 0.0,
        SIGMA=sigma, L=length,
        V_FIXED=-1.0 if turbulence.convection_speed_mps is None else turbulence.convection_speed_mps,
        V_MIN=turbulence.min_convection_speed_mps, AXIS=axis_NE)


def dryden_low_altitude(altitude_m: float, w20_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """MIL-F-8785C low-altitude Dryden intensities and length scales.

    Parameters
    ----------
    altitude_m : float
        Height above ground (m), in (0, 304.8] (the model holds below 1000 ft).
    w20_mps : float
        Wind speed at 20 ft (m/s): 15 / 30 / 45 kt for light / moderate / severe turbulence.

    Returns
    -------
    sigma_mps : numpy.ndarray, shape (3,)
        ``sigma_u, sigma_v, sigma_w`` (m/s): ``sigma_w = 0.1 W20``,
        ``sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4`` (h in ft).
    length_m : numpy.ndarray, shape (3,)
        ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2``, ``L_w = h`` (computed in ft, returned in m).
    """
    if not 0.0 < altitude_m <= 1000.0 * FT_M:
        raise ValueError(f"altitude_m = {altitude_m!r}: the low-altitude model needs 0 < h <= "
                         "304.8 m (1000 ft)")
    h_ft = altitude_m / FT_M
    base = 0.177 + 0.000823 * h_ft
    sigma_w = 0.1 * w20_mps
    sigma_uv = sigma_w / base**0.4
    L_uv_ft = h_ft / base**1.2
    return (np.array([sigma_uv, sigma_uv, sigma_w]),
            np.array([L_uv_ft, L_uv_ft, h_ft]) * FT_M)


def dryden_psd(component: str, f_hz, sigma_mps: float, length_m: float,
               airspeed_mps: float) -> np.ndarray:
    """One-sided Dryden power spectral density in time, (m/s)^2 / Hz (MIL-F-8785C).

    ``S(f) = (2 pi / V) Phi(Omega = 2 pi f / V)`` with ``Phi`` the spatial spectra in the module
    notes, so ``int_0^inf S(f) df = sigma^2``.

    Parameters
    ----------
    component : {"u", "v", "w"}
    f_hz : array_like
        Frequencies (Hz), >= 0.
    sigma_mps, length_m, airspeed_mps : float
        Intensity (m/s), length scale (m), convection airspeed (m/s, > 0).
    """
    if component not in ("u", "v", "w"):
        raise ValueError(f"component = {component!r}: allowed 'u', 'v', 'w'")
    if not airspeed_mps > 0.0:
        raise ValueError(f"airspeed_mps = {airspeed_mps!r}: must be > 0")
    omega = 2.0 * np.pi * np.asarray(f_hz, dtype=float) / airspeed_mps
    lo2 = (length_m * omega) ** 2
    if component == "u":
        phi = sigma_mps**2 * (2.0 * length_m / np.pi) / (1.0 + lo2)
    else:
        phi = sigma_mps**2 * (length_m / np.pi) * (1.0 + 3.0 * lo2) / (1.0 + lo2) ** 2
    return 2.0 * np.pi / airspeed_mps * phi


# --- kernels (``po``, ``so``: offsets of the Dryden blocks in the parameter and state arrays) ------

@njit(cache=True, inline="always")
def _two_pole_noise_cov(x: float) -> tuple:
    """Noise covariance ``(q11, q12, q22)`` of the normalised two-pole Dryden filter over ``x = a dt``."""
    if x < _SERIES_X:
        # 1 - e^{-2x}(...) cancels for small x; integrate the series of 4 s^m e^{-2s} instead.
        q11 = 0.0
        q12 = 0.0
        term = 1.0  # (-2)^n / n!
        xn = 1.0    # x^n
        for n in range(16):
            q11 += term * xn * x * x * x / (n + 3)
            q12 += term * xn * x * x / (n + 2)
            term *= -2.0 / (n + 1)
            xn *= x
        q11 *= 4.0
        q12 *= 4.0
    else:
        e2 = np.exp(-2.0 * x)
        q11 = 1.0 - e2 * (1.0 + 2.0 * x + 2.0 * x * x)
        q12 = 1.0 - e2 * (1.0 + 2.0 * x)
    q22 = -2.0 * np.expm1(-2.0 * x)
    return q11, q12, q22


@njit(cache=True, inline="always")
def _two_pole_coefficients(state: np.ndarray, c: int, x: float) -> None:
    """Store ``x, exp(-x)`` and the Cholesky factor of the step noise covariance at ``state[c:]`` (layout :data:`TWO_POLE_COEFFICIENTS`)."""
    q11, q12, q22 = _two_pole_noise_cov(x)
    l11 = np.sqrt(q11)
    l21 = q12 / l11 if l11 > 0.0 else 0.0
    state[c + _TP_X] = x
    state[c + _TP_DECAY] = np.exp(-x)
    state[c + _TP_L11] = l11
    state[c + _TP_L21] = l21
    state[c + _TP_L22] = np.sqrt(max(q22 - l21 * l21, 0.0))


@njit(cache=True, inline="always")
def _two_pole_advance(state: np.ndarray, i: int, c: int, n1: float, n2: float) -> None:
    """Advance the normalised two-pole filter states ``state[i], state[i+1]`` one step."""
    x = state[c + _TP_X]
    e = state[c + _TP_DECAY]
    s1 = state[i]
    s2 = state[i + 1]
    # state transition exp(A dt) = e^{-x} [[1, x], [0, 1]] for s1' = -a s1 + a s2, s2' = -a s2
    state[i] = e * (s1 + x * s2) + state[c + _TP_L11] * n1
    state[i + 1] = e * s2 + state[c + _TP_L21] * n1 + state[c + _TP_L22] * n2


def initial_state(params: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A Dryden state drawn from the filters' stationary law (``TURBULENCE_DRAWS_INITIAL`` standard
    normals from ``rng``, on or off): ``s_u ~ N(0, 1)``, ``(s1, s2) ~ N(0, [[1, 1], [1, 2]])`` for v
    and w; no step coefficients cached yet."""
    a, b1, b2, c1, c2 = (float(z) for z in rng.standard_normal(TURBULENCE_DRAWS_INITIAL))
    state = np.zeros(TURBULENCE_STATE.size)
    state[_S_U] = a
    state[_S_V] = b1
    state[_S_V + 1] = b1 + b2
    state[_S_W] = c1
    state[_S_W + 1] = c1 + c2
    state[_S_KEY] = -1.0
    return state


@njit(cache=True, inline="always")
def turbulence_step(params: np.ndarray, po: int, state: np.ndarray, so: int, m0: float, m1: float,
                    m2: float, dt: float, draws: np.ndarray, out_v_W: np.ndarray) -> None:
    """Add the turbulence at this tick to ``out_v_W`` (NED, m/s) and advance the filters by ``dt``.

    ``(m0, m1, m2)`` is the mean wind (NED, m/s) that scales fractional intensities and convects
    the frozen field; ``draws`` holds ``TURBULENCE_DRAWS_PER_STEP`` standard normals for this step.
    """
    n_u = draws[_D_U]
    n_v1 = draws[_D_V]
    n_v2 = draws[_D_V + 1]
    n_w1 = draws[_D_W]
    n_w2 = draws[_D_W + 1]
    if params[po + _ON] == 0.0:
        return

    speed = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    scale = speed if params[po + _FRACTION] != 0.0 else 1.0
    su = params[po + _SIGMA] * scale
    sv = params[po + _SIGMA + 1] * scale
    sw = params[po + _SIGMA + 2] * scale
    tu = su * state[so + _S_U]
    tv = sv * (_C1 * state[so + _S_V] + _C2 * state[so + _S_V + 1])
    tw = sw * (_C1 * state[so + _S_W] + _C2 * state[so + _S_W + 1])
    eN = params[po + _AXIS]
    eE = params[po + _AXIS + 1]
    # u along the mean wind, v 90 degrees to its right (east of north), w down
    out_v_W[0] += tu * eN - tv * eE
    out_v_W[1] += tu * eE + tv * eN
    out_v_W[2] += tw

    V = params[po + _V_FIXED]
    if V < 0.0:
        V = max(speed, params[po + _V_MIN])
    key = V * dt
    if key != state[so + _S_KEY]:
        # the coefficients depend on V dt / L only: recompute when the mean wind or dt changes
        xu = key / params[po + _L]
        em1 = np.expm1(-xu)
        state[so + _S_COEF_U] = 1.0 + em1
        state[so + _S_COEF_U + 1] = np.sqrt(-em1 * (2.0 + em1))   # sqrt(1 - exp(-2x))
        _two_pole_coefficients(state, so + _S_COEF_V, key / params[po + _L + 1])
        _two_pole_coefficients(state, so + _S_COEF_W, key / params[po + _L + 2])
        state[so + _S_KEY] = key
    state[so + _S_U] = state[so + _S_COEF_U] * state[so + _S_U] + state[so + _S_COEF_U + 1] * n_u
    _two_pole_advance(state, so + _S_V, so + _S_COEF_V, n_v1, n_v2)
    _two_pole_advance(state, so + _S_W, so + _S_COEF_W, n_w1, n_w2)


# --- the part (vtoladapt.parts) -----------------------------------------------------------------
Settings = TurbulenceConfig
PARAMS = TURBULENCE_PARAMS
STATE = TURBULENCE_STATE
NORMALS_PER_STEP = TURBULENCE_DRAWS_PER_STEP
UNIFORMS_PER_STEP = 0


def pack(settings: TurbulenceConfig, wind) -> np.ndarray:
    """The part's parameter block, its ``u`` axis along the mean wind of ``wind`` (the whole
    :class:`~vtoladapt.wind.WindConfig`; :meth:`~vtoladapt.wind.WindConfig.turbulence_axis_NE`)."""
    return pack_turbulence(settings, wind.turbulence_axis_NE())


@wind_step
def step(params, state, t, dt, p_W, draws, wind):
    """Add the turbulence to the tick's wind, convected by and scaled with the parts' mean wind before it."""
    turbulence_step(params, 0, state, 0, wind[W_MEAN_W], wind[W_MEAN_W + 1], wind[W_MEAN_W + 2], dt, draws,
                    wind[W_V_W:W_V_W + 3])
