"""Configuration validation (vtoladapt.config, vehicle files): every bad input names where and why.

Each bad file is the shipped caltech_vtol.toml with ONE textual edit, written to tmp_path, so the
only thing wrong with it is the edit (the unedited copy is checked to load). The ConfigError message
must name the file, the key and the offending value.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from vtoladapt import ConfigError, available_vehicles, load_vehicle
from vtoladapt.config import build, describe, read_toml, setting
from vtoladapt.vehicle import VEHICLE_DIR

SHIPPED_TEXT = (VEHICLE_DIR / "caltech_vtol.toml").read_text()


def write_variant(tmp_path: Path, old: str, new: str, name: str = "variant.toml") -> Path:
    """The shipped caltech_vtol.toml with the single occurrence of ``old`` replaced by ``new``."""
    assert SHIPPED_TEXT.count(old) == 1, f"{old!r} must occur exactly once in the shipped file"
    path = tmp_path / name
    path.write_text(SHIPPED_TEXT.replace(old, new))
    return path


def test_unedited_copy_loads(tmp_path):
    path = write_variant(tmp_path, "mass_kg = 1.70", "mass_kg = 1.70")
    veh = load_vehicle(path)
    assert veh.mass.mass_kg == 1.70
    assert veh.source_path == str(path)


# (edit old -> new, key named in the message, value named in the message, another fragment)
BAD_EDITS = {
    "misspelled key": ("mass_kg = 1.70", "mas_kg = 1.70", "mas_kg", "1.7", "did you mean 'mass_kg'? Allowed keys: "),
    "unknown key, nothing close": ("mass_kg = 1.70", "mass_kg = 1.70\nzzz = 1", "zzz", "1",
                                   "unknown key; allowed keys: "),
    "negative mass": ("mass_kg = 1.70", "mass_kg = -1.70", "mass_kg", "-1.7", ">= 0.1"),
    "zero mass": ("mass_kg = 1.70", "mass_kg = 0.0", "mass_kg", "0.0", ">= 0.1"),
    "nan mass": ("mass_kg = 1.70", "mass_kg = nan", "mass_kg", "nan", "finite"),
    "wrong type": ("mass_kg = 1.70", 'mass_kg = "1.70"', "mass_kg", "'1.70'", "number"),
    "bool for number": ("CL1 = 3.2502", "CL1 = true", "CL1", "True", "number"),
    "list wrong length": ("inertia_kgm2 = [0.055, 0.060, 0.105]", "inertia_kgm2 = [0.055, 0.060]",
                          "inertia_kgm2", "[0.055, 0.06]", "exactly 3"),
    "scalar for list": ("inertia_kgm2 = [0.055, 0.060, 0.105]", "inertia_kgm2 = 0.055",
                        "inertia_kgm2", "0.055", "list"),
    "triangle inequality": ("inertia_kgm2 = [0.055, 0.060, 0.105]",
                            "inertia_kgm2 = [0.055, 0.060, 0.200]", "inertia_kgm2",
                            "[0.055, 0.06, 0.2]", "triangle"),
    "rotor spin not +-1": ("lift_rotor_spin = [-1, -1, 1, 1]", "lift_rotor_spin = [-1, -1, 1, 2]",
                           "lift_rotor_spin[3]", "2", "+1 or -1"),
    "rotor spin zero": ("lift_rotor_spin = [-1, -1, 1, 1]", "lift_rotor_spin = [-1, 0, 1, 1]",
                        "lift_rotor_spin[1]", "0", "+1 or -1"),
    "rotor spins unbalanced": ("lift_rotor_spin = [-1, -1, 1, 1]", "lift_rotor_spin = [1, -1, 1, 1]",
                               "lift_rotor_spin", "[1, -1, 1, 1]", "each way"),
    "rotor position not x, y": ("[0.21, 0.26], [-0.21, -0.26]", "[0.21, 0.26, 0.0], [-0.21, -0.26]",
                                "lift_rotor_positions_m[0]", "[0.21, 0.26, 0.0]", "[x, y]"),
    "P0 wrong length": ("P0_diag = [200.0, 200.0, 0.1, 1.0, 5.0, 20.0, 0.1, 0.1]",
                        "P0_diag = [200.0, 200.0, 0.1, 1.0, 5.0, 20.0, 0.1]", "P0_diag",
                        "[200.0, 200.0, 0.1, 1.0, 5.0, 20.0, 0.1]", "exactly 8"),
    "P0 negative element": ("P0_diag = [200.0, 200.0, 0.1, 1.0, 5.0, 20.0, 0.1, 0.1]",
                            "P0_diag = [200.0, -200.0, 0.1, 1.0, 5.0, 20.0, 0.1, 0.1]",
                            "P0_diag[1]", "-200.0", "> 0"),
    "k1 out of range": ("k1 = 1.425", "k1 = 2.5", "k1", "2.5", "< 2"),
    "throttle above 100": ("throttle_max_pct = 100.0", "throttle_max_pct = 120.0",
                           "throttle_max_pct", "120.0", "<= 100"),
    "blend speeds reversed": ("hover_blend_airspeed_mps = [2.0, 4.0]",
                              "hover_blend_airspeed_mps = [4.0, 2.0]", "hover_blend_airspeed_mps",
                              "[4.0, 2.0]", "below"),
    "misspelled section": ("[envelope]", "[envelop]", "envelop", "alpha_max_deg",
                           "did you mean 'envelope'"),
}


@pytest.mark.parametrize("case", list(BAD_EDITS), ids=list(BAD_EDITS))
def test_bad_vehicle_file_names_file_key_and_value(tmp_path, case):
    old, new, key, value, fragment = BAD_EDITS[case]
    path = write_variant(tmp_path, old, new)
    with pytest.raises(ConfigError) as info:
        load_vehicle(path)
    msg = str(info.value)
    assert str(path) in msg, msg
    assert key in msg, msg
    assert value in msg, msg
    assert fragment in msg, msg


@pytest.mark.parametrize("old, key, section", [
    ("CTz = 2.87e-3\n", "CTz", "[force_model]"),
    ("mass_kg = 1.70", "mass_kg", "[mass]"),
    ('name = "caltech_vtol"\n', "name", ""),
])
def test_missing_field_names_file_section_and_key(tmp_path, old, key, section):
    path = write_variant(tmp_path, old, "")
    with pytest.raises(ConfigError, match="missing required key") as info:
        load_vehicle(path)
    msg = str(info.value)
    assert str(path) in msg and f"{section} {key}".strip() in msg, msg


def test_unknown_vehicle_name_lists_the_shipped_ones():
    with pytest.raises(ConfigError) as info:
        load_vehicle("caltek_vtol")
    msg = str(info.value)
    assert "caltek_vtol" in msg
    for name in ("caltech_vtol", "px4_standard_vtol"):
        assert name in msg
    assert {"caltech_vtol", "px4_standard_vtol"} <= set(available_vehicles())


def test_shipped_name_wins_over_a_folder_of_the_same_name(tmp_path, monkeypatch):
    """An output folder called like a vehicle in the working directory is not a vehicle file."""
    (tmp_path / "caltech_vtol").mkdir()
    monkeypatch.chdir(tmp_path)
    assert load_vehicle("caltech_vtol").name == "caltech_vtol"


def test_missing_and_malformed_files_name_the_file(tmp_path):
    missing = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match="file not found") as info:
        load_vehicle(missing)
    assert str(missing) in str(info.value)
    broken = tmp_path / "broken.toml"
    broken.write_text("[mass\nmass_kg = 1.7\n")
    with pytest.raises(ConfigError, match="not valid TOML") as info:
        read_toml(broken)
    assert str(broken) in str(info.value)


# --- config.build on its own (used by every configuration dataclass) ------------------------

@dataclasses.dataclass(frozen=True)
class _Inner:
    gain: float = setting("1/s", "a gain", gt=0.0)


@dataclasses.dataclass(frozen=True)
class _Example:
    rate_hz: float = setting("Hz", "loop rate", gt=0.0, le=1000.0)
    steps: int = setting("-", "step count", ge=1)
    mode: str = setting("-", "mode", choices=("fast", "exact"))
    limits: tuple[float, ...] = setting("m", "limits", ge=0.0, length=2)
    inner: _Inner = setting("-", "inner section")
    enabled: bool = setting("-", "switch", default=True)
    note: str | None = setting("-", "optional note", default=None)


GOOD = {"rate_hz": 250, "steps": 3, "mode": "fast", "limits": [1, 2.5], "inner": {"gain": 2.0}}


def test_build_converts_and_applies_defaults():
    obj = build(_Example, GOOD, source="x.toml")
    assert obj == _Example(250.0, 3, "fast", (1.0, 2.5), _Inner(2.0), True, None)
    assert isinstance(obj.rate_hz, float) and isinstance(obj.limits, tuple)
    with pytest.raises(dataclasses.FrozenInstanceError):
        obj.rate_hz = 1.0  # type: ignore[misc]


@pytest.mark.parametrize("change, fragments", [
    ({"rate_hz": 2000}, ["x.toml", "[sec] rate_hz = 2000", "<= 1000"]),
    ({"rate_hz": math.inf}, ["rate_hz = inf", "finite"]),
    ({"steps": 1.5}, ["steps = 1.5", "whole number"]),
    ({"steps": 0}, ["steps = 0", ">= 1"]),
    ({"mode": "slow"}, ["mode = 'slow'", "'fast', 'exact'"]),
    ({"limits": [1, -2]}, ["limits[1] = -2", ">= 0"]),
    ({"enabled": 1}, ["enabled = 1", "true or false"]),
    ({"inner": {"gain": -1}}, ["[sec.inner] gain = -1", "> 0"]),
    ({"inner": 3}, ["[sec.inner]", "must be a table"]),
    ({"rte_hz": 250}, ["rte_hz = 250", "did you mean 'rate_hz'"]),
])
def test_build_rejects_with_location_and_value(change, fragments):
    with pytest.raises(ConfigError) as info:
        build(_Example, {**GOOD, **change}, source="x.toml", section="sec")
    for fragment in fragments:
        assert fragment in str(info.value), str(info.value)


def test_unknown_key_message_stays_short_for_a_long_value():
    with pytest.raises(ConfigError) as info:
        build(_Example, {**GOOD, "bogus": list(range(1000))}, source="x.toml")
    assert "bogus = [0, 1, 2" in str(info.value) and len(str(info.value)) < 400


def test_describe_lists_unit_range_and_meaning():
    rows = {r[0]: r for r in describe(_Example)}
    assert rows["rate_hz"] == ("rate_hz", "Hz", "> 0 and <= 1000 (Hz)", "loop rate")
    assert rows["mode"][2] == "one of 'fast', 'exact'"


def test_setting_refuses_mutable_default():
    with pytest.raises(TypeError):
        setting("-", "bad", default=[1, 2])
