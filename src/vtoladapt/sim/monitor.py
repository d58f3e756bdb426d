"""Divergence monitor: the flight envelope a run must stay inside, checked every controller tick.

The envelope is stated once, here, as the scenario's ``[envelope]`` table (:class:`EnvelopeConfig`,
units in the names, defaults below). The compiled loop checks the plant state against it at the
start of every tick (:func:`check_envelope`) and once more after the last one; the first
violation stops the run. The log keeps every tick before it (each of them inside the envelope,
so finite), and the result says when and why (:attr:`vtoladapt.sim.results.SimulationResult.diverged_at_s`,
``divergence_reason``). ``[envelope] enabled = false`` switches the limits off, never the check for a
non-finite state: NaN or inf in the state stops the run either way. A diverged run is not an exception
inside a campaign (the campaign counts
it and goes on); a caller that wants one calls :meth:`SimulationResult.raise_if_diverged`, which
raises :class:`DivergenceError`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..config import Validated, setting
from ..errors import RunFailed
from ..layout import REF_P_W, X_OMEGA_B, X_P_W, X_SIZE, X_V_W, BlockLayout, Field

DIVERGENCE_REASONS: tuple[str, ...] = (
    "", "non-finite state", "speed above envelope.max_speed_mps",
    "body rate above envelope.max_body_rate_radps", "height below envelope.min_height_m",
    "height above envelope.max_height_m", "distance from the reference above envelope.max_position_error_m")
"""Reason code (what :func:`check_envelope` returns) -> words; code 0 is "inside the envelope"."""
REASON_OK = DIVERGENCE_REASONS.index("")
REASON_NON_FINITE = DIVERGENCE_REASONS.index("non-finite state")
REASON_SPEED = DIVERGENCE_REASONS.index("speed above envelope.max_speed_mps")
REASON_BODY_RATE = DIVERGENCE_REASONS.index("body rate above envelope.max_body_rate_radps")
REASON_HEIGHT_LOW = DIVERGENCE_REASONS.index("height below envelope.min_height_m")
REASON_HEIGHT_HIGH = DIVERGENCE_REASONS.index("height above envelope.max_height_m")
REASON_POSITION_ERROR = DIVERGENCE_REASONS.index("distance from the reference above envelope.max_position_error_m")

ENVELOPE_PARAMS = BlockLayout("envelope parameters", [
    Field("ON", 1, "-", "1.0: check the envelope"),
    Field("MAX_SPEED", 1, "m/s", "largest |v_W|"),
    Field("MAX_RATE", 1, "rad/s", "largest |omega_B|"),
    Field("MIN_H", 1, "m", "lowest height -p_D"),
    Field("MAX_H", 1, "m", "highest height -p_D"),
    Field("MAX_POS_ERR", 1, "m", "largest |p_W - p_ref_W|"),
])
_E_ON, _E_MAX_SPEED, _E_MAX_RATE, _E_MIN_H, _E_MAX_H, _E_MAX_POS_ERR = ENVELOPE_PARAMS.offsets(
    "ON", "MAX_SPEED", "MAX_RATE", "MIN_H", "MAX_H", "MAX_POS_ERR")


@dataclass(frozen=True)
class EnvelopeConfig(Validated):
    """Where a run stops as diverged (``[envelope]``); defaults are far outside any flight the
    controllers fly, so only a run that has lost the vehicle trips them."""

    config_section = "envelope"

    enabled: bool = setting("-", "stop the run when the state leaves the envelope (a non-finite state stops "
                            "it even when false)", default=True)
    max_speed_mps: float = setting("m/s", "largest ground speed |v_W|", default=50.0, gt=0.0, le=1000.0)
    max_body_rate_radps: float = setting("rad/s", "largest body rate |omega_B| (35 rad/s is a gyro's range)",
                                         default=30.0, gt=0.0, le=1000.0)
    min_height_m: float = setting("m", "lowest height -p_D above the world origin", default=-100.0,
                                  ge=-1e5, le=1e5)
    max_height_m: float = setting("m", "highest height -p_D above the world origin", default=1000.0,
                                  ge=-1e5, le=1e5)
    max_position_error_m: float = setting(
        "m", "largest distance |p_W - p_ref_W| from the reference position: a vehicle blown or flown this far "
        "from where it should be is lost, whatever its speed and height. The default is as far outside the "
        "flights we fly as the height limits: the pusher stuck at full throttle for 4 s (faults/pusher_saturated) "
        "carries the aircraft 180 m away and it flies back; a hold test may set 10",
        default=1000.0, gt=0.0, le=1e6)

    def _check(self, source: str) -> None:
        from ..config import ConfigError

        if not self.min_height_m < self.max_height_m:
            raise ConfigError(f"{source}: [envelope] min_height_m = {self.min_height_m:g}: must be below "
                              f"max_height_m = {self.max_height_m:g}")

    def to_kernel(self) -> np.ndarray:
        """The envelope as the loop's parameter array (:data:`ENVELOPE_PARAMS`)."""
        return ENVELOPE_PARAMS.pack(ON=float(self.enabled), MAX_SPEED=self.max_speed_mps,
                                    MAX_RATE=self.max_body_rate_radps, MIN_H=self.min_height_m,
                                    MAX_H=self.max_height_m, MAX_POS_ERR=self.max_position_error_m)

    def describe_violation(self, code: int, x: np.ndarray, t_s: float, ref: np.ndarray) -> str:
        """One line: what left the envelope, by how much, and when (``x`` the offending state,
        ``ref`` the reference row it was checked against)."""
        if code == REASON_NON_FINITE:
            bad = [i for i in range(X_SIZE) if not math.isfinite(x[i])]
            from ..layout import STATE_COLUMNS
            return f"non-finite state ({', '.join(STATE_COLUMNS[i] for i in bad[:4])}) at t = {t_s:.3f} s"
        if code == REASON_SPEED:
            return (f"speed {np.linalg.norm(x[X_V_W:X_V_W + 3]):.3g} m/s above envelope.max_speed_mps = "
                    f"{self.max_speed_mps:g} at t = {t_s:.3f} s")
        if code == REASON_BODY_RATE:
            return (f"body rate {np.linalg.norm(x[X_OMEGA_B:X_OMEGA_B + 3]):.3g} rad/s above "
                    f"envelope.max_body_rate_radps = {self.max_body_rate_radps:g} at t = {t_s:.3f} s")
        if code == REASON_HEIGHT_LOW:
            return (f"height {-x[X_P_W + 2]:.3g} m below envelope.min_height_m = {self.min_height_m:g} "
                    f"at t = {t_s:.3f} s")
        if code == REASON_HEIGHT_HIGH:
            return (f"height {-x[X_P_W + 2]:.3g} m above envelope.max_height_m = {self.max_height_m:g} "
                    f"at t = {t_s:.3f} s")
        if code == REASON_POSITION_ERROR:
            err = np.linalg.norm(x[X_P_W:X_P_W + 3] - ref[REF_P_W:REF_P_W + 3])
            return (f"position {err:.3g} m from the reference, above envelope.max_position_error_m = "
                    f"{self.max_position_error_m:g}, at t = {t_s:.3f} s")
        return ""


