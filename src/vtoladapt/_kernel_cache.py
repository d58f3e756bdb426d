"""Keep Numba's on-disk kernel cache consistent with the package's source.

Numba rebuilds a cached function only when *its own* file changes. A kernel that calls kernels
in other files (the simulation loop calls the plant, the sensors, the controller...) would keep
running the old callees after they are edited. So at import we hash every source file of the
package and, when the hash differs from the one the cache was built with, delete the package's
cache files: the next run recompiles (about a minute) instead of silently running stale code.
A fresh install has no cache and is unaffected; a read-only install is left alone.

A kernel of a file outside the package (a user's law, basis, wind part or sensor channel) reads
the package's layouts and offsets as compile-time constants too, so its cache goes stale the same
way when the package changes: :func:`ensure_fresh_module_kernels` deletes that file's cached kernels
when the package's digest differs from the one they were built with (the compile-once adapter,
:func:`vtoladapt._numba_abi.c_kernel`, calls it before Numba looks in the cache).
"""
from __future__ import annotations

import hashlib
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
STAMP_NAME = "kernel_sources.sha256"


def source_digest(package_dir: Path = PACKAGE_DIR) -> str:
    """SHA-256 over the relative path and bytes of every ``.py`` file of the package."""
    h = hashlib.sha256()
    for path in sorted(package_dir.rglob("*.py")):
        h.update(path.relative_to(package_dir).as_posix().encode())
        h.update(path.read_bytes())
    return h.hexdigest()


_DIGESTS: dict[Path, str] = {}


def is_package_file(source_file: Path, package_dir: Path = PACKAGE_DIR) -> bool:
    """Whether ``source_file`` is one of the package's own (kept by :func:`ensure_fresh_kernel_cache`)."""
    return Path(source_file).resolve().is_relative_to(package_dir)


def package_digest(package_dir: Path = PACKAGE_DIR) -> str:
    """:func:`source_digest` of ``package_dir``, computed once per process."""
    if package_dir not in _DIGESTS:
        _DIGESTS[package_dir] = source_digest(package_dir)
    return _DIGESTS[package_dir]


def ensure_fresh_kernel_cache(package_dir: Path = PACKAGE_DIR) -> bool:
    """Delete stale Numba cache files of the package; True if any cleaning was done."""
    stamp = package_dir / "__pycache__" / STAMP_NAME
    try:
        digest = _DIGESTS[package_dir] = source_digest(package_dir)
        if stamp.exists() and stamp.read_text().strip() == digest:
            return False
        for cached in list(package_dir.rglob("__pycache__/*.nbi")) + list(package_dir.rglob("__pycache__/*.nbc")):
            cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest)
        return True
    except OSError:
        return False  # read-only or racing install: leave the cache as it is


def ensure_fresh_module_kernels(source_file: Path, cache_dir: Path, package_dir: Path = PACKAGE_DIR) -> bool:
    """Delete the cached kernels of ``source_file`` (a module outside the package) in ``cache_dir``
    (where Numba caches them) if they were built against another version of the package's source;
    True if any cleaning was done. A stamp beside them records the package digest they match."""
    source_file, cache_dir = Path(source_file), Path(cache_dir)
    try:
        if is_package_file(source_file, package_dir):
            return False  # ensure_fresh_kernel_cache keeps them
        stamp = cache_dir / f"{source_file.stem}.vtoladapt-{STAMP_NAME}"
        digest = package_digest(package_dir)
        if stamp.exists() and stamp.read_text().strip() == digest:
            return False
        # Numba names a file's cached kernels "<file stem>.<function>-<line>.pyXY.nbi/.nbc"
        for cached in cache_dir.glob(f"{source_file.stem}.*.nb[ic]"):
            cached.unlink(missing_ok=True)
        cache_dir.mkdir(parents=True, exist_ok=True)
        stamp.write_text(digest)
        return True
    except OSError:
        return False  # a read-only folder: Numba cannot cache there either


def when_imported(module_name: str, callback) -> None:
    """Call ``callback()`` once ``module_name`` is imported: now if it is, else right after its import.

    The package makes Numba's disk cache safe for several processes
    (:func:`vtoladapt._numba_abi.make_disk_cache_process_safe`) before any kernel is loaded from it,
    without importing Numba when the package is imported (the command line takes over Ctrl-C first).
    """
    import importlib.abc
    import importlib.util
    import sys

    if module_name in sys.modules:
        callback()
        return

    class _AfterImport(importlib.abc.MetaPathFinder):
        def find_spec(self, fullname, path=None, target=None):
            if fullname != module_name:
                return None
            sys.meta_path.remove(self)
            spec = importlib.util.find_spec(fullname)  # the finders after this one
            if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
                return spec
            exec_module = spec.loader.exec_module

            def exec_then_call(module):
                exec_module(module)
                callback()

            spec.loader.exec_module = exec_then_call
            return spec

    sys.meta_path.insert(0, _AfterImport())
