"""The controller's Python API refuses what its file path refuses, and never hands a kernel a wrong object.

Each test here failed before the fix it names: settings built in Python were not validated (NaN
gains gave all-zero commands), the scenario's ``dt_control_s`` never reached the controller's
stability checks, ``step`` read past the end of a Reference passed as the Measurement, a NaN first
``t`` locked the controller, an all-NaN snapshot was restored, ``identifiability`` took ``T <= 0``,
the law checks' messages did not name the file, and the README's imports did not all work.
"""
from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from vtoladapt import layout as L
from vtoladapt.sim import mixer
from vtoladapt.config import ConfigError
from vtoladapt.control import (
    Command,
    Controller,
    ControllerConfig,
    ControllerSnapshot,
    L1Settings,
    Measurement,
    PIDSettings,
    Reference,
    controller_config_from_mapping,
)
from vtoladapt.control.blocks import P_DT_NOMINAL
from vtoladapt.control.registry import CONTROLLERS, controller_ids

CONTROLLER_KINDS = controller_ids()
from vtoladapt.experiments.metrics import identifiability
from vtoladapt.sim.scenario import load_scenario, scenario_from_mapping
from vtoladapt.sim.driver import prepare

README = Path(__file__).resolve().parents[1] / "README.md"


def _hover():
    return Measurement.from_parts(p_W=(0, 0, -1.5), v_W=(0, 0, 0), q_WB=(1, 0, 0, 0), omega_B=(0, 0, 0),
                                  accel_B=(0, 0, -9.80665), v_i_B=(0, 0, 0))


# --- 1. settings built in Python: the file's rules, the file's messages ------------------------------

def _outcome(make, source: str):
    """``('ok', object)`` or ``('error', message with the leading source replaced by SOURCE)``."""
    try:
        return "ok", make()
    except ConfigError as exc:
        text = str(exc)
        assert text.startswith(source + ": "), text
        return "error", "SOURCE" + text[len(source):]


NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**6, 10**6),
                    st.sampled_from([0.0, -1.0, 1e-9, 0.5, 2.0, 30.0, 250.0, 1e4, 1e12]))
VALUES = st.one_of(NUMBERS, st.lists(NUMBERS, min_size=0, max_size=4), st.booleans(),
                   st.sampled_from(["composite", "pid", "l1", "indi", "bogus", "a_d", "v_r_dot", "prior"]))
SHARED_KEYS = [f.name for f in dataclasses.fields(ControllerConfig) if f.name != "laws"]


@settings(max_examples=examples(300))
@given(kind=st.sampled_from(CONTROLLER_KINDS), key=st.sampled_from(SHARED_KEYS), value=VALUES,
       law_key=st.data(), law_value=VALUES, rate=st.one_of(st.none(), NUMBERS))
def test_python_and_file_refuse_the_same_settings_with_the_same_message(kind, key, value, law_key, law_value, rate):
    """Invariant: ``ControllerConfig(**table)`` is accepted iff the ``[controller]`` table is, and gives the same
    object or the same one-line message with the class named where the file is (cross-field rules included)."""
    law_cls = CONTROLLERS[kind].settings
    law_fields = [f.name for f in dataclasses.fields(law_cls)]
    law_table = {law_key.draw(st.sampled_from(law_fields)): law_value} if law_fields else {}
    # the law's own table alone (kind stays the default, so no rule of this law with the shared gains)
    file = _outcome(lambda: controller_config_from_mapping({kind: law_table}, source="c.toml"), "c.toml")
    made = _outcome(lambda: law_cls(**law_table), law_cls.__name__)
    assert made[0] == file[0], (made, file)
    if made[0] == "error":
        assert made[1] == file[1]
        return
    assert made[1] == getattr(file[1], kind)
    # with the shared keys and the kind that flies: every rule, the cross-field ones included
    table = {"kind": kind, key: value}
    if rate is not None:
        table["loop_rate_hz"] = rate
    file = _outcome(lambda: controller_config_from_mapping({**table, kind: law_table}, source="c.toml"), "c.toml")
    made = _outcome(lambda: ControllerConfig(**table, **{kind: law_cls(**law_table)}), "ControllerConfig")
    assert made[0] == file[0], (made, file)
    assert made[1] == file[1]


