"""The adapter to Numba's internals (:mod:`vtoladapt._numba_abi`) and the part tables built on it
(:mod:`vtoladapt.parts`): each function of the adapter against what it stands for, checked without
it (a C entry point called through ctypes, Numba's own cache index, the LLVM IR), and that no other
module of the package uses a private Numba or llvmlite name.
"""
from __future__ import annotations

import ast
import ctypes
import importlib.util
import sys
import types as pytypes
from pathlib import Path

import numpy as np
import pytest
from numba import cfunc, njit, types

from vtoladapt import _numba_abi, parts

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "src" / "vtoladapt"

ARRAY = types.float64[::1]
PAIR_SIGNATURE = types.void(ARRAY, ARRAY)
"""``f(x, out)``: the signature of the test's kernels."""


def _affine(x, out):
    for i in range(x.size):
        out[i] = 2.0 * x[i] + 1.0


def _ratio(x, out):
    out[0] = x[0] / x[1]


# not cached on disk: a test's kernels are compiled in the test's process
AFFINE = _numba_abi.c_kernel(PAIR_SIGNATURE, _affine, cache=False)
RATIO = _numba_abi.c_kernel(PAIR_SIGNATURE, _ratio, cache=False)
SQUARE_PLUS_ONE = cfunc(types.float64(types.float64))(lambda v: v * v + 1.0)

_load = _numba_abi.function_loader(PAIR_SIGNATURE, 1)  # the address in column 1, column 0 a decoy


@njit(cache=False)
def _call_row(table, j, x, out):
    _load(table, j)(x, out)


def _table(*fns) -> np.ndarray:
    table = np.full((len(fns), 3), -1, dtype=np.int64)  # other columns: values no call may use
    for j, fn in enumerate(fns):
        table[j, 1] = _numba_abi.c_address(fn, PAIR_SIGNATURE)
    return table


# --- the function loader and the C entry points --------------------------------------------------

def test_a_loaded_row_computes_what_its_function_computes():
    x = np.array([0.5, -3.0, 7.25])
    table = _table(RATIO, AFFINE)
    out = np.zeros(3)
    _call_row(table, 1, x, out)
    np.testing.assert_array_equal(out, 2.0 * x + 1.0)  # the Python arithmetic, independently
    out[:] = 0.0
    _call_row(table, 0, x, out)  # the other row, the other function
    assert out[0] == 0.5 / -3.0 and out[1] == 0.0


def test_c_address_is_the_c_entry_point():
    """Called through ctypes, outside Numba, the address computes the kernel's function."""
    address = _numba_abi.c_address(SQUARE_PLUS_ONE, types.float64(types.float64))
    c_fn = ctypes.CFUNCTYPE(ctypes.c_double, ctypes.c_double)(address)
    assert c_fn(3.0) == 10.0 and c_fn(-0.5) == 1.25


@pytest.mark.parametrize("fn", [njit(_affine), _affine, RATIO], ids=["njit", "python", "wrong signature"])
def test_c_address_refuses_anything_but_a_cfunc_of_the_signature(fn):
    signature = types.void(ARRAY, ARRAY, types.float64) if fn is RATIO else PAIR_SIGNATURE
    with pytest.raises(TypeError, match="not a numba cfunc"):
        _numba_abi.c_address(fn, signature)


def test_c_kernels_divide_as_c_does():
    """NumPy's error model: 1/0 is inf in the output, not an exception lost at the C entry point
    (with Python's, the wrapper prints it and the output keeps its old value)."""
    out = np.zeros(1)
    _call_row(_table(RATIO), 0, np.array([1.0, 0.0]), out)
    assert out[0] == np.inf


# --- the signature probe -------------------------------------------------------------------------

