"""The effectiveness kind wired through: each shipped effectiveness against finite differences of the
plant's true lift and moment, PX4's belief against the sdf's truth, and a user's effectiveness module
flown in the closed loop with the effect it predicts."""
import math
import sys
import types

import numpy as np
import pytest

import vtoladapt
from vtoladapt import forces, layout
from vtoladapt.config import ConfigError
from vtoladapt.sim import plant
from vtoladapt.sim.allocation import EFFECTIVENESS, N_ALLOC, N_OUT, EffectivenessInfo, effectiveness_of

VEHICLES = ("caltech_vtol", "px4_standard_vtol")


def _plant_lift_moment(p, v_i_B, thrust_N, surface_rad, t_unit_plant):
    """The plant's true ``[lift along -z (N), Mx, My, Mz (N m)]`` with the lift rotors at ``thrust_N`` and the
    surfaces at ``surface_rad``, no rotation, the pusher off."""
    act = np.zeros(layout.N_ACTUATORS)
    act[:layout.N_LIFT] = np.sqrt(np.asarray(thrust_N) / t_unit_plant)
    act[layout.ACT_SURFACE:layout.ACT_SURFACE + len(surface_rad)] = surface_rad
    rotors = plant.rotor_terms(act, 0, p, np.zeros(layout.N_SURFACES), 0)
    fx, fy, fz, mx, my, mz = plant.true_forces_moments(*v_i_B, 0.0, 0.0, 0.0, rotors, p)
    return np.array([-fz * p[plant.P_MASS], mx, my, mz])


def _finite_difference_B(veh, airspeed, h_N=1e-3, h_rad=1e-4):
    """Central differences of the plant's lift and moment in each actuator (rotor thrust, surface
    deflection) about a hover-like point, with the dynamic pressure of ``airspeed`` along body x."""
    p = plant.plant_config_from_mapping({}, "test").to_kernel(veh)
    t_unit = p[plant.P_FORCE_MASS] * p[plant.P_THETA + forces.I_CTZ] / layout.N_LIFT
    v = np.array([airspeed, 0.0, 0.0])
    T0 = np.full(layout.N_LIFT, 0.4 * t_unit)
    d0 = np.zeros(len(veh.surfaces))
    B = np.zeros((N_OUT, N_ALLOC))
    for i in range(layout.N_LIFT):
        e = np.zeros(layout.N_LIFT)
        e[i] = h_N
        B[:, i] = (_plant_lift_moment(p, v, T0 + e, d0, t_unit) - _plant_lift_moment(p, v, T0 - e, d0, t_unit)) / (2 * h_N)
    for j in range(len(veh.surfaces)):
        e = np.zeros(len(veh.surfaces))
        e[j] = h_rad
        B[:, layout.N_LIFT + j] = (_plant_lift_moment(p, v, T0, d0 + e, t_unit)
                                   - _plant_lift_moment(p, v, T0, d0 - e, t_unit)) / (2 * h_rad)
    qbar = 0.5 * p[plant.P_RHO] * airspeed ** 2
    return B, qbar


@pytest.mark.parametrize("name", VEHICLES)
@pytest.mark.parametrize("airspeed", [0.0, 6.0, 12.0])
def test_lift_rotors_surfaces_is_the_plants_own_effectiveness(name, airspeed):
    """'lift_rotors_surfaces' believes the vehicle file, and the plant flies the vehicle file: its B0 +
    qbar B_per_Pa equals the plant's finite-difference Jacobian of lift and moment (1e-7 relative)."""
    veh = vtoladapt.load_vehicle(name)
    B_fd, qbar = _finite_difference_B(veh, airspeed)
    eff = effectiveness_of(veh, "lift_rotors_surfaces")
    B = np.asarray(eff.B0) + qbar * np.asarray(eff.B_per_Pa)
    np.testing.assert_allclose(B, B_fd, rtol=1e-7, atol=1e-7 * np.abs(B_fd).max())
    assert np.abs(B[3, :layout.N_LIFT]).min() > 0.0  # every rotor yaws the airframe


