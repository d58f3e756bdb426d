"""The JSBSim engine against the native plant: the written aircraft loads, forces and moments agree at
operating points, a 2 s open-loop trajectory agrees, a scenario flies to its end; frames and errors.

The force comparison is the independent check: JSBSim evaluates the aircraft from its XML with its own
atmosphere, its own flow angles, its own thrusters (location x force for the lift rotors' moments) and its
own actuator components; the native plant evaluates :func:`vtoladapt.sim.plant.true_forces_moments`.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

jsbsim = pytest.importorskip("jsbsim", reason="the optional dependency jsbsim is not installed "
                                              "(pip install 'vtoladapt[jsbsim]')")

from vtoladapt import layout  # noqa: E402
from vtoladapt.config import ConfigError  # noqa: E402
from vtoladapt.frames import GRAVITY_MPS2, quat_from_euler, quat_to_rotmat  # noqa: E402
from vtoladapt.sim import plant as P  # noqa: E402
from vtoladapt.sim.jsbsim_aircraft import (ACTUATOR_PROPERTIES, EARTH_RADIUS_M, SLUG_KG,  # noqa: E402
                                           read_actuator_map, write_aircraft)
from vtoladapt.sim.jsbsim_engine import (JSBSimPlant, euler_from_q, geodetic_from_ned,  # noqa: E402
                                         incident_velocity, ned_from_geodetic)
from vtoladapt.vehicle import load_vehicle  # noqa: E402

VEHICLE = load_vehicle("caltech_vtol")


def _state(p_W=(0.0, 0.0, -1.5), v_W=(0.0, 0.0, 0.0), ypr_deg=(0.0, 0.0, 0.0), omega=(0.0, 0.0, 0.0),
           actuators=(0.6, 0.6, 0.6, 0.6, 0.0)) -> np.ndarray:
    q = quat_from_euler(*np.radians(ypr_deg))
    x = np.zeros(layout.X_SIZE)
    x[layout.X_P_W:layout.X_P_W + 3] = p_W
    x[layout.X_V_W:layout.X_V_W + 3] = v_W
    x[layout.X_Q_WB:layout.X_Q_WB + 4] = q
    x[layout.X_OMEGA_B:layout.X_OMEGA_B + 3] = omega
    x[layout.X_MOTOR:layout.X_MOTOR + len(actuators)] = actuators
    return x


def _native_force_moment(x, v_wind_W, params):
    """The native plant's total non-gravitational force (N) and moment (N m), body FRD."""
    v_i = incident_velocity(x, np.asarray(v_wind_W, dtype=float))
    rotors = P.rotor_terms(x, layout.X_MOTOR, params, np.zeros(layout.PLANT_INPUT_SIZE), layout.IN_SURFACE_LOSS)
    w = x[layout.X_OMEGA_B:layout.X_OMEGA_B + 3]
    fx, fy, fz, mx, my, mz = P.true_forces_moments(v_i[0], v_i[1], v_i[2], w[0], w[1], w[2], rotors, params)
    return np.array([fx, fy, fz]) * params[P.P_MASS], np.array([mx, my, mz])


# (name, state, wind NED m/s): hover and cruise, still air and steady wind, attached flow and past stall
S = np.radians
OPERATING_POINTS = [
    ("hover, still air", _state(), (0.0, 0.0, 0.0)),
    ("hover, 8 m/s headwind", _state(actuators=(0.62, 0.58, 0.61, 0.59, 0.1)), (-8.0, 0.0, 0.0)),
    ("hover in a gusty quartering wind, rotating", _state(omega=(0.3, -0.2, 0.1), ypr_deg=(20.0, 4.0, -3.0)),
     (-6.0, 3.0, 0.5)),
    ("cruise, still air", _state(v_W=(16.0, 0.0, 0.0), ypr_deg=(0.0, 3.0, 0.0),
                                 actuators=(0.1, 0.12, 0.1, 0.08, 0.7, S(5.0), S(-4.0), S(3.0))), (0.0, 0.0, 0.0)),
    ("cruise, sideslip and rates in a steady wind", _state(v_W=(14.0, 2.0, -1.0), ypr_deg=(10.0, 6.0, 8.0),
                                                           omega=(0.4, 0.2, -0.3),
                                                           actuators=(0.3, 0.2, 0.25, 0.3, 0.8, S(-10.0), S(8.0),
                                                                      S(-6.0))), (-3.0, -2.0, 0.0)),
    ("post-stall descent, 60 deg alpha", _state(v_W=(5.0, 0.0, 8.0), actuators=(0.5, 0.5, 0.5, 0.5, 0.3)),
     (0.0, 0.0, 0.0)),
    ("flying backwards, alpha -150 deg", _state(v_W=(-9.0, 1.0, 4.0), ypr_deg=(0.0, 0.0, 0.0)), (0.0, 0.0, 0.0)),
]
#: agreement of force (N) and moment (N m) at an operating point: relative to the largest component, plus an
#: absolute floor. Both engines evaluate the same formulas; what differs is JSBSim's unit conversions (feet,
#: slugs, pounds), its density (the standard atmosphere matched to the plant's by a temperature offset), its
#: flow angles from its own velocity transform and the lift rotors' moments from its thruster locations:
#: measured at 1e-10 N and N m (8 operating points), asserted at 1e-8.
FORCE_RTOL = 1e-8
FORCE_ATOL = 1e-8


