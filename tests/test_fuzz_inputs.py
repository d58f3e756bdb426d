"""Fuzzers: mutated scenario and vehicle files, force-balance CSVs, JSON side files, calibration
and posterior files, and NASA PCF files.

Each case must end in one of two ways: a clean error (a ``ConfigError``, whose message is one
line naming the file) or acceptance; an accepted scenario flies a short run whose true state and
commands stay finite. Anything else (another exception, a hang, a message without the file name)
fails and Hypothesis shrinks it to a minimal input.

The default run draws about two thousand cases (about a minute on two cores once the kernels
are compiled). Scale them with
``VTOLADAPT_FUZZ_SCALE`` (e.g. 10 for a long night); the draws are derandomised, so a run is
reproducible and CI does not flake.
"""
from __future__ import annotations

import copy
import dataclasses
import json
import math
import os
import tomllib
import typing
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import REPO_DATA_DIR
from vtoladapt.config import ConfigError
from vtoladapt.sim.scenario import SCENARIO_DIR, Scenario, scenario_from_mapping
from vtoladapt.vehicle import VEHICLE_DIR, Vehicle, vehicle_from_mapping

SCALE = float(os.environ.get("VTOLADAPT_FUZZ_SCALE", "1"))


class Text(str):
    """A base document for the mutators, shown by its length only in failure reports."""

    def __repr__(self) -> str:
        return f"<{len(self)} characters>"


def fuzz_settings(n: int):
    return settings(max_examples=max(1, int(n * SCALE)), derandomize=True, deadline=None,
                    suppress_health_check=list(HealthCheck), database=None)


def assert_clean(exc: BaseException, source: str) -> None:
    """A clean error: the project's error type, one non-empty line naming the file."""
    assert isinstance(exc, ConfigError), f"{type(exc).__name__}: {exc}"
    text = str(exc)
    assert text and "\n" not in text, repr(text)
    assert source in text, f"the message does not name {source!r}: {text}"


# --- values and mutations --------------------------------------------------------------------------------
EDGE_FLOATS = st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 1e-9, 1.0, -1.0, 1e9, -1e9, 1e300,
                               -1e300, math.inf, -math.inf, math.nan, 3600.0, 0.004])
NUMBERS = st.one_of(EDGE_FLOATS, st.floats(allow_nan=True, allow_infinity=True),
                    st.integers(-2**70, 2**70), st.integers(-5, 5))
SCALARS = st.one_of(NUMBERS, st.booleans(), st.text(max_size=12),
                    st.sampled_from(["", "\x00", "a\x00b", "x" * 300, "composite", "pid", "hold",
                                     "../../x", "nan"]))
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                       st.dictionaries(st.text(max_size=6), inner,
                                                                       max_size=3)),
                      max_leaves=8)


def _settings_tree(cls: type, prefix: tuple = ()) -> dict[tuple, type]:
    """(section path) -> settings class, for every table a file of ``cls`` may hold."""
    out = {prefix: cls}
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        inner = args[0] if args and typing.get_origin(tp) is not tuple else tp
        if dataclasses.is_dataclass(inner):
            out.update(_settings_tree(inner, prefix + (f.name,)))
    return out


def _set(mapping: dict, path: tuple, key: str, value) -> dict:
    node = mapping
    for p in path:
        nxt = node.get(p)
        if not isinstance(nxt, dict):
            nxt = {}
            node[p] = nxt
        node = nxt
    node[key] = value
    return mapping


def _leaf_paths(mapping, prefix=()):
    for k, v in mapping.items():
        yield prefix + (k,)
        if isinstance(v, dict):
            yield from _leaf_paths(v, prefix + (k,))


@st.composite
def mutated_mapping(draw, base: dict, cls: type, numeric_only: bool = False):
    """``base`` with one to three edits: a known key set to a random value, a key deleted or
    replaced, or an unknown key added."""
    tree = _settings_tree(cls)
    # a table without settings (e.g. [controller.nominal]) has no key to set
    sections = sorted((p for p in tree if dataclasses.fields(tree[p])), key=lambda p: ".".join(p))
    mapping = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["set_known", "set_known", "set_known", "delete", "replace",
                                   "unknown"]))
        if op == "set_known" or numeric_only:
            path = draw(st.sampled_from(sections))
            fields = [f.name for f in dataclasses.fields(tree[path])]
            key = draw(st.sampled_from(fields))
            value = draw(NUMBERS if numeric_only else VALUES)
            _set(mapping, path, key, value)
        elif op == "delete":
            leaves = list(_leaf_paths(mapping))
            if leaves:
                leaf = draw(st.sampled_from(leaves))
                node = mapping
                for p in leaf[:-1]:
                    node = node[p]
                node.pop(leaf[-1], None)
        elif op == "replace":
            leaves = list(_leaf_paths(mapping))
            if leaves:
                leaf = draw(st.sampled_from(leaves))
                _set(mapping, leaf[:-1], leaf[-1], draw(VALUES))
        else:
            _set(mapping, (), draw(st.text(min_size=1, max_size=8)), draw(VALUES))
    return mapping


