"""The JSBSim plant engine (``[plant] engine = "jsbsim"``): the same tick as :mod:`vtoladapt.sim.loop`, with
JSBSim integrating the aircraft.

Per controller tick, in the native loop's order:

* steps 0-2, compiled (:func:`sense_wind`): the envelope check on the state read from JSBSim, the tick's
  random draws (wind parts, then sensor channels, as the native tick draws them) and the wind at the
  vehicle; the wind goes to JSBSim's ``atmosphere/wind-{north,east,down}-fps`` properties;
* step 3, the truth the sensors sample: the incident velocity ``v_i_B = R_WB^T (v_W - v_wind_W)`` from
  JSBSim's state and this tick's wind (what JSBSim's own flow will be in its next step), and the specific
  force from JSBSim's total non-gravitational force over the true mass. JSBSim integrates first and then
  evaluates the forces at the new state, so that force is the one at the tick's state and actuator
  outputs, but under the previous tick's wind (the native plant's uses this tick's: the two differ only
  while the wind changes);
* steps 3-4, compiled (:func:`measure_and_control`): sensors, sensor faults, and the compiled controller
  step (:func:`vtoladapt.control.step.controller_step`, the one the native loop runs);
* steps 5-6, compiled (:func:`allocate_and_log`): the allocator, the actuator faults, the log row (the
  native layout);
* step 7: the actuator commands go to the fcs/ properties of the actuator map (a lost surface's share and
  a slow servo's lag and rate limit to their properties) and JSBSim runs ``plant_substeps`` steps of
  ``dt / plant_substeps``.

Frames: JSBSim's local frame is NED, as ours; its body frame is FRD, as ours. Position is JSBSim's
latitude, longitude and altitude on the aircraft's planet (a sphere, :mod:`vtoladapt.sim.jsbsim_aircraft`)
turned into north and east arc lengths and down from the run's origin (:func:`ned_from_geodetic`); the
attitude is JSBSim's Euler angles (yaw, pitch, roll about its local NED) as ``q_WB``. The origin sits
:data:`vtoladapt.sim.jsbsim_aircraft.ORIGIN_ALTITUDE_M` above the planet's surface, with the terrain
:data:`TERRAIN_BELOW_ORIGIN_M` below the origin, and JSBSim's standard atmosphere is warmed or cooled
(``atmosphere/delta-T``) until its density at the start is the plant's.

This loop is Python around compiled kernels and JSBSim: the native plant stays the default and the fast path.
"""
from __future__ import annotations

import math
import tempfile
import numpy as np
from numba import njit

from .. import layout
from ..config import ConfigError
from ..control.step import controller_step, functions_at
from ..frames import quat_from_euler, quat_to_rotmat
from ..layout import (IN_SERVO_SLOWDOWN, IN_SURFACE_LOSS, N_MOTORS, TRUTH_F_B, TRUTH_V_I_B,
                      TRUTH_V_WIND_W, TRUTH_WIND, WIND_SIZE, X_MOTOR, X_OMEGA_B, X_P_W, X_Q_WB, X_V_W)
from ..parts import draw
from ..sensors.suite import sensors_at
from ..wind.composer import wind_at
from . import plant as P
from .allocation import allocate
from .faults import active_mask, apply_actuator_faults, apply_measurement_faults
from .jsbsim_aircraft import (EARTH_RADIUS_M, FT_M, N_PER_LBF, ORIGIN_ALTITUDE_M, OUTPUT_PROPERTIES, SLUG_KG,
                              SURFACE_LOSS_PROPERTY, check_actuator_map, write_aircraft)
from .loop import _TW_ALLOC, report_mixed, write_log_row
from .mixer import MX_U_MAX
from .monitor import REASON_OK, check_envelope

TERRAIN_BELOW_ORIGIN_M = 100.0
"""The terrain's depth below the origin (m): the native plant has no ground, so neither has a JSBSim run in
practice (the skids of the written aircraft touch it only after a 100 m fall)."""
RANKINE_PER_KELVIN = 1.8


def jsbsim_available() -> bool:
    """Whether the optional ``jsbsim`` package (the ``jsbsim`` extra) can be imported."""
    try:
        import jsbsim  # noqa: F401
    except ImportError:
        return False
    return True