@pytest.fixture(scope="module")
def aircraft_dir(tmp_path_factory):
    return write_aircraft(VEHICLE, tmp_path_factory.mktemp("jsbsim_aircraft"))


def test_written_aircraft_loads_in_jsbsim(aircraft_dir):
    fdm = jsbsim.FGFDMExec(str(aircraft_dir.root))
    fdm.set_debug_level(0)
    assert fdm.load_model(aircraft_dir.name)
    assert fdm.run_ic()
    assert math.isclose(fdm["inertia/mass-slugs"] * SLUG_KG, VEHICLE.mass.mass_kg, rel_tol=1e-9)
    assert fdm["inertia/iyy-slugs_ft2"] * SLUG_KG * 0.3048**2 == pytest.approx(VEHICLE.mass.inertia_kgm2[1], rel=1e-9)
    amap = read_actuator_map(aircraft_dir.root / "aircraft" / aircraft_dir.name / "actuator_map.toml")
    assert amap == aircraft_dir.actuator_map
    assert len(amap) == layout.N_MOTORS + len(VEHICLE.surfaces)


@pytest.mark.parametrize("name, x, wind", OPERATING_POINTS, ids=[o[0] for o in OPERATING_POINTS])
def test_forces_and_moments_agree_with_the_native_plant(name, x, wind):
    config = P.PlantConfig()
    params = config.to_kernel(VEHICLE)
    plant = JSBSimPlant(VEHICLE, config, x, 0.001, v_wind_W=wind)
    F_j, M_j = plant.body_force_moment()  # evaluated at the initial state, time not advanced
    F_n, M_n = _native_force_moment(x, wind, params)
    np.testing.assert_allclose(F_j, F_n, rtol=0, atol=FORCE_ATOL + FORCE_RTOL * np.abs(F_n).max(), err_msg=name)
    np.testing.assert_allclose(M_j, M_n, rtol=0, atol=FORCE_ATOL + FORCE_RTOL * np.abs(M_n).max(), err_msg=name)
    # and the aircraft is not trivially zero there
    assert np.abs(F_n).max() > 1.0


def test_density_matches_the_plant():
    cfg = P.PlantConfig(air_density_kgpm3=1.05)
    plant = JSBSimPlant(VEHICLE, cfg, _state(), 0.001)
    assert math.isclose(plant.fdm["atmosphere/rho-slugs_ft3"] * 515.3788184, 1.05, rel_tol=1e-9)


def test_gravity_is_the_native_plants():
    # at the origin exactly; 1.5 m up it is 5e-7 smaller (inverse square over Earth's radius)
    plant = JSBSimPlant(VEHICLE, P.PlantConfig(), _state(p_W=(0.0, 0.0, 0.0)), 0.001)
    assert math.isclose(plant.fdm["accelerations/gravity-ft_sec2"] * 0.3048, GRAVITY_MPS2, rel_tol=1e-8)