def _vehicle_as_px4_believes(veh):
    """The vehicle with its rotors where PX4's CA_* parameters put them (positions and KM): a plant of the
    airframe the parameters describe."""
    import dataclasses

    t = veh.effectiveness_table("px4_ca")
    km = t["rotor_km_m"]
    spin = tuple(-1 if k > 0 else 1 for k in km)
    geo = dataclasses.replace(veh.geometry, lift_rotor_positions_m=tuple(zip(t["rotor_px_m"], t["rotor_py_m"])),
                              lift_rotor_spin=spin)
    act = dataclasses.replace(veh.actuators, yaw_torque_per_thrust_m=abs(km[0]))
    return veh.replace(geometry=geo, actuators=act)


@pytest.mark.parametrize("airspeed", [0.0, 9.0])
def test_px4_ca_is_the_effectiveness_of_the_airframe_its_parameters_describe(airspeed):
    """'px4_ca' on px4_standard_vtol: its rotor columns equal the finite differences of a plant whose rotors
    stand where CA_ROTORn_PX/PY put them with CA_ROTORn_KM; its surface columns those of the plant on the
    axes CA_SV_CSn_TRQ_* name (none of the surfaces' lift, which PX4's allocator does not model)."""
    veh = vtoladapt.load_vehicle("px4_standard_vtol")
    believed = _vehicle_as_px4_believes(veh)
    B_fd, qbar = _finite_difference_B(believed, airspeed)
    eff = effectiveness_of(veh, "px4_ca")
    B = np.asarray(eff.B0) + qbar * np.asarray(eff.B_per_Pa)
    n = layout.N_LIFT
    np.testing.assert_allclose(B[:, :n], B_fd[:, :n], rtol=1e-7, atol=1e-9)
    torque = np.array(veh.effectiveness_table("px4_ca")["surface_torque"])
    for j in range(len(veh.surfaces)):
        named = torque[j] != 0.0
        np.testing.assert_allclose(B[1:, n + j][named], B_fd[1:, n + j][named], rtol=1e-6, atol=1e-12)
        assert np.all(B[1:, n + j][~named] == 0.0) and B[0, n + j] == 0.0


def test_px4_belief_differs_from_the_sdf_truth_as_the_files_say():
    """The truth (sdf: +-0.35 m, momentConstant 0.06) against the belief (CA_*: 0.1515 / 0.245, 0.1875 m,
    KM 0.05): yaw per newton 0.05 / 0.06, roll arms 0.245 / 0.35 and 0.1875 / 0.35, pitch 0.1515 / 0.35."""
    veh = vtoladapt.load_vehicle("px4_standard_vtol")
    truth = np.asarray(effectiveness_of(veh, "lift_rotors_surfaces").B0)[:, :layout.N_LIFT]
    belief = np.asarray(effectiveness_of(veh).B0)[:, :layout.N_LIFT]  # the vehicle file's default: px4_ca
    assert veh.effectiveness == "px4_ca"
    np.testing.assert_allclose(belief[3] / truth[3], 0.05 / 0.06, rtol=1e-12)
    np.testing.assert_allclose(np.abs(belief[1] / truth[1]), [0.245 / 0.35, 0.1875 / 0.35, 0.245 / 0.35,
                                                              0.1875 / 0.35], rtol=1e-12)
    np.testing.assert_allclose(belief[2] / truth[2], 0.1515 / 0.35, rtol=1e-12)
    assert np.all(np.sign(belief) == np.sign(truth))  # same rotors, same senses


def test_px4_ca_refuses_a_sign_that_disagrees_with_the_vehicles_surface():
    veh = vtoladapt.load_vehicle("px4_standard_vtol")
    tables = dict((k, dict(veh.effectiveness_table(k))) for k, _ in veh.effectiveness_settings)
    tables["px4_ca"]["surface_torque"] = [[0.5, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 1.0, 0.0]]
    bad = veh.replace(effectiveness_settings=tables)
    with pytest.raises(ConfigError, match=r"surface_torque\[0\] TRQ_R = 0.5: .*opposite moment"):
        effectiveness_of(bad, "px4_ca")
    with pytest.raises(ConfigError, match=r"needs a \[effectiveness_settings.px4_ca\] table"):
        effectiveness_of(vtoladapt.load_vehicle("caltech_vtol"), "px4_ca")