@pytest.mark.parametrize("make", [
    lambda: ControllerConfig(K_v=(math.nan, 1.8, 4.0)),
    lambda: ControllerConfig(kind="pid", pid=PIDSettings(K_I=(math.nan, 0.4, 2.0))),
    lambda: ControllerConfig(K_v=(-5.0, -5.0, -5.0)),
    lambda: PIDSettings(feedforward="bogus"),
    lambda: L1Settings(cutoff_radps=-1.0),
    lambda: ControllerConfig(lowpass_cutoff_hz=-5.0),
    lambda: ControllerConfig(gamma=math.inf),
    lambda: ControllerConfig(loop_rate_hz=math.nan),
    lambda: ControllerConfig(loop_rate_hz=0.0),
    lambda: ControllerConfig(unseen_flow_accel_mps2=(0.3, 0.2)),
    lambda: ControllerConfig(wing_heading_tolerance_deg=(30.0, 10.0)),
    lambda: ControllerConfig(weathervane_airspeed_mps=(2.0, 1.0)),
    lambda: ControllerConfig(kind="pid", pid=L1Settings()),
    lambda: dataclasses.replace(ControllerConfig(), K_v=(0.0, 1.0, 1.0)),
])
def test_the_testers_settings_are_refused_in_one_line(make):
    with pytest.raises(ConfigError) as info:
        make()
    text = str(info.value)
    assert "\n" not in text and re.match(r"(ControllerConfig|PIDSettings|L1Settings): \[controller", text), text


def test_numpy_values_are_taken_as_the_file_would_give_them():
    cfg = ControllerConfig(K_v=np.array([1, 2, 3]), gamma=np.float64(2.0))
    assert cfg.K_v == (1.0, 2.0, 3.0) and all(type(k) is float for k in cfg.K_v)
    assert cfg == controller_config_from_mapping({"K_v": [1, 2, 3], "gamma": 2.0})
    hash(cfg)  # still hashable: the array became a tuple


# --- 2. the scenario's tick is the controller's ------------------------------------------------------

BASE = {"name": "t", "vehicle": "caltech_vtol", "duration_s": 0.1}


def test_l1_pole_is_checked_at_the_scenarios_tick_naming_the_file():
    ok = {"controller": {"kind": "l1", "l1": {"predictor_pole_radps": 100.0}}}
    assert scenario_from_mapping({**BASE, **ok}, "s.toml").controller.loop_rate_hz == 250.0   # a_s dt = 0.4
    with pytest.raises(ConfigError, match=r"^s\.toml: \[controller\.l1\] predictor_pole_radps = 100\.0: .*here 5 "):
        scenario_from_mapping({**BASE, "dt_control_s": 0.05, **ok}, "s.toml")


def test_sigma_step_is_checked_at_the_scenarios_tick_naming_the_file():
    sc = scenario_from_mapping({**BASE, "dt_control_s": 0.05, "controller": {"composite": {"sigma": 1.0}}},
                               "s.toml")
    assert sc.controller.loop_rate_hz == 20.0
    with pytest.raises(ConfigError, match=r"^s\.toml: \[controller\.composite\] sigma = 1\.0: .*dt = 0\.05 s"):
        prepare(sc)


def test_a_loop_rate_that_disagrees_with_dt_control_s_is_refused():
    with pytest.raises(ConfigError, match=r"^s\.toml: \[controller\] loop_rate_hz = 250: .*dt_control_s"):
        scenario_from_mapping({**BASE, "dt_control_s": 0.05, "controller": {"loop_rate_hz": 250.0}}, "s.toml")
    agree = scenario_from_mapping({**BASE, "dt_control_s": 0.01, "controller": {"loop_rate_hz": 100.0}}, "s.toml")
    assert agree.controller.loop_rate_hz == 100.0
    # a scenario changed in Python after loading is checked when the run is set up
    with pytest.raises(ConfigError, match=r"loop_rate_hz = 100: .*1/dt_control_s = 50 Hz"):
        prepare(agree.replace(dt_control_s=0.02))