def test_frames_round_trip_and_read_back():
    p = np.array([12.0, -7.0, -3.5])
    lat, lon, h = geodetic_from_ned(p, EARTH_RADIUS_M, 10.0)
    np.testing.assert_allclose(ned_from_geodetic(lat, lon, h, EARTH_RADIUS_M, 10.0), p, atol=1e-9)
    q = quat_from_euler(0.7, -0.3, 0.2)
    roll, pitch, yaw = euler_from_q(q)
    np.testing.assert_allclose((roll, pitch, yaw), (0.2, -0.3, 0.7), atol=1e-12)
    # JSBSim reads back the state it was started at (NED position, NED velocity, FRD rates, attitude)
    x = _state(p_W=(3.0, -2.0, -5.0), v_W=(4.0, 1.0, -0.5), ypr_deg=(30.0, 10.0, -5.0), omega=(0.1, -0.2, 0.3))
    plant = JSBSimPlant(VEHICLE, P.PlantConfig(), x, 0.001)
    y = np.zeros(layout.X_SIZE)
    plant.read_state(y)
    np.testing.assert_allclose(y[:13], x[:13], atol=1e-7)
    np.testing.assert_allclose(y[layout.X_MOTOR:layout.X_MOTOR + 5], x[layout.X_MOTOR:layout.X_MOTOR + 5], atol=1e-12)
    # JSBSim's body axes are ours: its body velocity is R_WB^T v_W of our quaternion
    R_WB = quat_to_rotmat(y[layout.X_Q_WB:layout.X_Q_WB + 4])
    uvw = np.array([plant.fdm[f"velocities/{c}-fps"] for c in "uvw"]) * 0.3048
    np.testing.assert_allclose(uvw, R_WB.T @ x[layout.X_V_W:layout.X_V_W + 3], atol=1e-9)


#: 2 s open loop with the same held commands: position (m), velocity (m/s), attitude (rad). The differences
#: are JSBSim's default integrators at 1 kHz (rectangular Euler for body rates and attitude, Adams-Bashforth 2
#: for velocity, 3 for position) against classical RK4 at 1 kHz, and its motor lag (a bilinear-transform
#: discretisation) against the exact solution.
#: Measured: 8 mm, 9 mm/s, 0.0011 rad after 2 s (still air and the steady wind), the aircraft 3.7-4.8 m away.
TRAJECTORY_TOL = {"position_m": 0.02, "velocity_mps": 0.02, "attitude_rad": 0.01}


@pytest.mark.parametrize("wind", [(0.0, 0.0, 0.0), (-6.0, 1.0, 0.0)], ids=["still air", "steady wind"])
def test_open_loop_trajectory_agrees_over_2_s(wind):
    config = P.PlantConfig()
    params = config.to_kernel(VEHICLE)
    trim = P.hover_trim_motor(VEHICLE, config)
    x0 = _state(v_W=(2.0, 0.0, 0.0), actuators=tuple(trim))
    u = P.plant_input([trim[0] * 1.02, trim[1] * 0.99, trim[2] * 1.0, trim[3] * 0.995, 0.3, 0.05, -0.05, 0.02, 0.0])
    v_w = np.array(wind, dtype=float)
    x = x0.copy()
    work = np.zeros(P.RK4_WORK_SIZE)
    for _ in range(500):  # 2 s at 250 Hz, 4 RK4 steps a tick
        P.plant_advance(x, u, v_w, params, 0.001, 4, False, work)
    plant = JSBSimPlant(VEHICLE, config, x0, 0.001, v_wind_W=wind)
    plant.command(u)
    plant.advance(2000)
    y = np.zeros(layout.X_SIZE)
    plant.read_state(y)
    assert np.abs(x[0:3] - x0[0:3]).max() > 0.5, "the trajectory must go somewhere to be compared"
    np.testing.assert_allclose(y[0:3], x[0:3], atol=TRAJECTORY_TOL["position_m"])
    np.testing.assert_allclose(y[3:6], x[3:6], atol=TRAJECTORY_TOL["velocity_mps"])
    angle = 2.0 * math.acos(min(1.0, abs(float(np.dot(y[6:10], x[6:10])))))
    assert angle < TRAJECTORY_TOL["attitude_rad"]


def test_missing_actuator_mapping_is_one_line(tmp_path):
    ac = write_aircraft(VEHICLE, tmp_path)
    bad = dataclasses.replace(ac, actuator_map={k: v for k, v in ac.actuator_map.items() if k != "pusher_cmd_frac"})
    with pytest.raises(ConfigError) as err:
        JSBSimPlant(VEHICLE, P.PlantConfig(), _state(), 0.001, aircraft=bad)
    msg = str(err.value)
    assert "\n" not in msg and "pusher_cmd_frac" in msg and str(ac.xml_path) in msg


def test_unknown_actuator_property_is_one_line(tmp_path):
    ac = write_aircraft(VEHICLE, tmp_path)
    amap = dict(ac.actuator_map, pusher_cmd_frac="fcs/no-such-throttle")
    with pytest.raises(ConfigError) as err:
        JSBSimPlant(VEHICLE, P.PlantConfig(), _state(), 0.001, aircraft=dataclasses.replace(ac, actuator_map=amap))
    msg = str(err.value)
    assert "\n" not in msg and "fcs/no-such-throttle" in msg and str(ac.xml_path) in msg