def test_the_signature_of_a_cfunc_is_the_one_it_was_compiled_for():
    sig = _numba_abi.signature_of(AFFINE)
    assert tuple(sig.args) == (ARRAY, ARRAY) and sig.return_type == types.void
    assert _numba_abi.is_c_kernel(AFFINE, PAIR_SIGNATURE)
    assert _numba_abi.is_c_kernel(SQUARE_PLUS_ONE, types.float64(types.float64))
    assert not _numba_abi.is_c_kernel(SQUARE_PLUS_ONE, types.float32(types.float64))
    assert not _numba_abi.is_c_kernel(AFFINE, types.void(ARRAY, types.float64[:]))  # not contiguous


@pytest.mark.parametrize("obj", [njit(PAIR_SIGNATURE)(_affine), _affine, 3, None], ids=["njit", "python", "int", "none"])
def test_anything_but_a_cfunc_has_no_signature(obj):
    assert _numba_abi.signature_of(obj) is None
    assert not _numba_abi.is_c_kernel(obj, PAIR_SIGNATURE)


def test_a_part_whose_step_is_not_a_c_kernel_is_refused():
    kind = parts.PartKind("wind", PAIR_SIGNATURE)
    module = pytypes.ModuleType("vtoladapt_test_part")
    module.Settings, module.pack, module.initial_state = None, lambda s, c: np.zeros(0), lambda p, r: np.zeros(0)
    module.PARAMS = module.STATE = parts.BlockLayout("empty", [])
    module.NORMALS_PER_STEP = module.UNIFORMS_PER_STEP = 0
    module.step = kind.kernel(_affine)
    kind.check(module)
    module.step = njit(PAIR_SIGNATURE)(_affine)  # Numba's calling convention only: no longer accepted
    with pytest.raises(TypeError, match="wind_step"):
        kind.check(module)


# --- the disk-cache probe ------------------------------------------------------------------------

def test_the_cache_probe_sees_the_index_numba_writes(tmp_path, monkeypatch):
    """Where Numba puts the index (beside the module, or under NUMBA_CACHE_DIR) is its business: the
    probe is asked before and after the one compilation."""
    source = tmp_path / "abi_cache_probe.py"
    source.write_text("from numba import njit\n\n\n@njit(cache=True)\ndef triple(x):\n    return 3 * x\n")
    spec = importlib.util.spec_from_file_location("abi_cache_probe", source)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "abi_cache_probe", module)
    spec.loader.exec_module(module)
    assert not _numba_abi.has_disk_cache(module.triple)
    assert module.triple(4) == 12  # compiles and writes the index
    assert module.triple.stats.cache_misses  # Numba's own account: it compiled (and saved) it
    assert _numba_abi.has_disk_cache(module.triple)
    assert any(p.suffix == ".nbi" for p in Path(module.triple.stats.cache_path).iterdir())


def test_the_cache_probe_says_cached_when_it_cannot_tell():
    assert _numba_abi.has_disk_cache(object())


# --- the prefetch intrinsic ----------------------------------------------------------------------

@njit(cache=False)
def _sum_with_prefetch(a):
    total = 0.0
    for i in range(a.shape[0]):
        if i + 1 < a.shape[0]:
            for j in range(0, a.shape[1], 8):
                _numba_abi.prefetch(a, i + 1, j)
        for j in range(a.shape[1]):
            total += a[i, j]
    return total


def test_prefetch_compiles_to_llvm_prefetch_and_changes_nothing():
    a = np.random.default_rng(0).standard_normal((6, 20))
    before = a.copy()
    expected = 0.0
    for v in a.ravel():  # the same order of additions, in Python
        expected += v
    assert _sum_with_prefetch(a) == expected
    np.testing.assert_array_equal(a, before)
    (ir,) = _sum_with_prefetch.inspect_llvm().values()
    assert "@llvm.prefetch" in ir


# --- no private Numba name outside the adapter ---------------------------------------------------

PRIVATE_MODULES = ("numba.core", "numba.experimental", "numba.np", "numba.cpython", "numba.misc", "numba.parfors",
                   "llvmlite")