def require_jsbsim(where: str) -> None:
    """One line naming ``where`` if the optional dependency is missing."""
    if not jsbsim_available():
        raise ConfigError(f"{where}: [plant] engine = 'jsbsim': the Python package jsbsim is not installed; "
                          "allowed: 'native', or 'jsbsim' after pip install 'vtoladapt[jsbsim]'")


# --- frames -------------------------------------------------------------------------------------------------
def ned_from_geodetic(lat_rad: float, lon_rad: float, h_m: float, radius_m: float, h0_m: float) -> np.ndarray:
    """Position (m, NED) of a point on a spherical planet of ``radius_m``, relative to the origin at latitude
    and longitude 0 and altitude ``h0_m``: north and east as arc lengths at the origin's radius, down as the
    altitude below the origin's."""
    r = radius_m + h0_m
    return np.array([lat_rad * r, lon_rad * r * math.cos(lat_rad), h0_m - h_m])


def geodetic_from_ned(p_W: np.ndarray, radius_m: float, h0_m: float) -> tuple:
    """The inverse of :func:`ned_from_geodetic`: ``(lat_rad, lon_rad, h_m)``."""
    r = radius_m + h0_m
    lat = p_W[0] / r
    return lat, p_W[1] / (r * math.cos(lat)), h0_m - p_W[2]


def euler_from_q(q_WB: np.ndarray) -> tuple:
    """``(roll, pitch, yaw)`` (rad) of ``q_WB``: the ZYX Euler angles JSBSim's ``ic/`` and ``attitude/`` use."""
    w, x, y, z = q_WB
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def incident_velocity(x: np.ndarray, v_wind_W: np.ndarray) -> np.ndarray:
    """eq:vi, ``v_i_B = R_WB^T (v_W - v_wind_W)``."""
    return quat_to_rotmat(x[X_Q_WB:X_Q_WB + 4]).T @ (x[X_V_W:X_V_W + 3] - v_wind_W)


def _one_line(exc: BaseException) -> str:
    """JSBSim's message in one line: its ``line N`` and its last sentence (its messages repeat the file)."""
    import re

    text = str(exc).strip()
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    where = next((m.group(0) for ln in lines for m in [re.search(r"line \d+", ln)] if m), "")
    what = next((ln for ln in reversed(lines) if not ln.startswith("In file")), type(exc).__name__)
    return f"{where}: {what}" if where else what