def test_a_comparison_checks_every_law_it_flies():
    data = {**BASE, "dt_control_s": 0.01, "experiment": {"kind": "comparison"},
            "controller": {"l1": {"predictor_pole_radps": 60.0}}}
    with pytest.raises(ConfigError, match=r"^s\.toml: \[controller\.l1\] predictor_pole_radps = 60\.0"):
        scenario_from_mapping(data, "s.toml")


@pytest.mark.parametrize("name", ["paper_comparison", "paper_convergence", "convergence_full_fan", "gym_hold"])
def test_the_paper_scenarios_controller_is_unchanged_bit_for_bit(name):
    """dt 0.004 s gives 250 Hz exactly, the old default: the same config, the same kernel parameters."""
    sc = load_scenario(name)
    assert sc.dt_control_s == 0.004 and sc.controller.loop_rate_hz == 250.0
    assert sc.controller == dataclasses.replace(sc.controller, loop_rate_hz=ControllerConfig().loop_rate_hz)
    assert prepare(sc.replace(duration_s=0.004)).controller_params[P_DT_NOMINAL] == 0.004


# --- 3-5. what step and set_state hand the kernel ----------------------------------------------------

@pytest.fixture(scope="module")
def ctrl(caltech):
    return Controller(caltech, ControllerConfig())


def test_step_refuses_a_reference_as_the_measurement(ctrl):
    ctrl.reset()
    ref = Reference.hold((0, 0, -1.5))
    for args in ((ref, ref), (_hover(), _hover()), (_hover().array, ref), (None, ref)):
        with pytest.raises(TypeError, match=r"^step: (measurement|reference) must be a"):
            ctrl.step(0.0, *args)
    assert ctrl.get_state().t_last is None


def test_a_non_finite_time_is_refused_and_the_previous_time_kept(ctrl):
    ctrl.reset()
    m, r = _hover(), Reference.hold((0, 0, -1.5))
    for t in (math.nan, math.inf, -math.inf, "0.0", None):
        with pytest.raises(ValueError, match=r"^step: t = .*: must be a finite time in s"):
            ctrl.step(t, m, r)
    assert ctrl.get_state().t_last is None
    first = ctrl.step(0.0, m, r)
    with pytest.raises(ValueError, match=r"previous step at t = 0\.0"):
        ctrl.step(math.nan, m, r)
    second = ctrl.step(np.float64(0.004), m, r)   # not locked
    assert 0.5 < first.u_z < 0.7 and 0.5 < second.u_z < 0.7
    assert ctrl.get_state().t_last == 0.004 and type(ctrl.get_state().t_last) is float


def test_set_state_refuses_non_finite_snapshots_and_keeps_its_own(ctrl):
    ctrl.reset()
    m, r = _hover(), Reference.hold((0, 0, -1.5))
    ctrl.step(0.0, m, r)
    good = ctrl.get_state()
    bad_state = good.state.copy()
    bad_state[7] = np.nan
    for snap, err in ((ControllerSnapshot(np.full_like(good.state, np.nan), None), r"state\[0\] = nan"),
                      (ControllerSnapshot(bad_state, 0.0), r"state\[7\] = nan"),
                      (ControllerSnapshot(good.state, math.nan), r"t_last = nan"),
                      (ControllerSnapshot(good.state[:-1], 0.0), r"shape"),
                      (good.state, r"expected a ControllerSnapshot")):
        with pytest.raises((ValueError, TypeError), match=err):
            ctrl.set_state(snap)
    after = ctrl.get_state()
    np.testing.assert_array_equal(after.state, good.state)
    assert after.t_last == good.t_last
    cmd = ctrl.step(0.004, m, r)
    assert np.all(np.isfinite(cmd.array)) and cmd.u_z > 0.5


def test_controller_refuses_a_vehicle_of_the_wrong_type():
    with pytest.raises(TypeError, match="vehicle must be a vtoladapt Vehicle"):
        Controller("caltech_vtol", ControllerConfig())


