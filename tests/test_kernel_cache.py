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
