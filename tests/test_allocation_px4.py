"""PX4's sequential desaturation (``[allocation] method = "px4"``) against cases computed by hand from PX4's
published algorithm (ControlAllocationSequentialDesaturation: pseudo-inverse, thrust, roll and pitch first,
yaw last with 15 % temporary headroom, MC_AIRMODE 0/1/2), and the unsaturated case against numpy's pinv.

The hand cases use a symmetric X quad (rotors at (+-0.25, +-0.25) m, 10 N each at full throttle, moment
constant 0.05 m, PX4's rotor order and spins), whose PX4-normalised mix is, per rotor, thrust 1, roll
-+0.7071, pitch +-0.7071, yaw +-1; the normalised setpoints are T / 40 N, tau_x 0.1 sqrt(2), tau_y 0.1
sqrt(2) and tau_z / 2 (per N m). Setpoints below are rotor thrust fractions."""
import math
import sys
import types

import numpy as np
import pytest

import vtoladapt
from vtoladapt import layout
from vtoladapt.sim.allocation import (ALLOC_PARAMS, ALLOC_REPORT, ALLOC_REPORT_OFFSET, ALLOC_WORK_SIZE, EFFECTIVENESS,
                                      N_ALLOC, N_OUT, Effectiveness, EffectivenessInfo, allocate, allocator_params,
                                      effectiveness_of)

T_MAX = 10.0
ARM = 0.25
KM = 0.05


def _quad_effectiveness(vehicle):
    B0 = np.zeros((N_OUT, N_ALLOC))
    pos = [(ARM, ARM), (-ARM, -ARM), (ARM, -ARM), (-ARM, ARM)]
    km = [KM, KM, -KM, -KM]
    for i, ((x, y), k) in enumerate(zip(pos, km)):
        B0[:, i] = [1.0, -y, x, k]
    hi = np.zeros(N_ALLOC)
    hi[:4] = T_MAX
    share = np.zeros(N_ALLOC)
    share[:4] = 0.25
    return Effectiveness(B0, np.zeros((N_OUT, N_ALLOC)), np.zeros(N_ALLOC), hi, share, T_MAX, 1.0)


@pytest.fixture(scope="module")
def quad():
    mod = types.ModuleType("test_px4_symmetric_quad")
    mod.effectiveness = _quad_effectiveness
    sys.modules[mod.__name__] = mod
    EFFECTIVENESS.register(EffectivenessInfo("test_quad", "a symmetric X quad", mod.__name__))
    try:
        yield vtoladapt.load_vehicle("caltech_vtol")
    finally:
        EFFECTIVENESS.unregister("test_quad")
        del sys.modules[mod.__name__]


def _meas(veh, qbar):
    meas = np.zeros(layout.MEAS_SIZE)
    meas[layout.MEAS_Q_WB] = 1.0
    meas[layout.MEAS_V_I_B] = math.sqrt(2.0 * qbar / veh.envelope.air_density_kgpm3)
    meas[layout.MEAS_V_I_VALID] = 1.0 if qbar > 0 else 0.0
    return meas


def _allocate(veh, p, y, qbar=0.0):
    """``(rotor thrusts N, surfaces rad, achieved [T, tau], saturated)`` for the demand ``y``."""
    total = p[ALLOC_PARAMS.slice("TOTAL_UNIT")][0]
    t_unit = p[ALLOC_PARAMS.slice("T_UNIT")][0]
    cmd = np.zeros(layout.CMD_SIZE)
    cmd[layout.CMD_U_Z] = math.sqrt(y[0] / total)
    cmd[layout.CMD_TAU_B:layout.CMD_TAU_B + 3] = y[1:]
    out = np.zeros(layout.N_ACTUATORS)
    w = np.zeros(ALLOC_WORK_SIZE)
    sat = allocate(cmd, _meas(veh, qbar), p, out, w, 0)
    rep = w[ALLOC_REPORT_OFFSET:ALLOC_REPORT_OFFSET + ALLOC_REPORT.size]
    return (t_unit * out[:4] ** 2, out[layout.ACT_SURFACE:layout.ACT_SURFACE + layout.N_SURFACES],
            rep[ALLOC_REPORT.slice("ACHIEVED")].copy(), bool(sat))


