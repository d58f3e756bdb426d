"""Control surfaces in the plant against their analytic derivatives; servos against their closed forms and
scipy; the vehicle files' surface tables against their sources; the physical truth draw."""
import math

import numpy as np
import pytest

import vtoladapt
from vtoladapt import layout
from vtoladapt.sim import plant
from vtoladapt.sim.surfaces import servo_response, servo_response_reference
from vtoladapt.sim.truth import PHYSICAL_DRAW_CLIP_SIGMAS, draw_physical_parameters


@pytest.fixture(scope="module", params=["caltech_vtol", "px4_standard_vtol"])
def veh(request):
    return vtoladapt.load_vehicle(request.param)


def _forces(p, v_i_B, surface_rad, loss=None):
    """The plant's true (specific force, moment) with the surfaces at ``surface_rad`` and the rotors off."""
    act = np.zeros(layout.N_ACTUATORS)
    act[layout.ACT_SURFACE:layout.ACT_SURFACE + len(surface_rad)] = surface_rad
    lossv = np.zeros(layout.N_SURFACES) if loss is None else np.asarray(loss, dtype=float)
    rotors = plant.rotor_terms(act, 0, p, lossv, 0)
    out = plant.true_forces_moments(*v_i_B, 0.0, 0.0, 0.0, rotors, p)
    return np.array(out[:3]), np.array(out[3:])


