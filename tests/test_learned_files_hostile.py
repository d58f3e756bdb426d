"""Issue #33's reproducers, each a test: tampered learned-basis files and ``learn-basis`` under hostile input
end with exit 2, one line naming the file (and the member), and nothing written or changed."""
from __future__ import annotations

import json
import os
import time
import zipfile

import numpy as np
import pytest

from vtoladapt.bases.netfile import FEATURES, N_FEATURES, NetFile, read_net, write_net
from vtoladapt.cli import main
from vtoladapt.config import ConfigError
from vtoladapt.vehicle import VEHICLE_DIR

META = {"format": "vtoladapt-learned-basis-1", "features": list(FEATURES), "vehicle": "caltech_vtol",
        "physics": "extended", "draws": []}


def net_arrays(h=3, hidden=(7, 5), seed=1) -> dict:
    rng = np.random.default_rng(seed)
    H1, H2 = hidden
    return dict(x_mean=rng.normal(size=N_FEATURES), x_std=rng.uniform(0.5, 2.0, N_FEATURES),
                W1=rng.normal(size=(H1, N_FEATURES)), b1=rng.normal(size=H1), W2=rng.normal(size=(H2, H1)),
                b2=rng.normal(size=H2), W3=rng.normal(size=(3 * h, H2)), b3=rng.normal(size=3 * h),
                theta_mean=rng.normal(size=h), theta_std=rng.uniform(0.1, 1.0, h))


def save_npz(path, meta=None, meta_text=None, **change):
    """A basis file as np.savez writes it, with arrays or meta keys replaced."""
    arrays = net_arrays()
    arrays.update(change)
    text = meta_text if meta_text is not None else json.dumps({**META, **(meta or {})})
    with open(path, "wb") as fh:
        np.savez(fh, meta=np.array(text), **arrays)
    return path


def folder_state(folder) -> dict:
    """Every file below ``folder``: bytes and modification time (what 'nothing changed' means)."""
    out = {}
    for root, _, files in os.walk(folder):
        for name in files:
            p = os.path.join(root, name)
            st = os.stat(p)
            if not os.path.isfile(p):  # a pipe: opening it would wait for a writer
                out[p] = ("not a file", st.st_mtime_ns)
                continue
            with open(p, "rb") as fh:
                out[p] = (fh.read(), st.st_mtime_ns)
    return out


def refused(argv, capsys, folder) -> str:
    """Run the command: exit 2, one line on stderr, nothing below ``folder`` changed; returns the line."""
    before = folder_state(folder)
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err.strip()
    assert code == 2, (code, err)
    assert len(err.splitlines()) == 1 and "internal error" not in err, err
    assert folder_state(folder) == before
    return err


def vehicle_flying(tmp_path, net_file) -> str:
    path = tmp_path / "v.toml"
    path.write_text((VEHICLE_DIR / "caltech_vtol.toml").read_text()
                    + f'\n[basis_settings.learned]\nfile = "{net_file}"\n')
    return str(path)


# --- the network file ---------------------------------------------------------------------------------
def test_an_npy_under_an_npz_name_is_refused_by_bases_and_run(tmp_path, capsys):
    """Reproducer 1: "TypeError: 'numpy.ndarray' object does not support the context manager protocol"."""
    np.save(tmp_path / "net.npy", np.zeros(3))
    os.replace(tmp_path / "net.npy", tmp_path / "net.npz")
    err = refused(["bases", "--vehicle", vehicle_flying(tmp_path, "net.npz")], capsys, tmp_path)
    assert "net.npz: a single numpy array (.npy), not a learned basis file" in err
    scenario = tmp_path / "s.toml"
    scenario.write_text(f'name = "s"\nvehicle = "{vehicle_flying(tmp_path, "net.npz")}"\nduration_s = 0.2\n'
                        '[controller]\nkind = "composite"\nbasis = "learned"\n')
    err = refused(["run", scenario, "--out", tmp_path / "out", "--quiet"], capsys, tmp_path)
    assert "net.npz: a single numpy array" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("meta, message", [
    ({"features": 5}, r"member meta: features = 5: inputs this version does not compute"),
    ({"features": None}, r"member meta: features = None"),
    ({"vehicle": 5}, r"member meta: vehicle = 5; allowed: text"),
    ({"draws": {"a": 1}}, r"member meta: draws = \{'a': 1\}; allowed: a list"),
    ({"summary": json.loads("[" * 40 + "]" * 40)}, r"member meta: JSON nested more than 32 levels"),
])
def test_bad_meta_types_are_refused_naming_the_member(tmp_path, capsys, meta, message):
    """Reproducer 2: features = 5 or null raised TypeError."""
    path = save_npz(tmp_path / "net.npz", meta)
    with pytest.raises(ConfigError, match=message) as err:
        read_net(path)
    assert str(err.value).startswith(str(path)) and "\n" not in str(err.value)
    refused(["bases", "--vehicle", vehicle_flying(tmp_path, "net.npz")], capsys, tmp_path)