def test_the_quads_mix_is_pxs_normalised_pseudo_inverse(quad):
    p = allocator_params(quad, effectiveness_id="test_quad", method="px4")
    mix = p[ALLOC_PARAMS.slice("PX4_MIX")].reshape(4, 4)
    r = 1 / math.sqrt(2)
    np.testing.assert_allclose(mix, [[1, -r, r, 1], [1, r, -r, 1], [1, r, r, -1], [1, -r, -r, -1]], atol=1e-12)
    np.testing.assert_allclose(p[ALLOC_PARAMS.slice("PX4_SCALE")], [1 / 40, 0.1 * math.sqrt(2),
                                                                    0.1 * math.sqrt(2), 0.5], rtol=1e-12)


# (airmode, [T N, tau_x, tau_y, tau_z N m], the hand-computed rotor thrust fractions)
HAND_CASES = [
    # yaw alone past the rotors' range: +0.8 on 0.5 gives 1.3 / -0.3; with 15 % headroom the gains are -0.15
    # (rotors 0, 1) and -0.3 (rotors 2, 3), summed -0.3: [1, 1, 0, 0]; thrust stays 20 N, yaw 1.6 -> 1.0 N m
    (0, [20.0, 0.0, 0.0, 1.6], [1.0, 1.0, 0.0, 0.0]),
    # roll at the rotors' bounds (0.5 -+ 0.5), then yaw 0.2: [0.2, 1.2, 0.8, -0.2]; gains -0.05 and -0.2 sum
    # to -0.2: yaw gives way entirely, roll and thrust are kept: [0, 1, 1, 0]
    (0, [20.0, 5.0, 0.0, 0.4], [0.0, 1.0, 1.0, 0.0]),
    # thrust high, roll saturating: 0.75 -+ 0.4 = [0.35, 1.15, 1.15, 0.35], thrust down by 0.15; yaw 0.2
    # gives [0.4, 1.2, 0.8, 0.0], headroom gain -0.05 -> [0.35, 1.15, 0.85, 0.05]; thrust down 0.15 ->
    # [0.2, 1.0, 0.7, -0.1], the half step back up 0.05 -> [0.25, 1.05, 0.75, -0.05]; clipped
    (0, [30.0, 4.0, 0.0, 0.4], [0.25, 1.0, 0.75, 0.0]),
    # airmode off, low thrust, large roll: [-0.1, 0.3, 0.3, -0.1]; thrust may not rise (gain +0.1 refused),
    # roll gives way by -0.1414 along its column: [0, 0.2, 0.2, 0] (roll 2 -> 1 N m, thrust 4 N kept)
    (0, [4.0, 2.0, 0.0, 0.0], [0.0, 0.2, 0.2, 0.0]),
    # the same with roll/pitch airmode: thrust rises by 0.1 instead: [0, 0.4, 0.4, 0] (roll kept, 8 N)
    (1, [4.0, 2.0, 0.0, 0.0], [0.0, 0.4, 0.4, 0.0]),
    # roll/pitch/yaw airmode: yaw mixed in at once, [1.3, 1.3, -0.3, -0.3]; thrust gains -0.3 and +0.3
    # cancel; yaw (no headroom) -0.3: [1, 1, 0, 0]
    (2, [20.0, 0.0, 0.0, 1.6], [1.0, 1.0, 0.0, 0.0]),
]


@pytest.mark.parametrize("airmode, y, expected", HAND_CASES)
def test_hand_computed_desaturation(quad, airmode, y, expected):
    p = allocator_params(quad, effectiveness_id="test_quad", method="px4", airmode=airmode)
    T, _s, achieved, sat = _allocate(quad, p, np.array(y))
    np.testing.assert_allclose(T / T_MAX, expected, atol=1e-12)
    B = np.asarray(_quad_effectiveness(quad).B0)[:, :4]
    np.testing.assert_allclose(achieved, B @ T, atol=1e-9)
    assert sat