@st.composite
def mutated_text(draw, text: str):
    """``text`` with a few byte-level edits (delete, insert, duplicate or swap lines, truncate)."""
    data = bytearray(text.encode("utf-8"))
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["delete", "insert", "flip", "truncate", "dup_line", "token"]))
        n = len(data)
        i = draw(st.integers(0, max(0, n - 1)))
        if op == "delete" and n:
            del data[i:i + draw(st.integers(1, 8))]
        elif op == "insert":
            data[i:i] = draw(st.binary(min_size=1, max_size=6))
        elif op == "flip" and n:
            data[i] = draw(st.integers(0, 255))
        elif op == "truncate":
            del data[i:]
        elif op == "dup_line":
            lines = bytes(data).split(b"\n")
            j = draw(st.integers(0, len(lines) - 1))
            lines.insert(j, lines[j])
            data = bytearray(b"\n".join(lines))
        else:
            token = draw(st.sampled_from([b"nan", b"inf", b"-inf", b"1e999", b"-1e999", b"", b",",
                                          b"\t", b"0", b"-0", b"1e-320", b"\"", b"[", b"{}",
                                          b"99999999999999999999"]))
            data[i:i] = token
    return bytes(data)


def _write(tmp_path_factory, name: str, payload) -> Path:
    folder = tmp_path_factory.mktemp("fuzz", numbered=True)
    path = folder / name
    if isinstance(payload, bytes):
        path.write_bytes(payload)
    else:
        path.write_text(payload)
    return path


# --- scenario and vehicle files --------------------------------------------------------------------------
BASE_SCENARIO_TEXT = (SCENARIO_DIR / "paper_comparison.toml").read_text()
BASE_SCENARIO = tomllib.loads(BASE_SCENARIO_TEXT)
BASE_VEHICLE_TEXT = (VEHICLE_DIR / "caltech_vtol.toml").read_text()
BASE_VEHICLE = tomllib.loads(BASE_VEHICLE_TEXT)


@fuzz_settings(300)
@given(mapping=mutated_mapping(BASE_SCENARIO, Scenario))
def test_mutated_scenarios_are_accepted_or_refused_cleanly(mapping):
    try:
        scenario_from_mapping(mapping, "fuzz_scenario.toml")
    except Exception as exc:  # noqa: BLE001 - the point: only ConfigError is clean
        assert_clean(exc, "fuzz_scenario.toml")


@fuzz_settings(300)
@given(mapping=mutated_mapping(BASE_VEHICLE, Vehicle))
def test_mutated_vehicles_are_accepted_or_refused_cleanly(mapping):
    try:
        veh = vehicle_from_mapping(mapping, "fuzz_vehicle.toml")
    except Exception as exc:  # noqa: BLE001
        assert_clean(exc, "fuzz_vehicle.toml")
        return
    assert np.all(np.isfinite(veh.theta_scaled)) and math.isfinite(veh.aero_scale_per_m)


@fuzz_settings(300)
@given(data=st.data())
def test_byte_mutated_scenario_and_vehicle_files(tmp_path_factory, data):
    from vtoladapt.sim.scenario import load_scenario
    from vtoladapt.vehicle import load_vehicle

    which = data.draw(st.sampled_from(["scenario", "vehicle"]))
    base = BASE_SCENARIO_TEXT if which == "scenario" else BASE_VEHICLE_TEXT
    path = _write(tmp_path_factory, f"mutated_{which}.toml", data.draw(mutated_text(base)))
    try:
        (load_scenario if which == "scenario" else load_vehicle)(path)
    except Exception as exc:  # noqa: BLE001
        assert_clean(exc, str(path))


STATE_COLUMNS = ("p_N_m", "p_E_m", "p_D_m", "v_N_mps", "v_E_mps", "v_D_mps", "q_w", "q_x", "q_y",
                 "q_z", "omega_x_radps", "omega_y_radps", "omega_z_radps", "cmd_u_x_frac",
                 "cmd_u_z_frac", "cmd_tau_x_Nm", "cmd_tau_y_Nm", "cmd_tau_z_Nm")
