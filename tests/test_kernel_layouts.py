"""The kernels' flat arrays follow their BlockLayout declarations.

Each component's ``to_kernel()`` is checked against its declaration field by field, with the
values computed here from the settings, so a field put in the wrong place, or a declaration that
no longer matches what is packed, fails.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from vtoladapt import layout, sensors
from vtoladapt.sim import allocation, mixer, plant
from vtoladapt.layout import BlockLayout
from vtoladapt.probe import ProbeTip, SDP33Sensor, estimation, sensor, tip
from vtoladapt.wind import WindConfig, dryden, fan_array, gusts


def _all_layouts():
    from vtoladapt import parts
    from vtoladapt.gym import batch_kernel, spaces
    from vtoladapt.sensors import airflow_probe, attitude, imu, mocap
    from vtoladapt.sim import faults, loop, monitor
    from vtoladapt.wind import composer, constant

    found = []
    for module in (layout, plant, mixer, fan_array, gusts, dryden, constant, composer, tip, sensor, estimation, imu,
                   mocap, attitude, airflow_probe, parts, faults, loop, monitor, batch_kernel, spaces):
        found += [(f"{module.__name__}.{n}", v) for n, v in vars(module).items() if isinstance(v, BlockLayout)]
    return found


@pytest.mark.parametrize("name, lay", _all_layouts(), ids=lambda x: x if isinstance(x, str) else "")
def test_every_field_has_a_unit_and_a_meaning(name, lay):
    for field_name, _offset, _size, unit, doc in lay.describe():
        assert unit.strip() and doc.strip(), f"{name}.{field_name}"


def test_shared_arrays_keep_their_log_columns():
    # the log columns are part of the Parquet format: these names are what readers use
    assert layout.STATE_COLUMNS[:3] == ("p_N_m", "p_E_m", "p_D_m")
    assert layout.STATE_COLUMNS[layout.X_MOTOR + layout.N_MOTORS - 1] == "pusher_frac"
    assert layout.STATE_COLUMNS[-1] == "surface4_rad" and len(layout.STATE_COLUMNS) == layout.X_SIZE == 22
    assert layout.MEASUREMENT_COLUMNS[layout.MEAS_V_I_VALID] == "meas_v_i_valid"
    assert layout.MEAS_SIZE == 20 and layout.REF_SIZE == 11 and layout.CMD_SIZE == 5
    assert layout.COMMAND_COLUMNS[layout.CMD_TAU_B] == "cmd_tau_x_Nm"
    assert layout.REFERENCE_COLUMNS[layout.REF_YAW_RATE] == "ref_yaw_rate_radps"


def test_plant_parameters_land_in_their_fields(caltech):
    cfg = plant.PlantConfig(mass_kg=2.0, stall_angle_deg=14.0, Cnr=-0.2, rotor_reaction_torque=False)
    p = cfg.to_kernel(caltech)
    L = plant.PLANT_PARAMS
    assert p.size == L.size == plant.P_SIZE
    assert L.view(p, "MASS")[0] == 2.0
    assert L.view(p, "FORCE_MASS")[0] == caltech.mass.mass_kg
    J = L.view(p, "J").reshape(3, 3)
    np.testing.assert_allclose(J @ L.view(p, "JINV").reshape(3, 3), np.eye(3), atol=1e-12)
    assert L.view(p, "ALPHA_STALL")[0] == pytest.approx(math.radians(14.0))
    assert L.view(p, "STALL_EXP")[0] == pytest.approx(math.exp(cfg.stall_blend_rate_per_rad * math.radians(14.0)))
    assert L.view(p, "CNR")[0] == -0.2 and L.view(p, "KM_PUSHER")[0] == 0.0
    xy = np.array(caltech.geometry.lift_rotor_positions_m)
    np.testing.assert_array_equal(L.view(p, "ROTOR_X"), xy[:, 0])
    np.testing.assert_array_equal(L.view(p, "ROTOR_Y"), xy[:, 1])
    np.testing.assert_array_equal(L.view(p, "THETA"), cfg.theta_true_scaled(caltech))
    assert plant.RK4_WORK_SIZE == (5 * plant.N_BODY + 2 * layout.N_ACTUATORS + plant.ROTOR_TERMS_SIZE
                                   + 2 * layout.N_SURFACES)
    # the surfaces: derivatives times S (and b, c), their limits and servos
    S, b = caltech.geometry.wing_area_m2, caltech.geometry.wingspan_m
    for j, sf in enumerate(caltech.surfaces):
        np.testing.assert_allclose(L.view(p, "SURF_M")[3 * j:3 * j + 3],
                                   S * np.array(sf.derivatives_per_rad[3:]) * [b, S / b, b], rtol=1e-12)
        assert L.view(p, "SURF_LIMIT")[j] == pytest.approx(math.radians(sf.limit_deg))
        assert L.view(p, "SURF_TAU")[j] == sf.time_constant_s
    assert L.view(p, "N_SURF")[0] == len(caltech.surfaces) and L.view(p, "SURF_LIMIT")[-1] == 0.0


def test_wind_parameters_land_in_the_parts_blocks():
    cfg = WindConfig.from_mapping({
        "constant_mps": [1.0, 2.0, 3.0],
        "fan_array": {"schedule": [[0, 10], [2, 40]], "array_bearing_deg": 90.0, "max_speed_mps": 10.0},
        "turbulence": {"enabled": True, "sigma_mps": [1.0, 2.0, 3.0], "length_scale_m": [4.0, 5.0, 6.0]},
        "gusts": [{"shape": "step", "start_s": 1.0, "duration_s": 2.0, "amplitude_mps": [7.0, 8.0, 9.0]}]})
    from vtoladapt.wind import composer

    p = cfg.to_kernel()
    assert cfg.assemble().ids == ("fan_array", "constant", "gusts", "turbulence")
    np.testing.assert_array_equal(composer.WIND_PARAMS.view(p, "CONSTANT"), [1.0, 2.0, 3.0])
    fan = composer.WIND_PARAMS.view(p, "FAN_ARRAY")
    np.testing.assert_array_equal(fan_array.FAN_PARAMS.view(fan, "T")[:2], [0.0, 2.0])
    np.testing.assert_array_equal(fan_array.FAN_PARAMS.view(fan, "U")[:2], [10.0, 40.0])
    np.testing.assert_allclose(fan_array.FAN_PARAMS.view(fan, "DIR"), [0.0, -1.0], atol=1e-15)
    turb = composer.WIND_PARAMS.view(p, "TURBULENCE")
    np.testing.assert_array_equal(dryden.TURBULENCE_PARAMS.view(turb, "SIGMA"), [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(dryden.TURBULENCE_PARAMS.view(turb, "L"), [4.0, 5.0, 6.0])
    g = composer.WIND_PARAMS.view(p, "GUSTS")
    assert gusts.GUSTS_PARAMS.view(g, "N")[0] == 1
    entry = gusts.GUSTS_PARAMS.view(g, "TABLE")[:gusts.GUST_PARAMS.size]
    np.testing.assert_array_equal(gusts.GUST_PARAMS.view(entry, "AMPLITUDE"), [7.0, 8.0, 9.0])
    assert gusts.GUST_PARAMS.view(entry, "SHAPE")[0] == gusts.GUST_SHAPES.index("step")


def test_sensor_parameters_land_in_their_blocks():
    cfg = sensors.SensorsConfig.from_mapping({"imu": {"gyro_range_dps": 1000.0}, "mocap": {"latency_s": 0.02},
                                              "attitude": {"noise_std_deg": 0.5},
                                              "probe": {"model": "pressure", "calibration": "single_k"}})
    suite = cfg.assemble(sensors.SensorContext(1.1, 1.2))
    p = suite.params
    imu = suite.block(p, "imu")
    assert sensors.imu.PARAMS.view(imu, "GYRO_RANGE")[0] == pytest.approx(math.radians(1000.0))
    mocap = suite.block(p, "mocap")
    assert sensors.mocap.PARAMS.view(mocap, "LATENCY")[0] == 0.02
    att = suite.block(p, "attitude")
    assert sensors.attitude.PARAMS.view(att, "STD")[0] == pytest.approx(math.radians(0.5))
    probe = suite.block(p, "probe")
    pp = sensors.airflow_probe.PARAMS
    assert pp.view(probe, "RHO_TRUE")[0] == 1.1 and pp.view(probe, "RHO_ASSUMED")[0] == 1.2
    np.testing.assert_array_equal(pp.view(probe, "TIP"), ProbeTip().to_kernel())
    np.testing.assert_array_equal(pp.view(probe, "SDP"), SDP33Sensor().to_kernel())
    cal = probe[pp.offset("CAL"):]
    assert cal[estimation.CAL_KIND] == estimation.KIND_SINGLE_K and cal.size == estimation.SK_SIZE
    assert suite.params_layout.fields[-1].size == pp.size + estimation.SK_SIZE  # the calibration ends the block


def test_probe_and_mixer_arrays_follow_their_declarations(caltech):
    t = ProbeTip(port_angle_deg=30.0, pressure_factor=2.0, static_port_coefficient=0.1).to_kernel()
    np.testing.assert_allclose(t, [math.radians(30.0), 2.0, 0.1])
    assert t[tip.TIP_PRESSURE_FACTOR] == 2.0
    s = SDP33Sensor(offset_Pa=(0.1, 0.2, 0.3)).to_kernel()
    np.testing.assert_array_equal(sensor.SENSOR_PARAMS.view(s, "OFFSET"), [0.1, 0.2, 0.3])
    assert estimation.TB_KIND == estimation.SK_KIND == estimation.CAL_KIND
    m = mixer.mixer_params(caltech)
    assert m.size == mixer.MX_SIZE
    assert m[allocation.AL_TOTAL_UNIT] == pytest.approx(4.0 * m[allocation.AL_T_UNIT])


def _prefix(module, lay, prefix, rename=None, base=0):
    """``{constant name: (bound value, declared offset)}`` for a layout bound as ``prefix + NAME``."""
    rename = rename or {}
    return {rename.get(f.name, prefix + f.name): (getattr(module, rename.get(f.name, prefix + f.name)),
                                                  base + lay.offset(f.name)) for f in lay.fields}


def test_bound_offsets_are_their_fields():
    # the constants kernels use are bound by name; a constant bound to the wrong field fails here
    pairs = {}
    pairs.update(_prefix(plant, plant.PLANT_PARAMS, "P_"))
    pairs.update(_prefix(plant, plant.RK4_WORK, "_W_"))
    pairs.update(_prefix(layout, layout.STATE, "X_"))
    pairs.update(_prefix(layout, layout.MEASUREMENT, "MEAS_"))
    pairs.update(_prefix(layout, layout.REFERENCE, "REF_"))
    pairs.update(_prefix(layout, layout.COMMAND, "CMD_"))
    for channel in (sensors.imu, sensors.mocap, sensors.attitude, sensors.airflow_probe):
        pairs.update(_prefix(channel, channel.PARAMS, "_"))
        pairs.update(_prefix(channel, channel.STATE, "_S_"))
        pairs.update(_prefix(channel, channel.DRAWS, "_D_"))
    pairs.update({f"{k} (wind)": v for k, v in _prefix(dryden, dryden.TURBULENCE_STATE, "_S_").items()})
    pairs.update(_prefix(allocation, allocation.ALLOC_PARAMS, "AL_"))
    pairs.update(_prefix(layout, layout.PLANT_INPUT, "IN_"))
    wrong = {name: v for name, v in pairs.items() if v[0] != v[1]}
    assert wrong == {}
    assert len(pairs) > 100