def test_yaw_gives_way_first_when_roll_and_pitch_saturate(quad):
    """Roll and pitch asked together at the edge, with a yaw demand: what is given up is yaw; roll, pitch and
    thrust are what was asked (airmode 0)."""
    p = allocator_params(quad, effectiveness_id="test_quad", method="px4")
    y = np.array([20.0, 2.5, 2.5, 0.8])   # roll and pitch each +-0.25 on 0.5: rotors at [0.5, 0.5, 1, 0]
    T, _s, achieved, sat = _allocate(quad, p, y)
    assert sat
    np.testing.assert_allclose(achieved[:3], y[:3], atol=1e-9)
    assert abs(achieved[3]) < 0.5 * y[3]


@pytest.mark.parametrize("name", ["caltech_vtol", "px4_standard_vtol"])
@pytest.mark.parametrize("airmode", [0, 1, 2])
def test_unsaturated_px4_allocation_is_the_pseudo_inverse(name, airmode):
    """Demands the rotors can meet (random thrusts inside their range, hover, surfaces off): PX4's allocation
    is numpy.linalg.pinv of the believed effectiveness applied to the demand, met exactly, not saturated."""
    veh = vtoladapt.load_vehicle(name)
    p = allocator_params(veh, surfaces=False, method="px4", airmode=airmode)
    eff = effectiveness_of(veh)
    B = np.asarray(eff.B0)[:, :4]
    t_max = np.asarray(eff.upper)[:4]
    rng = np.random.default_rng(5)
    for _ in range(100):
        y = B @ rng.uniform(0.15, 0.85, 4) * t_max
        T, s, achieved, sat = _allocate(veh, p, y)
        assert not sat
        np.testing.assert_allclose(T, np.linalg.pinv(B) @ y, rtol=1e-9, atol=1e-9 * t_max.max())
        np.testing.assert_allclose(achieved, y, rtol=1e-9, atol=1e-9)
        assert np.all(s == 0.0)


def test_px4_surfaces_take_the_moment_first_at_speed_and_none_in_hover():
    """At speed the surfaces get the pseudo-inverse of their moment columns over the dynamic pressure, the
    rotors the rest: a feasible demand is met exactly; in hover (below the vehicle's hover-blend airspeed)
    the surfaces stay neutral."""
    veh = vtoladapt.load_vehicle("px4_standard_vtol")
    p = allocator_params(veh, method="px4", airmode=1)
    y = np.array([40.0, 0.3, 0.2, 0.05])
    T_h, s_h, ach_h, sat_h = _allocate(veh, p, y, 0.0)
    T_f, s_f, ach_f, sat_f = _allocate(veh, p, y, 60.0)
    assert not sat_h and not sat_f
    assert np.all(s_h == 0.0) and np.abs(s_f).max() > 1e-3
    np.testing.assert_allclose(ach_f, y, atol=1e-9)
    np.testing.assert_allclose(ach_h, y, atol=1e-9)
    eff = effectiveness_of(veh)
    Bq = np.asarray(eff.B_per_Pa)[1:, 4:7]
    np.testing.assert_allclose(s_f[:3], np.linalg.pinv(Bq) @ y[1:] / 60.0, rtol=1e-9)


def test_bad_method_and_airmode_are_one_line_errors():
    from vtoladapt.config import ConfigError
    from vtoladapt.sim.scenario import scenario_from_mapping

    veh = vtoladapt.load_vehicle("caltech_vtol")
    with pytest.raises(ValueError, match="method = 'lp': unknown; allowed: bounded_lsq, px4"):
        allocator_params(veh, method="lp")
    for bad, match in (({"method": "qp"}, r"\[allocation\] method = 'qp'"),
                       ({"airmode": 3}, r"\[allocation\] airmode = 3")):
        with pytest.raises(ConfigError, match=match):
            scenario_from_mapping({"name": "x", "vehicle": "caltech_vtol", "duration_s": 1.0, "allocation": bad},
                                  "x.toml")