class JSBSimPlant:
    """One run's aircraft in JSBSim: written from the vehicle and the run's resolved plant config into a
    temporary folder (kept while this object lives), loaded, and started at ``x0``."""

    def __init__(self, vehicle, plant_config: P.PlantConfig, x0: np.ndarray, dt_s: float,
                 aircraft=None, v_wind_W=(0.0, 0.0, 0.0)) -> None:
        import jsbsim

        self._tmp = None
        if aircraft is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="vtoladapt-jsbsim-")
            aircraft = write_aircraft(vehicle, self._tmp.name, plant_config)
        self.aircraft = aircraft
        check_actuator_map(aircraft.actuator_map, aircraft.n_surfaces, str(aircraft.xml_path))
        self.n_surfaces = aircraft.n_surfaces
        self.rho_kgpm3 = plant_config.air_density_kgpm3 or vehicle.envelope.air_density_kgpm3
        self.mass_kg = plant_config.mass_kg if plant_config.mass_kg is not None else vehicle.mass.mass_kg
        p = plant_config.to_kernel(vehicle)
        self.servo_tau_s = p[P.P_SURF_TAU:P.P_SURF_TAU + layout.N_SURFACES].copy()
        self.servo_rate_radps = p[P.P_SURF_RATE:P.P_SURF_RATE + layout.N_SURFACES].copy()
        fdm = jsbsim.FGFDMExec(str(aircraft.root))
        fdm.set_debug_level(0)
        # before loading: the flight control's filters take their coefficients from the step at load time
        fdm.set_dt(dt_s)
        try:
            loaded = fdm.load_model(aircraft.name)
        except Exception as exc:  # JSBSim's own parse errors: the file, the line and JSBSim's words, one line
            raise ConfigError(f"{aircraft.xml_path}: JSBSim cannot load the aircraft: {_one_line(exc)}") from None
        if not loaded:
            raise ConfigError(f"{aircraft.xml_path}: JSBSim cannot load the aircraft (load_model returned false)")
        self._props = [aircraft.actuator_map.get(c) for c in layout.ACTUATORS.columns]
        for prop in (q for q in self._props if q is not None):
            if not fdm.get_property_manager().hasNode(prop):
                raise ConfigError(f"{aircraft.xml_path}: actuator map property {prop}: not defined by the aircraft")
        self.fdm = fdm
        self.start(x0, v_wind_W)

    def start(self, x0: np.ndarray, v_wind_W=(0.0, 0.0, 0.0)) -> None:
        """Initial conditions from the plant state ``x0`` (motors and servos included), the wind ``v_wind_W``
        (m/s, NED), and ``run_ic``."""
        fdm = self.fdm
        v_wind_W = np.asarray(v_wind_W, dtype=float)
        lat, lon, h = geodetic_from_ned(x0[X_P_W:X_P_W + 3], EARTH_RADIUS_M, ORIGIN_ALTITUDE_M)
        fdm["ic/terrain-elevation-ft"] = (ORIGIN_ALTITUDE_M - TERRAIN_BELOW_ORIGIN_M) / FT_M
        fdm["ic/lat-geod-rad"] = lat
        fdm["ic/long-gc-rad"] = lon
        fdm["ic/h-sl-ft"] = h / FT_M
        roll, pitch, yaw = euler_from_q(x0[X_Q_WB:X_Q_WB + 4])
        fdm["ic/phi-rad"], fdm["ic/theta-rad"], fdm["ic/psi-true-rad"] = roll, pitch, yaw
        for name, i in (("vn", 0), ("ve", 1), ("vd", 2)):
            fdm[f"ic/{name}-fps"] = x0[X_V_W + i] / FT_M
        for name, i in (("p", 0), ("q", 1), ("r", 2)):
            fdm[f"ic/{name}-rad_sec"] = x0[X_OMEGA_B + i]
        # actuators start at the state's outputs: a JSBSim actuator's first run (in run_ic) takes its input
        outputs = x0[X_MOTOR:X_MOTOR + layout.N_ACTUATORS]
        for prop, value in zip(self._props, outputs):
            if prop is not None:
                self.fdm[prop] = float(value)
        for j in range(self.n_surfaces):
            self.fdm[SURFACE_LOSS_PROPERTY.format(j + 1)] = 0.0
        fdm["atmosphere/delta-T"] = 0.0
        try:
            ok = fdm.run_ic()
        except Exception as exc:  # a function reading a property nobody defines fails here, not at load
            raise ConfigError(f"{self.aircraft.xml_path}: JSBSim cannot start the aircraft: {_one_line(exc)}") from None
        if not ok:
            raise ConfigError(f"{self.aircraft.xml_path}: JSBSim cannot start the aircraft (run_ic returned false)")
        # warm or cool the standard atmosphere until its density at the start is the plant's (ideal gas at
        # the same pressure: rho ~ 1/T)
        for _ in range(3):
            rho = fdm["atmosphere/rho-slugs_ft3"] * 515.3788184
            T_R = fdm["atmosphere/T-R"]
            fdm["atmosphere/delta-T"] = fdm["atmosphere/delta-T"] + T_R * (rho / self.rho_kgpm3 - 1.0)
            fdm.run_ic()
        # run_ic takes the wind from JSBSim's initial conditions (which hold a horizontal wind only) and
        # evaluates the forces without ours: set the wind and evaluate them again without advancing time
        # (the actuators already sit at their inputs, so their extra filter steps leave them there); twice,
        # because the flight control (the pusher's advance ratio) runs before JSBSim's auxiliary model and so
        # sees the flow of the previous evaluation
        self.set_wind(v_wind_W)
        fdm.suspend_integration()
        fdm.run()
        fdm.run()
        fdm.resume_integration()

    # --- reading JSBSim's state ---------------------------------------------------------------------------
    def read_state(self, x: np.ndarray) -> None:
        """Our plant state (:data:`vtoladapt.layout.STATE`) from JSBSim's."""
        f = self.fdm
        x[X_P_W:X_P_W + 3] = ned_from_geodetic(f["position/lat-geod-rad"], f["position/long-gc-rad"],
                                               f["position/h-sl-meters"], EARTH_RADIUS_M, ORIGIN_ALTITUDE_M)
        x[X_V_W] = f["velocities/v-north-fps"] * FT_M
        x[X_V_W + 1] = f["velocities/v-east-fps"] * FT_M
        x[X_V_W + 2] = f["velocities/v-down-fps"] * FT_M
        q = quat_from_euler(f["attitude/psi-rad"], f["attitude/theta-rad"], f["attitude/phi-rad"])
        x[X_Q_WB:X_Q_WB + 4] = q if q[0] >= 0.0 else -q  # one of the two quaternions of a rotation
        x[X_OMEGA_B] = f["velocities/p-rad_sec"]
        x[X_OMEGA_B + 1] = f["velocities/q-rad_sec"]
        x[X_OMEGA_B + 2] = f["velocities/r-rad_sec"]
        for i, prop in enumerate(OUTPUT_PROPERTIES[:N_MOTORS + self.n_surfaces]):
            x[X_MOTOR + i] = f[prop]

    def specific_force(self, f_B: np.ndarray) -> None:
        """The total non-gravitational force of JSBSim's last step over the true mass (m/s^2, body FRD)."""
        f = self.fdm
        k = N_PER_LBF / (f["inertia/mass-slugs"] * SLUG_KG)
        f_B[0] = f["forces/fbx-total-lbs"] * k
        f_B[1] = f["forces/fby-total-lbs"] * k
        f_B[2] = f["forces/fbz-total-lbs"] * k

    def body_force_moment(self) -> tuple:
        """JSBSim's total non-gravitational force (N) and moment about the centre of gravity (N m), body FRD,
        of its last step."""
        f = self.fdm
        F = np.array([f[f"forces/fb{a}-total-lbs"] for a in "xyz"]) * N_PER_LBF
        M = np.array([f[f"moments/{a}-total-lbsft"] for a in "lmn"]) * N_PER_LBF * FT_M
        return F, M

    # --- writing to JSBSim --------------------------------------------------------------------------------
    def set_wind(self, v_wind_W: np.ndarray) -> None:
        """Give JSBSim the wind at the aircraft, ``v_wind_W`` in m/s NED (its wind properties are in ft/s)."""
        f = self.fdm
        f["atmosphere/wind-north-fps"] = v_wind_W[0] / FT_M
        f["atmosphere/wind-east-fps"] = v_wind_W[1] / FT_M
        f["atmosphere/wind-down-fps"] = v_wind_W[2] / FT_M

    def command(self, u_in: np.ndarray) -> None:
        """The plant input (:data:`vtoladapt.layout.PLANT_INPUT`) onto the fcs/ properties."""
        f = self.fdm
        for prop, value in zip(self._props, u_in[:layout.N_ACTUATORS]):
            if prop is not None:
                f[prop] = float(value)
        for j in range(self.n_surfaces):
            f[SURFACE_LOSS_PROPERTY.format(j + 1)] = float(u_in[IN_SURFACE_LOSS + j])
            slow = 1.0 + float(u_in[IN_SERVO_SLOWDOWN + j])
            f[f"fcs/vtol/surface-{j + 1}-lag-per-s"] = 1.0 / (self.servo_tau_s[j] * slow)
            f[f"fcs/vtol/surface-{j + 1}-rate-limit-radps"] = self.servo_rate_radps[j] / slow

    def advance(self, n_steps: int) -> None:
        """Integrate ``n_steps`` of JSBSim's time step; a run JSBSim stops is a RuntimeError naming the XML."""
        for _ in range(n_steps):
            if not self.fdm.run():
                raise RuntimeError(f"{self.aircraft.xml_path}: JSBSim stopped the run")


