"""A basis's extra columns (after the paper's eight) and the shared front and back end (issue #34, defects 2, 3).

Both tests fly the compiled step on a stand-in aircraft (level, at the setpoint) with the test
basis of ``tests/example_extra_columns.py``: the paper's columns, a constant body-y force ``Fy0``
and a second pusher column ``CTx_extra = u_x^2``, whose weights the test sets.

* **Unseen-flow detector and blind weathervane** (:func:`test_detector_and_weathervane_judge_the_physics_columns`):
  the probe reads "invalid, zero" (its reading at low airspeed and with the flow outside its cone) and
  the accelerometer feels a side force the physics model lacks. With the paper's basis the detector
  calls it an unseen flow and the heading turns against the force. With the test basis and ``Fy0``
  set to exactly that force the full basis explains it (``e = 0``): the decision and the heading must
  still be the paper basis's, tick for tick.
* **Throttle solve** (:func:`test_throttle_solve_converges_with_a_throttle_dependent_extra_column`):
  a forward acceleration is commanded in hover, so the pusher must give ``a_x``. ``CTx_extra = r C_Tx``
  says the pusher gives ``(1 + r)`` times the physics' thrust: the full model's fixed point is
  ``u_x^2 = a_x / ((1 + r) C_Tx)`` (computed here, independently of the controller). Taken at once at
  the last command, the extra force closes a one-tick loop of gain ``-r`` through the allocation: an
  oscillation that decays as ``0.85^k`` at r = 0.85 and never ends at r = 1.5 (the throttle jumps
  between 0 and the physics' answer). The command must settle on the fixed point without alternating.
"""
from __future__ import annotations

import numpy as np
import pytest

import example_extra_columns
from control_helpers import columns, new_diag, step as controller_step
from vtoladapt import components, forces, layout as L, load_vehicle
from vtoladapt.bases import BASES, describe_basis
from vtoladapt.control import ControllerConfig, controller_arrays

TICK_S = 0.004
SIDE_FORCE_MPS2 = 0.8
"""Above the detector's "on" threshold (``unseen_flow_accel_mps2`` = (0.1, 0.2))."""


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle("caltech_vtol")


@pytest.fixture(scope="module")
def registered():
    assert "paper_extra_test" not in BASES
    components.register("basis", example_extra_columns.INFO)
    yield example_extra_columns.INFO
    BASES.unregister("paper_extra_test")


class _StandIn:
    """Level at the setpoint; the accelerometer reads the physics model's force at the last command plus ``d_B``."""

    def __init__(self, vehicle, basis, extra_theta, d_B, a_ref_W=(0.0, 0.0, 0.0), probe_valid=True):
        spec = describe_basis(vehicle, basis)
        init = spec.theta_scaled.copy()
        init[8:] = extra_theta
        # nominal: theta-hat is theta_0 throughout; no motor lag: Phi sees exactly the last command
        self.params, self.state = controller_arrays(
            vehicle, ControllerConfig(kind="nominal", basis=basis, regressor_motor_lag=False), theta_0=init)
        self.vehicle = vehicle
        self.d_B = np.asarray(d_B, dtype=float)
        self.cmd = np.zeros(L.CMD_SIZE)
        self.diag = new_diag(self.params)
        self.cols = columns(self.params)
        self.ref = L.pack_reference((0.0, 0.0, -1.5), a_W=a_ref_W)
        self.probe_valid = probe_valid

    def step(self):
        f = np.zeros(3)
        forces.body_force(np.zeros(3), self.cmd[L.CMD_U_X], self.cmd[L.CMD_U_Z], self.vehicle.theta_scaled,
                          self.vehicle.model_kernel, f)
        m = np.zeros(L.MEAS_SIZE)
        m[L.MEAS_P_W:L.MEAS_P_W + 3] = (0.0, 0.0, -1.5)
        m[L.MEAS_Q_WB] = 1.0
        m[L.MEAS_ACCEL_B:L.MEAS_ACCEL_B + 3] = f + self.d_B
        m[L.MEAS_V_I_VALID] = 1.0 if self.probe_valid else 0.0       # "invalid" but finite: reads zero
        controller_step(self.params, self.state, m, self.ref, TICK_S, self.cmd, self.diag)
        assert np.all(np.isfinite(self.cmd))
        return {k: float(self.diag[self.cols[k]]) for k in ("unseen_flow", "probe_valid_used", "heading_cmd_rad")}


def test_detector_and_weathervane_judge_the_physics_columns(vehicle, registered):
    d_B = (0.0, SIDE_FORCE_MPS2, 0.0)
    runs = {}
    for basis, extra in (("paper", ()), ("paper_extra_test", (SIDE_FORCE_MPS2, 0.0))):
        ac = _StandIn(vehicle, basis, extra, d_B, probe_valid=False)
        runs[basis] = [ac.step() for _ in range(300)]
    paper, extra = runs["paper"], runs["paper_extra_test"]
    # the full test basis explains the side force: its own prediction error is ~0 ...
    assert abs(ac.diag[ac.cols["pred_err_y_mps2"]]) < 1e-9
    # ... the paper's basis calls it an unseen flow, stops trusting the probe and turns against the force
    assert paper[-1]["unseen_flow"] == 1.0 and paper[-1]["probe_valid_used"] == 0.0
    assert paper[-1]["heading_cmd_rad"] < -0.2
    # and so does every basis, tick for tick
    for k in ("unseen_flow", "probe_valid_used"):
        assert [r[k] for r in extra] == [r[k] for r in paper], k
    np.testing.assert_allclose([r["heading_cmd_rad"] for r in extra], [r["heading_cmd_rad"] for r in paper],
                               rtol=0.0, atol=1e-9)


@pytest.mark.parametrize("ratio", (0.85, 1.5))
def test_throttle_solve_converges_with_a_throttle_dependent_extra_column(vehicle, registered, ratio):
    a_x = 1.0
    C_Tx = vehicle.theta_scaled[forces.I_CTX]
    ac = _StandIn(vehicle, "paper_extra_test", (0.0, ratio * C_Tx), np.zeros(3), a_ref_W=(a_x, 0.0, 0.0))
    u2 = []
    for _ in range(500):
        ac.step()
        u2.append(ac.cmd[L.CMD_U_X] ** 2)
    u2 = np.array(u2)
    np.testing.assert_allclose(u2[-50:], a_x / ((1.0 + ratio) * C_Tx), rtol=1e-6)
    # no tick-to-tick oscillation on the way: after the start the changes keep their sign
    d = np.diff(u2[10:])
    d = d[np.abs(d) > 1e-12 * u2[-1]]
    assert np.all(d[:-1] * d[1:] > 0.0), "the throttle alternates tick to tick"