@pytest.mark.parametrize("airspeed", [4.0, 10.0, 18.0])
@pytest.mark.parametrize("delta", [-0.3, 0.05, 0.2])
def test_surface_moment_is_the_analytic_derivative(veh, airspeed, delta):
    """Each surface's force and moment: q S [CX, CY, CZ] delta and q S [b Cl, c Cm, b Cn] delta, with
    q = rho V^2 / 2 of the incident flow, from the vehicle file's numbers (the difference to the same
    flow with the surfaces neutral, so the wing's own force drops out)."""
    eff = 1.3
    p = plant.plant_config_from_mapping({"surface_effectiveness": [eff] * 4}, "test").to_kernel(veh)
    rho = veh.envelope.air_density_kgpm3
    S, b = veh.geometry.wing_area_m2, veh.geometry.wingspan_m
    c = S / b
    m = veh.mass.mass_kg
    v = airspeed * np.array([math.cos(0.05), 0.02, math.sin(0.05)])
    q = 0.5 * rho * float(v @ v)
    f0, M0 = _forces(p, v, [])
    for j, sf in enumerate(veh.surfaces):
        deflect = np.zeros(j + 1)
        deflect[j] = delta
        f, M = _forces(p, v, deflect)
        cx, cy, cz, cl, cm, cn = sf.derivatives_per_rad
        np.testing.assert_allclose(M - M0, eff * q * S * delta * np.array([b * cl, c * cm, b * cn]),
                                   rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose((f - f0) * m, eff * q * S * delta * np.array([cx, cy, cz]), rtol=1e-12,
                                   atol=1e-12)
        # a lost surface does nothing
        loss = np.zeros(layout.N_SURFACES)
        loss[j] = 1.0
        f_lost, M_lost = _forces(p, v, deflect, loss)
        np.testing.assert_allclose(M_lost, M0, atol=1e-12)


def test_surfaces_do_nothing_in_still_air(veh):
    p = plant.plant_config_from_mapping({}, "test").to_kernel(veh)
    f, M = _forces(p, np.zeros(3), [0.3] * len(veh.surfaces))
    assert np.all(M == 0.0) and np.all(f == 0.0)


@pytest.mark.parametrize("d0, c, tau, rate", [
    (0.0, 0.02, 0.02, 8.7),    # small step: the lag alone
    (0.0, 0.4, 0.02, 8.7),     # large step: slew at the rate limit, then the lag
    (0.3, -0.3, 0.05, 3.0),    # the other way, slow servo
])
def test_servo_closed_form_matches_its_ode(d0, c, tau, rate):
    t = np.linspace(0.0, 0.3, 61)
    ours = np.array([servo_response(d0, c, s, tau, rate) for s in t])
    ref = servo_response_reference(d0, c, t, tau, rate)
    np.testing.assert_allclose(ours, ref, atol=1e-8)


def test_the_plant_servo_follows_lag_and_rate_limit_analytically():
    """A step of 0.4 rad on the PX4 elevator (tau 25 ms, 400 deg/s): in the closed-loop integrator the
    surface ramps at exactly the rate limit until the gap is R tau, then decays as exp(-t / tau)."""
    veh = vtoladapt.load_vehicle("px4_standard_vtol")
    p = plant.plant_config_from_mapping({}, "test").to_kernel(veh)
    sf = veh.surfaces[2]
    tau, R = sf.time_constant_s, math.radians(sf.rate_limit_degps)
    c = 0.4
    x = layout.pack_state([0, 0, -50], [0, 0, 0], [1, 0, 0, 0], [0, 0, 0], np.zeros(5))
    u = plant.plant_input(np.r_[np.zeros(5), 0.0, 0.0, c, 0.0])
    work = np.zeros(plant.RK4_WORK_SIZE)
    h = 0.001
    t1 = (c - R * tau) / R

    def analytic(t):
        return R * t if t <= t1 else c - R * tau * math.exp(-(t - t1) / tau)

    for k in range(1, 121):
        plant.plant_advance(x, u, np.zeros(3), p, h, 1, False, work)
        assert x[layout.X_SERVO + 2] == pytest.approx(analytic(k * h), abs=1e-12)
    # a slow servo (servo_slow fault, factor 3): tau x 3, rate / 3
    x[layout.X_SERVO + 2] = 0.0
    u[layout.IN_SERVO_SLOWDOWN + 2] = 2.0
    tau3, R3 = 3 * tau, R / 3
    t13 = (c - R3 * tau3) / R3
    for k in range(1, 301):
        plant.plant_advance(x, u, np.zeros(3), p, h, 1, False, work)
    t = 0.3
    expected = R3 * t if t <= t13 else c - R3 * tau3 * math.exp(-(t - t13) / tau3)
    assert x[layout.X_SERVO + 2] == pytest.approx(expected, abs=1e-12)
    # commands beyond the limit stop at the limit
    u[layout.IN_SERVO_SLOWDOWN + 2] = 0.0
    u[layout.ACT_SURFACE + 2] = 5.0
    for _ in range(1000):
        plant.plant_advance(x, u, np.zeros(3), p, h, 1, False, work)
    assert x[layout.X_SERVO + 2] == pytest.approx(math.radians(sf.limit_deg), abs=1e-9)


def test_surfaces_in_the_rk4_path_agree_with_solve_ivp():
    """Surfaces deflecting in a 12 m/s flow: the fixed-step plant (exact servos) against DOP853."""
    veh = vtoladapt.load_vehicle("caltech_vtol")
    p = plant.plant_config_from_mapping({}, "test").to_kernel(veh)
    x0 = layout.pack_state([0, 0, -5], [12.0, 0.0, 0.0], [1, 0, 0, 0], [0.0, 0.0, 0.0], [0.5] * 4 + [0.4])
    u = plant.plant_input([0.5, 0.5, 0.5, 0.5, 0.4, 0.05, -0.01, 0.01, 0.0])  # within the slew limit: smooth
    ref = plant.integrate_reference(x0, u, np.zeros(3), p, 0.2)
    x = x0.copy()
    f = np.empty(3)
    for _ in range(200):
        plant.rk4_step(x, u, np.zeros(3), p, 0.001, f)
    np.testing.assert_allclose(x[layout.X_SERVO:layout.X_SERVO + 3], ref[layout.X_SERVO:layout.X_SERVO + 3], atol=1e-9)
    np.testing.assert_allclose(x[layout.X_OMEGA_B:layout.X_OMEGA_B + 3], ref[layout.X_OMEGA_B:layout.X_OMEGA_B + 3],
                               atol=1e-7)
    assert abs(ref[layout.X_OMEGA_B]) > 0.05  # the aileron rolled it: the check is not of a still airframe


def test_px4_surfaces_are_the_gazebo_models():
    """The vehicle file's numbers re-derived from the sdf's joints and lift-drag plugins."""
    from vtoladapt.vehicles.px4_standard_vtol import PX4_STANDARD_VTOL, px4_standard_vtol_surfaces

    veh = vtoladapt.load_vehicle("px4_standard_vtol")
    derived = px4_standard_vtol_surfaces(veh.geometry.wing_area_m2, veh.geometry.wingspan_m)
    assert [s.name for s in veh.surfaces] == list(derived)
    for sf in veh.surfaces:
        np.testing.assert_allclose(sf.derivatives_per_rad, derived[sf.name], atol=5e-7)
        assert sf.limit_deg == pytest.approx(math.degrees(PX4_STANDARD_VTOL["surface_limit_rad"]), abs=1e-3)
    # a positive left elevon (less lift on the left half) rolls left, the right one right; both pitch up
    left, right = veh.surfaces[0].derivatives, veh.surfaces[1].derivatives
    assert left["Cl"] < 0 < right["Cl"] and left["Cm"] > 0 and right["Cm"] > 0


def test_caltech_v_tail_is_symmetric():
    veh = vtoladapt.load_vehicle("caltech_vtol")
    l, r = (s.derivatives for s in veh.surfaces[1:3])
    assert l["Cm"] == r["Cm"] < 0 and l["Cn"] == -r["Cn"] and l["CY"] == -r["CY"] and l["CZ"] == r["CZ"] < 0


# --- the physical truth draw --------------------------------------------------------------------------

def test_physical_draw_is_seeded_spread_as_stated_and_leaves_the_table_i_draw_alone():
    veh = vtoladapt.load_vehicle("px4_standard_vtol")
    u = veh.uncertainty
    a, b = draw_physical_parameters(veh, 7), draw_physical_parameters(veh, 7)
    assert a == b and a != draw_physical_parameters(veh, 8)
    draws = [draw_physical_parameters(veh, s) for s in range(3000)]
    # a standard normal clipped to +-c: E[z^2] = (2 Phi(c) - 1) - 2 c phi(c) + 2 c^2 (1 - Phi(c))
    from scipy.stats import norm

    c = PHYSICAL_DRAW_CLIP_SIGMAS
    clipped_std = math.sqrt((2 * norm.cdf(c) - 1) - 2 * c * norm.pdf(c) + 2 * c * c * norm.sf(c))
    stall = np.array([d["stall_angle_deg"] for d in draws])
    assert stall.mean() == pytest.approx(veh.envelope.stall_angle_deg, abs=0.1)
    assert stall.std() == pytest.approx(u.stall_angle_deg * clipped_std, rel=0.06)
    assert np.abs(stall - veh.envelope.stall_angle_deg).max() <= PHYSICAL_DRAW_CLIP_SIGMAS * u.stall_angle_deg + 1e-9
    log_mass = np.log([d["mass_kg"] / veh.mass.mass_kg for d in draws])
    assert log_mass.std() == pytest.approx(u.mass_frac * clipped_std, rel=0.06)
    eff = np.log([d["surface_effectiveness"] for d in draws])
    np.testing.assert_allclose(eff.std(axis=0), u.surface_effectiveness_frac * clipped_std, rtol=0.08)
    assert abs(np.corrcoef(eff[:, 0], eff[:, 1])[0, 1]) < 0.06  # independent
    # its own stream: the Table I draw of a seed is the same with or without it
    from vtoladapt.sim.scenario import scenario_from_mapping

    base = {"name": "t", "vehicle": "px4_standard_vtol", "duration_s": 1.0, "seed": 11,
            "plant": {"coefficients_from": "table_i_draw"}}
    sc1 = scenario_from_mapping(base, "t")
    sc2 = scenario_from_mapping({**base, "plant": {"coefficients_from": "table_i_draw", "physical_from": "draw"}}, "t")
    r1, r2 = sc1.plant.resolved(veh, 11), sc2.plant.resolved(veh, 11)
    assert r1.coefficients == r2.coefficients
    assert r2.mass_kg == pytest.approx(draw_physical_parameters(veh, 11)["mass_kg"])
    # an explicit value is kept
    sc3 = scenario_from_mapping({**base, "plant": {"physical_from": "draw", "mass_kg": 4.0}}, "t")
    assert sc3.plant.resolved(veh, 11).mass_kg == 4.0


def test_a_drawn_plant_changes_the_truth_but_not_the_controller():
    from vtoladapt.sim.driver import prepare
    from vtoladapt.sim.scenario import scenario_from_mapping

    base = {"name": "t", "vehicle": "caltech_vtol", "duration_s": 0.1, "seed": 5}
    a = prepare(scenario_from_mapping(base, "t"))
    b = prepare(scenario_from_mapping({**base, "plant": {"physical_from": "draw"}}, "t"))
    np.testing.assert_array_equal(a.controller_params, b.controller_params)
    np.testing.assert_array_equal(a.mixer_params, b.mixer_params)
    assert b.plant_params[plant.P_MASS] != a.plant_params[plant.P_MASS]
    assert b.plant_params[plant.P_TAU_LIFT] != a.plant_params[plant.P_TAU_LIFT]
    assert not np.array_equal(b.plant_params[plant.PLANT_PARAMS.slice("SURF_M")],
                              a.plant_params[plant.PLANT_PARAMS.slice("SURF_M")])