PHYSICAL_SECTIONS = ("plant", "wind", "sensors", "initial", "reference")


@st.composite
def in_range_mutation(draw):
    """The paper's single-run scenario with one to three physical keys drawn inside their
    declared ranges (edges included): these must be accepted and fly."""
    mapping = copy.deepcopy(BASE_SCENARIO)
    mapping["experiment"] = {"kind": "single"}
    mapping["duration_s"] = 0.4
    tree = {p: c for p, c in _settings_tree(Scenario).items() if p and p[0] in PHYSICAL_SECTIONS}
    hints_cache = {}
    sections = sorted(tree, key=lambda p: ".".join(p))
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(sections))
        cls = tree[path]
        hints = hints_cache.setdefault(cls, typing.get_type_hints(cls))
        numeric = []
        for f in dataclasses.fields(cls):
            tp = hints[f.name]
            if tp in (float, typing.Optional[float], float | None):
                numeric.append(f)
        if not numeric:
            continue
        f = draw(st.sampled_from(numeric))
        m = f.metadata
        lo = m.get("ge") if m.get("ge") is not None else m.get("gt")
        hi = m.get("le") if m.get("le") is not None else m.get("lt")
        if lo is None or hi is None:
            continue
        value = draw(st.one_of(st.sampled_from([lo, hi]), st.floats(lo, hi)))
        if (m.get("gt") is not None and value <= m["gt"]) or (m.get("lt") is not None and value >= m["lt"]):
            continue
        _set(mapping, path, f.name, value)
    return mapping


@fuzz_settings(8)
@given(mapping=in_range_mutation())
def test_accepted_physical_mutations_fly_with_finite_state(mapping):
    from vtoladapt.sim.driver import simulate

    try:
        scenario = scenario_from_mapping(mapping, "fuzz_run.toml")
    except ConfigError as exc:  # cross-field checks may still refuse a combination
        assert_clean(exc, "fuzz_run.toml")
        return
    result = simulate(scenario)
    block = result.columns_like(STATE_COLUMNS)
    assert np.all(np.isfinite(block)), [c for c, ok in zip(STATE_COLUMNS, np.isfinite(block).all(0))
                                        if not ok]


# --- force-balance CSV and the tunnel side file ----------------------------------------------------------
@pytest.fixture(scope="module")
def tunnel_files(tmp_path_factory):
    from vtoladapt import load_vehicle
    from vtoladapt.fitting.tunnel import make_design, run_virtual_tunnel, write_tunnel_run

    folder = tmp_path_factory.mktemp("tunnel")
    run = run_virtual_tunnel(load_vehicle("caltech_vtol"), np.random.default_rng(0),
                             design=make_design(), seed=0)
    csv_path, side = write_tunnel_run(run, folder / "d.csv")
    lines = csv_path.read_text().splitlines()
    short = "\n".join(lines[:5] + lines[5::40]) + "\n"  # header and a sample of rows: fast
    return Text(short), Text(side.read_text())


@fuzz_settings(400)
@given(data=st.data())
def test_mutated_force_balance_csv(tmp_path_factory, tunnel_files, data):
    from vtoladapt.fitting.data import read_force_balance_csv

    text, _ = tunnel_files
    path = _write(tmp_path_factory, "balance.csv", data.draw(mutated_text(text)))
    try:
        table = read_force_balance_csv(path)
    except Exception as exc:  # noqa: BLE001
        assert_clean(exc, str(path))
        return
    for name in ("airspeed_mps", "alpha_rad", "beta_rad", "throttle_x_pct", "throttle_z_pct",
                 "force_B_N"):
        assert np.all(np.isfinite(getattr(table, name))), name


def _mutate_json(draw, doc):
    """One to three edits of a JSON document: a value replaced, a key deleted or added."""
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, 3))):
        paths = [()]

        def walk(node, prefix):
            if isinstance(node, dict):
                for k, v in node.items():
                    paths.append(prefix + (k,))
                    walk(v, prefix + (k,))
            elif isinstance(node, list):
                for i, v in enumerate(node[:4]):
                    paths.append(prefix + (i,))
                    walk(v, prefix + (i,))

        walk(doc, ())
        path = draw(st.sampled_from(paths))
        value = draw(VALUES)
        if not path:
            if draw(st.booleans()):
                doc = value
            continue
        node = doc
        for p in path[:-1]:
            node = node[p]
        op = draw(st.sampled_from(["set", "set", "delete"]))
        if op == "delete" and isinstance(node, dict):
            node.pop(path[-1], None)
        else:
            node[path[-1]] = value
    return doc


def _json_text(doc) -> str:
    return json.dumps(doc, allow_nan=True)