"""Numba's internal packages, and llvmlite (``numba.extending``, ``numba.types``, ``numba.typed`` are public)."""
PRIVATE_ATTRIBUTES = {"_sig", "_cache", "_cache_hits", "_wrapper_address", "_wrapper_name", "_pyfunc", "_compiler",
                      "_library", "_get_jit_address", "_get_wrapper_address", "_can_compile", "_compile_for_args"}
"""Private attributes of Numba's dispatchers and cfuncs the package has used or might."""
ALLOWED_PRIVATE_OPTIONS = {"_nrt"}
"""The one private option of ``numba.jit`` the package passes (see :mod:`vtoladapt._numba_abi`)."""
NUMBA_DECORATORS = {"njit", "jit", "cfunc", "vectorize", "guvectorize", "generated_jit", "intrinsic", "overload",
                    "register_jitable"}


def _is_private_module(name: str) -> bool:
    return any(name == m or name.startswith(m + ".") for m in PRIVATE_MODULES)


def _private_uses(source: str) -> list[str]:
    """What in ``source`` touches a private Numba or llvmlite name, one line each."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [f"{node.lineno}: import {a.name}" for a in node.names if _is_private_module(a.name)]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            mod = node.module
            if _is_private_module(mod):
                found.append(f"{node.lineno}: from {mod} import ...")
            elif mod.split(".")[0] == "numba":
                found += [f"{node.lineno}: from {mod} import {a.name}" for a in node.names if a.name.startswith("_")]
        elif isinstance(node, ast.Attribute):
            if node.attr in PRIVATE_ATTRIBUTES:
                found.append(f"{node.lineno}: .{node.attr}")
            chain = ast.unparse(node)
            if _is_private_module(chain):
                found.append(f"{node.lineno}: {chain}")
        elif isinstance(node, ast.Call):
            name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
            if name in ("getattr", "hasattr", "setattr") and len(node.args) > 1:
                attr = node.args[1]
                if isinstance(attr, ast.Constant) and attr.value in PRIVATE_ATTRIBUTES:
                    found.append(f"{node.lineno}: {name}(..., {attr.value!r})")
            if name in NUMBA_DECORATORS:
                found += [f"{node.lineno}: {name}({k.arg}=...)" for k in node.keywords
                          if k.arg and k.arg.startswith("_") and k.arg not in ALLOWED_PRIVATE_OPTIONS]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.startswith("llvm."):
            found.append(f"{node.lineno}: LLVM intrinsic {node.value!r}")
    return found


def test_the_scan_finds_what_it_looks_for():
    """The check below must be able to fail: every kind of use it looks for, found in a snippet, and
    the adapter's own uses found in the adapter."""
    snippet = ("from numba.experimental.function_type import _get_jit_address\n"
               "from numba.core import cgutils\nimport llvmlite.ir\nfrom numba import _helperlib\n"
               "sig = f._sig\npath = d._cache.cache_path\n@njit(cache=True, _nrt=False, _dbg_optnone=True)\n"
               "def g(): pass\nname = 'llvm.prefetch.p0'\nx = numba.core.types\nsig = getattr(f, '_sig', None)\n")
    found = "\n".join(_private_uses(snippet))
    for expected in ("1: from numba.experimental", "2: from numba.core", "3: import llvmlite.ir",
                     "4: from numba import _helperlib", "5: ._sig", "6: ._cache", "7: njit(_dbg_optnone=...)",
                     "9: LLVM intrinsic", "10: numba.core.types", "11: getattr(..., '_sig')"):
        assert expected in found, (expected, found)
    assert "_nrt" not in found
    adapter = _private_uses((PACKAGE_DIR / "_numba_abi.py").read_text())
    assert any("numba.core" in u for u in adapter) and any("llvmlite" in u for u in adapter)


def test_no_module_but_the_adapter_uses_a_private_numba_name():
    offenders = {}
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        if path.name == "_numba_abi.py":
            continue
        uses = _private_uses(path.read_text())
        if uses:
            offenders[str(path.relative_to(PACKAGE_DIR))] = uses
    assert not offenders, f"private Numba/llvmlite API outside vtoladapt/_numba_abi.py: {offenders}"