def test_an_unknown_effectiveness_is_a_one_line_error():
    from vtoladapt.sim.scenario import scenario_from_mapping

    with pytest.raises(ConfigError, match=r"\[allocation\] effectiveness = 'nope': unknown; allowed: "
                                          r"'lift_rotors_surfaces', 'px4_ca'"):
        scenario_from_mapping({"name": "x", "vehicle": "caltech_vtol", "duration_s": 1.0,
                               "allocation": {"effectiveness": "nope"}}, "x.toml")


# --- a user's effectiveness flies ------------------------------------------------------------------------
YAW_FACTOR = 2.0


def _users_module():
    """A user's airframe belief: the package's effectiveness with the rotors' yaw authority doubled (a
    wrong belief on purpose, so its effect is predictable)."""
    from vtoladapt.sim.effectiveness import effectiveness as package_effectiveness

    mod = types.ModuleType("user_effectiveness_double_yaw")

    def effectiveness(vehicle):
        e = package_effectiveness(vehicle)
        B0 = np.array(e.B0)
        B0[3, :layout.N_LIFT] *= YAW_FACTOR
        return type(e)(B0, e.B_per_Pa, e.lower, e.upper, e.preferred_share, e.t_unit_N, e.throttle_max)

    mod.effectiveness = effectiveness
    return mod


@pytest.fixture()
def users_effectiveness():
    from vtoladapt.components import register

    mod = _users_module()
    sys.modules[mod.__name__] = mod
    register("effectiveness", EffectivenessInfo("double_yaw", "the rotors' yaw believed twice as strong",
                                                mod.__name__))
    try:
        yield "double_yaw"
    finally:
        EFFECTIVENESS.unregister("double_yaw")
        del sys.modules[mod.__name__]


def test_a_users_effectiveness_flies_and_changes_the_commands_as_predicted(users_effectiveness):
    """A closed-loop run in hover with a yaw step: with the user's module (yaw believed twice as strong) every
    unsaturated tick's asked moment is met on the allocator's own model, and the differential thrust the
    rotors get for the same asked yaw moment is half the package's (the allocator inverts what it believes:
    (T0 + T1 - T2 - T3) k_m 2 = tau_z). The aircraft still holds (the controller closes the loop)."""
    from vtoladapt.sim.driver import simulate
    from vtoladapt.sim.scenario import scenario_from_mapping

    base = {"name": "user_eff", "vehicle": "caltech_vtol", "duration_s": 6.0, "seed": 3,
            "reference": {"yaw_deg": 20.0}, "controller": {"kind": "pd"}}
    sc_user = scenario_from_mapping({**base, "allocation": {"effectiveness": users_effectiveness,
                                                            "surfaces": False}}, "user_eff")
    sc_pkg = scenario_from_mapping({**base, "allocation": {"surfaces": False}}, "pkg_eff")
    veh = vtoladapt.load_vehicle("caltech_vtol")
    km = veh.actuators.yaw_torque_per_thrust_m
    spin = np.array(veh.geometry.lift_rotor_spin, dtype=float)
    for sc, factor in ((sc_user, YAW_FACTOR), (sc_pkg, 1.0)):
        res = simulate(sc)
        assert res.metadata["diverged_at_s"] is None
        t_unit = veh.mass.mass_kg * veh.theta_scaled[1] / layout.N_LIFT
        T = t_unit * np.stack([res[f"motor{i + 1}_cmd_frac"] for i in range(layout.N_LIFT)], axis=1) ** 2
        yaw_model = (T * (-spin * km * factor)).sum(axis=1)
        ok = res["mixer_saturated"] == 0.0
        asked = res["alloc_asked_tau_z_Nm"]
        np.testing.assert_allclose(yaw_model[ok], asked[ok], atol=1e-6)
        assert np.abs(asked[ok]).max() > 1e-3  # the yaw step asked a yaw moment
