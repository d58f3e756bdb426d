"""The paper's composite adaptive controller and the four baselines of its comparison.

* :mod:`.tracking` (eq:wr, eq:f_ctrl, eq:m_ctrl), :mod:`.attitude` (eq:fbar_solve, eq:alphad,
  eq:Rd and the hover blend), :mod:`.allocation` (eq:f_proj), :mod:`.adaptation`
  (eq:prediction_error, eq:th_adapt, eq:P_adapt, projection, Lyapunov function);
* :mod:`.kernel`: the compiled step ``controller_step(params, state, meas, ref, dt, cmd, diag)``
  shared by the five controllers, and the array layouts;
* :mod:`.config`: :class:`ControllerConfig` (the ``[controller]`` table);
* :mod:`.api`: :class:`Controller` for use in your own loop;
* :mod:`.trajectory`: position references.
"""
from .api import Command, Controller, ControllerSnapshot, ControllerState, Measurement, Reference, controller_arrays
from .config import CONTROLLER_KINDS, ControllerConfig, controller_config_from_mapping, load_controller_config
from .kernel import CONTROLLER_DIAG_COLUMNS, controller_initial_state, controller_params, controller_step, \
    default_theta_bounds
from .trajectory import Hold, MinJerkWaypoints, PositionReference, VelocityProfile, trajectory_from_reference

__all__ = ["CONTROLLER_DIAG_COLUMNS", "CONTROLLER_KINDS", "Command", "Controller", "ControllerConfig",
           "ControllerSnapshot", "ControllerState", "Hold", "Measurement", "MinJerkWaypoints",
           "PositionReference", "Reference", "VelocityProfile", "controller_arrays",
           "controller_config_from_mapping", "controller_initial_state", "controller_params",
           "controller_step", "default_theta_bounds", "load_controller_config",
           "trajectory_from_reference"]