@pytest.mark.parametrize("text", ['{"a": ' + "[" * 100_000 + "]" * 100_000 + "}", "[" * 100_000, "7", "{"])
def test_deep_or_foreign_meta_json_is_a_refusal_not_a_recursion_error(tmp_path, text):
    """Reproducer 2: a deeply nested JSON string raised RecursionError."""
    path = save_npz(tmp_path / "net.npz", meta_text=text)
    with pytest.raises(ConfigError, match=r"net\.npz: member meta") as err:
        read_net(path)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("name, factor", [("theta_mean", 1e300), ("theta_std", 1e300), ("W3", 1e300),
                                          ("x_mean", 1e10), ("x_std", 1e-300), ("b1", -1e6)])
def test_finite_but_absurd_values_are_refused(tmp_path, capsys, name, factor):
    """Reproducer 3: theta_mean x 1e300 passed and the run divided by zero inside the compiled loop."""
    arrays = net_arrays()
    path = save_npz(tmp_path / "net.npz", **{name: arrays[name] * factor})
    with pytest.raises(ConfigError, match=rf"net\.npz: member {name} holds .*; allowed: .* <= "):
        read_net(path)
    err = refused(["bases", "--vehicle", vehicle_flying(tmp_path, "net.npz")], capsys, tmp_path)
    assert f"member {name}" in err


@pytest.mark.parametrize("dtype", ["U3", "complex128", "bool", "int64", "float16", "object"])
def test_arrays_other_than_real_floats_are_refused_naming_file_and_member(tmp_path, dtype):
    """Reproducer 4: a text W1 was refused without the file; complex lost its imaginary part; bool, int, float16
    were accepted. An object array is refused from its header, never unpickled."""
    W1 = net_arrays()["W1"]
    bad = np.array([[{"x": 1}] * N_FEATURES] * 7, dtype=object) if dtype == "object" else (
        np.full(W1.shape, "abc") if dtype == "U3" else (W1 + 1j if dtype == "complex128" else W1.astype(dtype)))
    path = tmp_path / "net.npz"
    with open(path, "wb") as fh:  # np.savez pickles an object array (allow_pickle is its default for writing)
        np.savez(fh, meta=np.array(json.dumps(META)), **{**net_arrays(), "W1": bad})
    with pytest.raises(ConfigError, match=rf"^{path}: member W1: dtype .*; allowed: float64 or float32"):
        read_net(path)


def test_float32_arrays_are_read_as_float64(tmp_path):
    arrays = net_arrays()
    path = save_npz(tmp_path / "net.npz", W2=arrays["W2"].astype(np.float32))
    net = read_net(path)
    assert net.W2.dtype == np.float64
    np.testing.assert_array_equal(net.W2, arrays["W2"].astype(np.float32).astype(np.float64))