# --- the compiled parts of the tick ----------------------------------------------------------------------------
@njit(cache=True, nogil=True)
def sense_wind(x, truth, envelope, wind, sensors, ref, t, dt, rng) -> int:
    """Steps 0-2 of the native tick (:func:`vtoladapt.sim.loop.tick_sense`): envelope, draws, wind."""
    reason = check_envelope(x, envelope, ref)
    if reason != REASON_OK:
        return reason
    wind_table, wind_p, wind_s, wind_draws = wind
    sensor_table, sensor_p, sensor_s, sensor_draws = sensors
    draw(rng, wind_table, wind_draws)
    draw(rng, sensor_table, sensor_draws)
    wind_at(wind_table, wind_p, wind_s, t, dt, x[X_P_W:X_P_W + 3], wind_draws,
            truth[TRUTH_WIND:TRUTH_WIND + WIND_SIZE])
    return REASON_OK


@njit(cache=True, nogil=True)
def measure_and_control(x, truth, meas, sensors, faults, controller, ref, t, dt, cmd, diag) -> None:
    """Steps 3-4 after the truth is in ``truth``: sensors, sensor faults, the controller step."""
    sensor_table, sensor_p, sensor_s, sensor_draws = sensors
    sensors_at(sensor_table, sensor_p, sensor_s, t, dt, x, truth, sensor_draws, meas)
    apply_measurement_faults(faults[0], faults[1], t, dt, meas)
    controller_step(functions_at(controller[0]), controller[1], controller[2], meas, ref, dt, cmd, diag)