# --- the mixer's checked entry points ----------------------------------------------------------------

from vtoladapt.sim.allocation import ALLOC_WORK_SIZE, allocate  # noqa: E402


def test_motor_commands_match_the_compiled_mixer(caltech, ctrl):
    ctrl.reset()
    cmd = ctrl.step(0.0, _hover(), Reference.hold((0, 0, -1.5)))
    cmd.tau_B = (0.05, -0.1, 0.02)
    p = mixer.mixer_params(caltech)
    out = np.zeros(L.N_ACTUATORS)
    sat = allocate(cmd.array, np.zeros(L.MEAS_SIZE), p, out, np.zeros(ALLOC_WORK_SIZE), 0)
    for given_mixer in (caltech, p):
        motors, saturated = mixer.motor_commands(cmd, given_mixer)
        np.testing.assert_array_equal(motors, out)
        assert saturated == sat
    np.testing.assert_array_equal(mixer.motor_commands(list(cmd.array), p)[0], out)
    # sqrt(mean u_i^2) by hand
    assert mixer.lift_collective(out) == pytest.approx(math.sqrt(np.mean(out[:4] ** 2)), rel=1e-15)
    assert mixer.lift_collective(list(out[:4])) == mixer.lift_collective(out)
    assert mixer.lift_collective(out[:L.N_MOTORS]) == mixer.lift_collective(out)


@pytest.mark.parametrize("call, err", [
    (lambda p: mixer.lift_collective(np.array([0.5, 0.5])), r"motor_cmd: has shape \(2,\)"),
    (lambda p: mixer.lift_collective([0.5, 0.5, np.nan, 0.5, 0.0]), r"motor_cmd\[2\] = nan"),
    (lambda p: mixer.lift_collective([0.5, 0.5, 1.5, 0.5, 0.0]), r"motor_cmd\[2\] = 1\.5: out of range"),
    (lambda p: mixer.lift_collective("abc"), r"motor_cmd"),
    (lambda p: mixer.motor_commands(np.zeros(3), p), r"command: has shape \(3,\)"),
    (lambda p: mixer.motor_commands(Command(np.array([0.1, np.inf, 0.0, 0.0, 0.0])), p), r"command\[1\] = inf"),
    (lambda p: mixer.motor_commands(Command(), np.zeros(3)), r"mixer params: has shape"),
    (lambda p: mixer.motor_commands(Command(), np.zeros_like(p)), r"not from mixer_params"),
])
def test_the_checked_mixer_refuses_what_the_kernel_would_misread(caltech, call, err):
    with pytest.raises((TypeError, ValueError), match=err):
        call(mixer.mixer_params(caltech))


# --- 6. identifiability ------------------------------------------------------------------------------

@pytest.mark.parametrize("S, T, err", [
    (np.eye(8), 0.0, "adapt_time_s = 0.0"), (np.eye(8), -5.0, "adapt_time_s = -5.0"),
    (np.eye(8), math.nan, "adapt_time_s = nan"), (np.eye(8), math.inf, "adapt_time_s = inf"),
    (np.eye(7), 1.0, r"shape \(7, 7\)"), (np.full((8, 8), np.nan), 1.0, "finite and symmetric"),
    (np.triu(np.ones((8, 8))), 1.0, "finite and symmetric"),
])
def test_identifiability_refuses_what_has_no_spectrum(caltech, S, T, err):
    with pytest.raises(ValueError, match=err):
        identifiability(S, caltech.theta_scaled, T)


def test_identifiability_of_a_known_sum(caltech):
    """S = T diag(mu / theta_0^2) has sensitivities sqrt(mu), independent of T."""
    th0 = caltech.theta_scaled
    mu = np.array([4.0, 0.25, 9.0, 0.0, 1.0, 0.5, 2.25, 0.01])
    for T in (0.5, 30.0):
        out = identifiability(np.diag(T * mu / th0 ** 2), th0, T)
        np.testing.assert_allclose([d["sensitivity_mps2"] for d in out["directions"]],
                                   np.sqrt(np.sort(mu)[::-1]), rtol=1e-12, atol=1e-12)
        assert out["n_determined"] == int(np.sum(np.sqrt(mu) >= out["threshold_sensitivity_mps2"]))


