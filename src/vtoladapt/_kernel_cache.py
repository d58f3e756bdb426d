"""Keep Numba's on-disk kernel cache consistent with the package's source.

Numba rebuilds a cached function only when *its own* file changes. A kernel that calls kernels
in other files (the simulation loop calls the plant, the sensors, the controller...) would keep
running the old callees after they are edited. So at import we hash every source file of the
package and, when the hash differs from the one the cache was built with, delete the package's
cache files: the next run recompiles (about a minute) instead of silently running stale code.
A fresh install has no cache and is unaffected; a read-only install is left alone.
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


def ensure_fresh_kernel_cache(package_dir: Path = PACKAGE_DIR) -> bool:
    """Delete stale Numba cache files of the package; True if any cleaning was done."""
    stamp = package_dir / "__pycache__" / STAMP_NAME
    try:
        digest = source_digest(package_dir)
        if stamp.exists() and stamp.read_text().strip() == digest:
            return False
        for cached in list(package_dir.rglob("__pycache__/*.nbi")) + list(package_dir.rglob("__pycache__/*.nbc")):
            cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest)
        return True
    except OSError:
        return False  # read-only or racing install: leave the cache as it is
