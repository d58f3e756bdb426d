"""The stale-kernel guard: editing any source clears the package's Numba cache, once."""
from vtoladapt._kernel_cache import STAMP_NAME, ensure_fresh_kernel_cache, source_digest


def test_cache_cleared_when_any_source_changes(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub" / "__pycache__").mkdir(parents=True)
    (pkg / "__pycache__").mkdir()
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    cached = [pkg / "__pycache__" / "a.f-1.py311.nbi", pkg / "sub" / "__pycache__" / "b.g-2.py311.nbc"]
    for c in cached:
        c.write_text("compiled")
    assert ensure_fresh_kernel_cache(pkg)          # no stamp yet: clean and stamp
    assert not any(c.exists() for c in cached)
    for c in cached:
        c.write_text("compiled")
    assert not ensure_fresh_kernel_cache(pkg)      # unchanged source: cache kept
    assert all(c.exists() for c in cached)
    (pkg / "sub" / "b.py").write_text("y = 3\n")   # a callee in another file changes
    assert ensure_fresh_kernel_cache(pkg)
    assert not any(c.exists() for c in cached)
    assert (pkg / "__pycache__" / STAMP_NAME).read_text() == source_digest(pkg)


USER_LAW_MODULE = '''
from vtoladapt import _numba_abi
from numba import types

OFFSET = {offset}  # a layout constant the kernel bakes in, as a user's law reads the package's offsets

def _kernel(x):
    return x + OFFSET


kernel = _numba_abi.c_kernel(types.float64(types.float64), _kernel)
'''


def _load_user_module(path, name, monkeypatch):
    """Import ``path`` as module ``name``, as a user's ``import`` would (a fresh import every call)."""
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, name, module)
    spec.loader.exec_module(module)
    return module


def test_a_users_cached_kernels_are_rebuilt_when_the_package_changes(tmp_path, monkeypatch):
    """A user's kernel cached against one version of the package is not run against another: it
    bakes the package's offsets in, and Numba only watches the user's own file."""
    import ctypes

    import vtoladapt._kernel_cache as kc
    from vtoladapt._numba_abi import kernel_cache_dir

    source = tmp_path / "users_law.py"
    source.write_text(USER_LAW_MODULE.format(offset=1.0))
    module = _load_user_module(source, "users_law", monkeypatch)
    assert ctypes.CFUNCTYPE(ctypes.c_double, ctypes.c_double)(module.kernel.address)(1.0) == 2.0
    cache_dir = kernel_cache_dir(module._kernel)
    cached = sorted(cache_dir.glob("users_law.*.nb[ic]"))
    assert cached, "the kernel was cached"
    stamp = cache_dir / f"users_law.vtoladapt-{kc.STAMP_NAME}"
    assert stamp.read_text() == kc.package_digest()

    # same package: the cache is kept (the file is not recompiled)
    mtimes = [p.stat().st_mtime_ns for p in cached]
    _load_user_module(source, "users_law", monkeypatch)
    assert [p.stat().st_mtime_ns for p in cached] == mtimes

    # another version of the package: the user's cached kernels are deleted before Numba looks
    monkeypatch.setitem(kc._DIGESTS, kc.PACKAGE_DIR, "another version")
    assert kc.ensure_fresh_module_kernels(source, cache_dir)
    assert not list(cache_dir.glob("users_law.*.nb[ic]"))
    assert stamp.read_text() == "another version"
    assert not kc.ensure_fresh_module_kernels(source, cache_dir)  # stamped: done once


def test_the_packages_own_kernels_are_left_to_the_package_guard(tmp_path):
    import vtoladapt._kernel_cache as kc

    own = kc.PACKAGE_DIR / "frames.py"
    assert not kc.ensure_fresh_module_kernels(own, tmp_path)
    assert not list(tmp_path.iterdir())


_SAVER = r'''
import os, pathlib, sys, time
import vtoladapt, numba  # the package makes Numba's disk cache process-safe once Numba is imported
from numba.core import caching
cache_dir, key, go = sys.argv[1:4]
cache_file = caching.IndexDataCacheFile(cache_dir, "kernel", "stamp")
read_index = cache_file._load_index
def read_index_slowly():
    index = read_index()
    time.sleep(0.5)  # widen the window between reading the index and writing it
    return index
cache_file._load_index = read_index_slowly
pathlib.Path(go + "." + key).touch()
while not os.path.exists(go):
    time.sleep(0.01)
cache_file.save(key, ("the code of", key))
'''


def test_two_processes_caching_different_signatures_at_once_keep_both(tmp_path):
    """Two processes saving different signatures of one kernel into a cold cache at the same time
    (the two workers of ``make test`` from a fresh clone): each signature keeps its own code.

    Numba's own save picks the same data file for both (numba/numba#4807): one entry is lost or
    names the other's code, which a later load links with the wrong types."""
    import subprocess
    import sys
    import time

    from numba.core import caching

    go = tmp_path / "go"
    keys = ("signature_a", "signature_b")
    savers = [subprocess.Popen([sys.executable, "-c", _SAVER, str(tmp_path), key, str(go)]) for key in keys]
    deadline = time.monotonic() + 120
    while not all((tmp_path / f"go.{key}").exists() for key in keys):
        assert time.monotonic() < deadline and all(s.poll() is None for s in savers), "a saver did not start"
        time.sleep(0.02)
    go.touch()
    assert [s.wait(timeout=120) for s in savers] == [0, 0]
    cache_file = caching.IndexDataCacheFile(str(tmp_path), "kernel", "stamp")
    assert [cache_file.load(key) for key in keys] == [("the code of", key) for key in keys]
    assert len(list(tmp_path.glob("kernel.*.nbc"))) == 2


def test_the_process_safe_cache_is_installed_whichever_is_imported_first():
    import subprocess
    import sys

    check = ("from numba.core import caching; import sys; "
             "sys.exit(0 if caching.IndexDataCacheFile._vtoladapt_process_safe else 1)")
    for first in ("import vtoladapt; import numba", "import numba; import vtoladapt"):
        assert subprocess.run([sys.executable, "-c", f"{first}; {check}"]).returncode == 0, first
    # importing the package alone does not import Numba (the command line takes over Ctrl-C first)
    assert subprocess.run([sys.executable, "-c", "import sys, vtoladapt; sys.exit('numba' in sys.modules)"]
                          ).returncode == 0