def test_bad_xml_is_one_line_naming_the_file(tmp_path):
    ac = write_aircraft(VEHICLE, tmp_path)
    text = ac.xml_path.read_text()
    for bad, words in ((text.replace("<metrics>", "<metrics><wingarea>oops</wingarea>", 1), "oops"),
                        (text[:len(text) // 2], "line ")):
        ac.xml_path.write_text(bad)
        with pytest.raises(ConfigError) as err:
            JSBSimPlant(VEHICLE, P.PlantConfig(), _state(), 0.001, aircraft=ac)
        msg = str(err.value)
        assert "\n" not in msg and str(ac.xml_path) in msg and words in msg


def test_actuator_map_file_rejects_unknown_columns(tmp_path):
    path = tmp_path / "actuator_map.toml"
    path.write_text('[actuators]\nmotor9_cmd_frac = "fcs/x"\n')
    with pytest.raises(ConfigError, match="motor9_cmd_frac: not an actuator column"):
        read_actuator_map(path)


def test_actuator_map_covers_every_actuator_column():
    assert set(ACTUATOR_PROPERTIES) == set(layout.ACTUATORS.columns)


def test_a_scenario_flies_to_its_end_on_jsbsim_with_finite_logs():
    """The paper's hold in front of the fan array (its first 6 s: hover, then the fan starts at 5 s), on JSBSim:
    every tick logged in the native log layout, all finite, and the hold kept (an independent bound: the
    native run of the same scenario stays within 5 cm; on JSBSim it must stay within 20 cm)."""
    from vtoladapt.sim.driver import simulate
    from vtoladapt.sim.scenario import load_scenario

    base = load_scenario("paper_comparison").replace(duration_s=6.0)
    jsb = base.replace(plant=dataclasses.replace(base.plant, engine="jsbsim"))
    native = simulate(base)
    result = simulate(jsb)
    assert result.metadata["plant_engine"] == "jsbsim" and result.metadata["diverged_at_s"] is None
    assert result.columns == native.columns and result.data.shape == native.data.shape
    assert np.isfinite(result.data).all()
    err = np.abs(result.columns_like(("p_N_m", "p_E_m", "p_D_m")) - np.array([0.0, 0.0, -1.5])).max()
    assert err < 0.2
    # the fan blew during the run (the wind JSBSim was given each tick)
    assert result.columns_like(("wind_N_mps",)).min() < -1.0
    assert result.metadata["plant_engine"] == "jsbsim" and native.metadata["plant_engine"] == "native"


def test_engine_setting_is_validated():
    from vtoladapt.sim.scenario import scenario_from_mapping

    with pytest.raises(ConfigError) as err:
        scenario_from_mapping({"name": "x", "vehicle": "caltech_vtol", "duration_s": 1.0,
                               "plant": {"engine": "xplane"}}, "s.toml")
    msg = str(err.value)
    assert "\n" not in msg and "engine" in msg and "xplane" in msg and "jsbsim" in msg


def test_vehicle_jsbsim_command_writes_a_folder_jsbsim_opens(tmp_path, capsys):
    from vtoladapt.cli import main

    out = tmp_path / "ac"
    assert main(["vehicle", "jsbsim", "caltech_vtol", "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    fdm = jsbsim.FGFDMExec(str(out))
    fdm.set_debug_level(0)
    assert fdm.load_model("caltech_vtol") and fdm.run_ic()
    assert read_actuator_map(out / "aircraft" / "caltech_vtol" / "actuator_map.toml")["pusher_cmd_frac"] == \
        "fcs/vtol/pusher-cmd-norm"


def test_a_missing_jsbsim_is_one_line_naming_the_scenario(monkeypatch):
    import builtins

    from vtoladapt.sim.driver import prepare
    from vtoladapt.sim.scenario import scenario_from_mapping

    real_import = builtins.__import__

    def no_jsbsim(name, *args, **kwargs):
        if name == "jsbsim":
            raise ImportError("no jsbsim")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_jsbsim)
    sc = scenario_from_mapping({"name": "x", "vehicle": "caltech_vtol", "duration_s": 1.0,
                                "plant": {"engine": "jsbsim"}}, "s.toml", source_path="s.toml")
    with pytest.raises(ConfigError) as err:
        prepare(sc)
    msg = str(err.value)
    assert "\n" not in msg and "s.toml" in msg and "pip install 'vtoladapt[jsbsim]'" in msg
