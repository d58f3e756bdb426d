"""``make test``'s two processes take each test module whole (tests/conftest.py groups them under xdist's
``--dist loadgroup``), so a module's fixtures, the documentation site's build among them, are computed once."""
import pytest


def test_under_loadgroup_this_test_carries_its_modules_group(request):
    if not getattr(request.config.option, "loadgroup", False):
        pytest.skip("meaningful only in make test's processes (pytest-xdist --dist loadgroup)")
    group = request.node.module.__name__
    # xdist's scheduler sends tests by the "@group" suffix of their node ids; without it every test is scheduled
    # alone (pytest 9.2 with pytest-xdist 3.8: the suffix is written where pytest no longer reads it)
    assert request.node.nodeid.endswith("@" + group), request.node.nodeid