def _bomb_member(zf: zipfile.ZipFile, name: str, header: dict | None, n_bytes: int) -> None:
    """A member of ``n_bytes`` zeros after an optional npy header, deflated (about 1000:1)."""
    with zf.open(name, "w", force_zip64=True) as fh:
        if header is not None:
            np.lib.format.write_array_header_1_0(fh, header)
        chunk = bytes(1 << 22)
        for _ in range(n_bytes // len(chunk)):
            fh.write(chunk)


def test_a_decompression_bomb_is_refused_from_the_zip_directory(tmp_path, monkeypatch):
    """Reproducer 5: an extra 2 GiB member (compressed into a small file) took 35 s and 4 GB and was accepted.
    Here 256 MiB members, in about 260 kB: refused in well under a second, from the directory's sizes alone."""
    extra = save_npz(tmp_path / "extra.npz")
    with zipfile.ZipFile(extra, "a", compression=zipfile.ZIP_DEFLATED) as zf:
        _bomb_member(zf, "padding.npy", None, 256 << 20)
    inside = tmp_path / "inside.npz"
    with zipfile.ZipFile(inside, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, a in net_arrays().items():
            if name != "W2":
                with zf.open(f"{name}.npy", "w") as fh:
                    np.lib.format.write_array(fh, a)
        with zf.open("meta.npy", "w") as fh:
            np.lib.format.write_array(fh, np.array(json.dumps(META)))
        _bomb_member(zf, "W2.npy", {"descr": "<f8", "fortran_order": False, "shape": (5, 7)}, 256 << 20)
    assert os.path.getsize(extra) < 2 << 20 and os.path.getsize(inside) < 2 << 20
    opened = []
    real_open = zipfile.ZipFile.open
    monkeypatch.setattr(zipfile.ZipFile, "open", lambda self, name, *a, **k: opened.append(
        getattr(name, "filename", name)) or real_open(self, name, *a, **k))
    for path, message in ((extra, r"member 'padding\.npy': not a member of a learned basis file"),
                          (inside, r"member W2: 268435584 bytes uncompressed; allowed: at most \d+")):
        opened.clear()
        t0 = time.perf_counter()
        with pytest.raises(ConfigError, match=message):
            read_net(path)
        assert time.perf_counter() - t0 < 1.0
        assert "padding.npy" not in opened and (path == extra or "W2.npy" not in opened), opened


@pytest.mark.parametrize("hidden", [(12000, 5), (7, 2000), (257, 5)])
def test_hidden_widths_are_capped_as_learn_basis_caps_them(tmp_path, hidden):
    """Reproducer 5: 12000 x 12000 was accepted; learn-basis --hidden is capped at 256."""
    path = save_npz(tmp_path / "net.npz", **net_arrays(hidden=hidden))
    with pytest.raises(ConfigError, match=r"net\.npz: member [Wb][12]"):
        read_net(path)


def test_hidden_widths_at_the_cap_are_read(tmp_path):
    path = save_npz(tmp_path / "net.npz", **{k: v * 0.01 for k, v in net_arrays(h=30, hidden=(256, 256)).items()})
    assert read_net(path).hidden == (256, 256) and read_net(path).h == 30


def test_a_w3_not_divisible_by_three_names_w3(tmp_path):
    """Reproducer 13: reported as "x_mean has shape (16,); allowed: (16,)"."""
    path = save_npz(tmp_path / "net.npz", W3=np.ones((8, 5)), b3=np.ones(8))
    with pytest.raises(ConfigError, match=r"member W3 has shape \(8, 5\): 8 rows; allowed: a multiple of 3") as err:
        read_net(path)
    assert "x_mean" not in str(err.value)


@pytest.mark.parametrize("cut", [0, 100, 1000, -22])
def test_a_truncated_archive_is_refused(tmp_path, cut):
    good = save_npz(tmp_path / "good.npz").read_bytes()
    path = tmp_path / "cut.npz"
    path.write_bytes(good[:cut])
    with pytest.raises(ConfigError, match=r"cut\.npz: "):
        read_net(path)


def test_write_net_into_a_missing_folder_names_the_folder_and_leaves_nothing(tmp_path):
    """Reproducer 13: FileNotFoundError naming the .part file."""
    net = NetFile(**net_arrays(), meta=dict(META))
    with pytest.raises(ConfigError, match=r"folder .*missing does not exist") as err:
        write_net(tmp_path / "missing" / "net.npz", net)
    assert ".part" not in str(err.value)
    (tmp_path / "d.npz").mkdir()
    with pytest.raises(ConfigError, match=r"d\.npz: is a folder"):
        write_net(tmp_path / "d.npz", net)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.npz"] and not any((tmp_path / "d.npz").iterdir())


def test_write_net_refuses_what_read_net_would_refuse(tmp_path):
    net = NetFile(**{**net_arrays(), "theta_mean": np.full(3, 1e300)}, meta=dict(META))
    with pytest.raises(ConfigError, match="theta_mean holds 1e"):
        write_net(tmp_path / "n.npz", net)
    assert not list(tmp_path.iterdir())


def test_a_member_twice_is_refused(tmp_path):
    """Which copy counts would be the reader's guess (numpy's np.load takes the last)."""
    path = save_npz(tmp_path / "net.npz")
    with zipfile.ZipFile(path, "a") as zf, zf.open("W1.npy", "w") as fh:
        np.lib.format.write_array(fh, np.zeros((7, N_FEATURES)))
    with pytest.raises(ConfigError, match=r"net\.npz: member 'W1\.npy' twice"):
        read_net(path)