@njit(cache=True, nogil=True)
def allocate_and_log(x, truth, meas, work, mixer_p, faults, controller, ref, cmd, diag, motor_cmd, t, log) -> None:
    """Steps 5-6 (:func:`vtoladapt.sim.loop.tick_actuate` without the plant's advance)."""
    saturated = allocate(cmd, meas, mixer_p, motor_cmd, work, _TW_ALLOC)
    report_mixed(controller[2], motor_cmd, saturated)
    apply_actuator_faults(faults[0], faults[1], t, mixer_p[MX_U_MAX], motor_cmd)
    row = log[0]
    if row.shape[0] > 0:
        write_log_row(row, x, truth, meas, ref, cmd, diag, motor_cmd, saturated, active_mask(faults[0], t),
                      controller, log[1], log[2], t, work)


def run_chunk_jsbsim(run, plant: JSBSimPlant, x: np.ndarray, k0: int, k1: int, log: np.ndarray) -> tuple[int, int]:
    """:func:`vtoladapt.sim.driver.run_chunk` on JSBSim: ticks ``k0 .. k1-1`` into ``log``, ``x`` kept equal to
    JSBSim's state. Returns ``(ticks_done, reason)`` as the native loop does."""
    sc = run.scenario
    dt = sc.dt_control_s
    truth, meas, cmd, diag, motor_cmd, work = run.scratch()
    wind, sensors = run.wind(), run.sensors()
    faults = (run.fault_schedule, run.fault_state)
    controller = (run.controller_fns, run.controller_params, run.controller_state)
    refs = run.reference_table[k0:k1]
    t0 = k0 * dt
    plant.read_state(x)
    for k in range(k1 - k0):
        t = t0 + k * dt
        ref = refs[k]
        reason = sense_wind(x, truth, run.envelope, wind, sensors, ref, t, dt, run.rng)
        if reason != REASON_OK:
            return k, int(reason)
        v_wind = truth[TRUTH_V_WIND_W:TRUTH_V_WIND_W + 3]
        plant.set_wind(v_wind)
        truth[TRUTH_V_I_B:TRUTH_V_I_B + 3] = incident_velocity(x, v_wind)
        plant.specific_force(truth[TRUTH_F_B:TRUTH_F_B + 3])
        measure_and_control(x, truth, meas, sensors, faults, controller, ref, t, dt, cmd, diag)
        allocate_and_log(x, truth, meas, work, run.mixer_params, faults, controller, ref, cmd, diag, motor_cmd, t,
                         (log[k], run.theta_true, run.gamma))
        plant.command(motor_cmd)
        plant.advance(sc.plant_substeps)
        plant.read_state(x)
        if not np.all(np.isfinite(x)):
            return k + 1, int(check_envelope(x, run.envelope, ref)) or 1
    return k1 - k0, int(check_envelope(x, run.envelope, refs[-1]))