@fuzz_settings(200)
@given(data=st.data())
def test_mutated_truth_side_file(tmp_path_factory, tunnel_files, data):
    from vtoladapt.fitting.cli import read_truth_checked

    doc = _mutate_json(data.draw, json.loads(tunnel_files[1]))
    path = _write(tmp_path_factory, "d.truth.json", _json_text(doc))
    try:
        info = read_truth_checked(path)
    except Exception as exc:  # noqa: BLE001
        assert_clean(exc, str(path))
        return
    if "theta_table" in info:
        assert np.all(np.isfinite(info["theta_table"]))


# --- calibration, posterior and NASA PCF files -----------------------------------------------------------
@pytest.fixture(scope="module")
def probe_files(tmp_path_factory):
    from vtoladapt.probe import ProbeTip, simulate_calibration_sweep, write_probe_csv
    from vtoladapt.probe.calibration import calibrate, save_calibration

    folder = tmp_path_factory.mktemp("probe")
    data = simulate_calibration_sweep(ProbeTip(), np.random.default_rng(1), n_rings=4, n_test=4)
    cal = save_calibration(folder / "calibration.json", calibrate(data, smoothing=1e-3))
    csv_text = write_probe_csv(folder / "probe.csv", data).read_text()
    pcf_lines = (REPO_DATA_DIR / "nasa-multihole-probe" / "16328-1_M050.csv").read_text().splitlines()
    pcf = "\n".join(pcf_lines[:14] + pcf_lines[14::25]) + "\n"
    return Text(cal.read_text()), Text(pcf), Text(csv_text)


@fuzz_settings(60)
@given(data=st.data())
def test_mutated_calibration_file(tmp_path_factory, probe_files, data):
    from vtoladapt.probe.calibration import load_calibration

    doc = _mutate_json(data.draw, json.loads(probe_files[0]))
    path = _write(tmp_path_factory, "calibration.json", _json_text(doc))
    try:
        load_calibration(path)
    except Exception as exc:  # noqa: BLE001
        assert_clean(exc, str(path))


@pytest.fixture(scope="module")
def posterior_text(tmp_path_factory):
    """A posterior.json of a short fit to virtual-tunnel data (the format ``fit`` writes)."""
    from vtoladapt import load_vehicle
    from vtoladapt.fitting.bayes import SamplerSettings, fit_table1
    from vtoladapt.fitting.posterior import posterior_dict_from_fit, write_posterior
    from vtoladapt.fitting.tunnel import make_design, run_virtual_tunnel

    veh = load_vehicle("caltech_vtol")
    run = run_virtual_tunnel(veh, np.random.default_rng(0), design=make_design(), seed=0)
    fit = fit_table1(run.data, veh, np.random.default_rng(0), settings=SamplerSettings.fast())
    path = write_posterior(tmp_path_factory.mktemp("post") / "posterior.json",
                           posterior_dict_from_fit(fit))
    return Text(path.read_text())


@fuzz_settings(50)
@given(data=st.data())
def test_mutated_posterior_file(tmp_path_factory, posterior_text, data):
    from vtoladapt.fitting.posterior import load_posterior

    doc = _mutate_json(data.draw, json.loads(posterior_text))
    path = _write(tmp_path_factory, "posterior.json", _json_text(doc))
    try:
        post = load_posterior(path)
    except Exception as exc:  # noqa: BLE001
        assert_clean(exc, str(path))
        return
    assert np.all(np.isfinite(post.theta_table))


@fuzz_settings(300)
@given(data=st.data())
def test_mutated_nasa_pcf(tmp_path_factory, probe_files, data):
    from vtoladapt.probe.data import read_probe_data

    path = _write(tmp_path_factory, "probe.pcf", data.draw(mutated_text(probe_files[1])))
    try:
        table = read_probe_data(path, "nasa")
    except Exception as exc:  # noqa: BLE001
        assert_clean(exc, str(path))
        return
    assert np.all(np.isfinite(table.alpha_deg)) and np.all(np.isfinite(table.beta_deg))


@fuzz_settings(200)
@given(data=st.data())
def test_mutated_probe_csv(tmp_path_factory, probe_files, data):
    from vtoladapt.probe.data import read_probe_data

    path = _write(tmp_path_factory, "probe.csv", data.draw(mutated_text(probe_files[2])))
    try:
        table = read_probe_data(path, "csv")
    except Exception as exc:  # noqa: BLE001
        assert_clean(exc, str(path))
        return
    assert np.all(np.isfinite(table.alpha_deg)) and np.all(np.isfinite(table.beta_deg))