# --- 7. messages name the file and the key set wrong -------------------------------------------------

def test_law_rules_name_the_file_and_both_keys():
    with pytest.raises(ConfigError,
                       match=r"^s\.toml: \[controller\.l1\] predictor_pole_radps = 125\.0: .*loop_rate_hz"):
        scenario_from_mapping({**BASE, "controller": {"kind": "l1", "l1": {"predictor_pole_radps": 125.0}}}, "s.toml")
    with pytest.raises(ConfigError, match=r"^s\.toml: \[controller\] lowpass_cutoff_hz = 1\.0: .*K_v"):
        scenario_from_mapping({**BASE, "controller": {"kind": "indi", "lowpass_cutoff_hz": 1.0}}, "s.toml")
    # an impossible rate is the rate's fault, not the untouched sigma's
    with pytest.raises(ConfigError, match=r"^s\.toml: \[controller\] loop_rate_hz = 1e-09: out of range"):
        scenario_from_mapping({**BASE, "controller": {"loop_rate_hz": 1e-9}}, "s.toml")


def test_a_table_without_keys_says_so():
    with pytest.raises(ConfigError,
                       match=r"^s\.toml: \[controller\.nominal\] x = 1: unknown key; this table takes no keys$"):
        scenario_from_mapping({**BASE, "controller": {"nominal": {"x": 1}}}, "s.toml")


# --- 8. the README's snippets run --------------------------------------------------------------------

def _section_snippets() -> list[str]:
    text = README.read_text(encoding="utf-8")
    start = text.index("## Using the controller in your own loop")
    # "Adding a controller" is the recipe tests/test_readme_extensions.py runs (it registers a law)
    end = text.index("\n### Adding a controller", start + 1)
    blocks = re.findall(r"```python\n(.*?)```", text[start:end], flags=re.S)
    # excerpts of the package's own files (they start with their path) are shown, not run
    return [b for b in blocks if not b.lstrip().startswith("# src/")]


def test_the_controller_sections_python_snippets_run(capsys):
    snippets = _section_snippets()
    assert len(snippets) >= 2
    for code in snippets:
        exec(compile(code, "README.md", "exec"), {"__name__": "readme_snippet"})
    out = capsys.readouterr().out
    assert "theta-hat:" in out and "predictor_pole_radps = 200.0" in out


def test_a_scenarios_controller_table_loaded_alone_takes_its_rate(tmp_path):
    from vtoladapt.control import load_controller_config

    path = tmp_path / "s.toml"
    path.write_text('dt_control_s = 0.01\n[controller]\nkind = "l1"\n')
    assert load_controller_config(path).loop_rate_hz == 100.0
    path.write_text('dt_control_s = 0.05\n[controller]\nkind = "l1"\n[controller.l1]\npredictor_pole_radps = 100.0\n')
    with pytest.raises(ConfigError, match=r"s\.toml: \[controller\.l1\] predictor_pole_radps = 100\.0: .*here 5 "):
        load_controller_config(path)
    path.write_text('dt_control_s = 0.05\n[controller]\nloop_rate_hz = 250.0\n')
    with pytest.raises(ConfigError, match=r"s\.toml: \[controller\] loop_rate_hz = 250: .*= 20 Hz"):
        load_controller_config(path)
    # no dt_control_s: the scenario's default 4 ms, as the scenario loader takes it
    path.write_text('[controller]\nloop_rate_hz = 100.0\n')
    with pytest.raises(ConfigError, match=r"s\.toml: \[controller\] loop_rate_hz = 100: .*= 250 Hz"):
        load_controller_config(path)
    with pytest.raises(ConfigError, match=r"loop_rate_hz = 100: .*= 250 Hz"):
        scenario_from_mapping({**BASE, "controller": {"loop_rate_hz": 100.0}}, "s.toml")
