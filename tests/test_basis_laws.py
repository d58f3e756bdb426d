"""Every law flies every basis: the shipped laws with the extended and the learned basis, in a side wind
past the wing's stall range (the new columns are excited), logs finite, theta-hat of the basis's size,
the adaptive laws moving the extra weights and the others leaving them at the prior."""
from __future__ import annotations

import numpy as np
import pytest

from vtoladapt import load_vehicle, simulate
from vtoladapt.bases import describe_basis
from vtoladapt.control.registry import controller_ids, theta_adaptive_ids
from vtoladapt.sim.scenario import scenario_from_mapping

SHIPPED = ("composite", "composite_pconst", "tracking_only", "nominal", "pid", "pd", "indi", "l1")


@pytest.fixture(scope="module")
def runs():
    out = {}
    for basis in ("extended", "learned"):
        for kind in SHIPPED:
            out[basis, kind] = simulate(scenario_from_mapping({
                "name": "laws", "vehicle": "caltech_vtol", "duration_s": 6.0, "seed": 3,
                "wind": {"fan_array": {"schedule": [[0.0, 0.0], [1.0, 70.0], [6.0, 70.0]],
                                       "array_bearing_deg": 60.0}},
                "controller": {"kind": kind, "basis": basis}}, "laws"))
    return out


def test_the_shipped_laws_are_the_registry():
    assert set(SHIPPED) <= set(controller_ids())


@pytest.mark.parametrize("basis", ["extended", "learned"])
@pytest.mark.parametrize("kind", SHIPPED)
def test_every_law_flies_the_basis(runs, basis, kind):
    res = runs[basis, kind]
    spec = describe_basis(load_vehicle("caltech_vtol"), basis)
    assert not res.diverged and np.all(np.isfinite(res.data))
    assert res.theta_hat.shape == (len(res), spec.n)
    extra = res.theta_hat[:, 8:]
    moved = np.abs(extra[-1] - spec.theta_scaled[8:]).max()
    if kind in theta_adaptive_ids():
        assert moved > 1e-4, moved
    else:
        assert moved == 0.0
    # the flight stays close to its reference: the basis does not break the loop
    assert np.sqrt(np.mean(np.sum(res.velocity_error_W[500:] ** 2, axis=1))) < 1.0