class DivergenceError(RunFailed):
    """A run left its envelope; ``result`` is the truncated :class:`SimulationResult`.

    A :class:`vtoladapt.errors.RunFailed`: the CLI exits with status 1 and ``str(error)`` as the
    one-line reason (``where`` says which run and where its outputs were kept).
    """

    def __init__(self, result, where: str = ""):
        self.result = result
        super().__init__(f"{where}run diverged: {result.divergence_reason}")


@njit(cache=True, nogil=True, _nrt=False)
def check_envelope(x, env, ref) -> int:
    """Reason code (:data:`DIVERGENCE_REASONS`) of the first envelope limit ``x`` violates, else 0.

    A non-finite state is refused whether the envelope is on or not (``ON`` switches the limits only).

    ``ref`` is the reference row (``REF_*``) of the same tick. A handful of multiplications per
    tick: the speed, rate and position error are compared squared.
    """
    # a non-finite state stops the run with the envelope off too: nothing after it means anything,
    # and a log of NaN with exit 0 would pass for a run
    for i in range(X_SIZE):
        if not np.isfinite(x[i]):
            return REASON_NON_FINITE
    if env[_E_ON] == 0.0:
        return REASON_OK
    v2 = x[X_V_W] ** 2 + x[X_V_W + 1] ** 2 + x[X_V_W + 2] ** 2
    if v2 > env[_E_MAX_SPEED] ** 2:
        return REASON_SPEED
    w2 = x[X_OMEGA_B] ** 2 + x[X_OMEGA_B + 1] ** 2 + x[X_OMEGA_B + 2] ** 2
    if w2 > env[_E_MAX_RATE] ** 2:
        return REASON_BODY_RATE
    h = -x[X_P_W + 2]
    if h < env[_E_MIN_H]:
        return REASON_HEIGHT_LOW
    if h > env[_E_MAX_H]:
        return REASON_HEIGHT_HIGH
    e2 = ((x[X_P_W] - ref[REF_P_W]) ** 2 + (x[X_P_W + 1] - ref[REF_P_W + 1]) ** 2
          + (x[X_P_W + 2] - ref[REF_P_W + 2]) ** 2)
    if e2 > env[_E_MAX_POS_ERR] ** 2:
        return REASON_POSITION_ERROR
    return REASON_OK
