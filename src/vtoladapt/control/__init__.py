"""The paper's composite adaptive controller and its baselines, one module per control law.

Package map
-----------
* :mod:`.registry`: the one list of controllers (id, label, colour, adaptive or not, law module);
* :mod:`.laws`: one module per law (:mod:`.laws.composite`, :mod:`.laws.composite_pconst`,
  :mod:`.laws.tracking_only`, :mod:`.laws.pid`, :mod:`.laws.pd`, ...), each with its settings,
  its parameter and state blocks and its compiled update;
* :mod:`.frontend` (sanitised inputs, incident velocity and the wind-estimate fallback, tracking
  errors, regressor and filters) and :mod:`.backend` (desired attitude, moment law, allocation,
  output guard, diagnostics): what every law shares;
* :mod:`.kernel`: the compiled step ``controller_step(params, state, meas, ref, dt, cmd, diag)``
  (front end, the law's update, back end), the parameter and state builders, state accessors;
* :mod:`.layouts`: the shared parameter, state and diagnostics blocks (``BlockLayout``);
* the equations: :mod:`.tracking` (eq:wr, eq:f_ctrl, eq:m_ctrl), :mod:`.attitude` (eq:fbar_solve,
  eq:alphad, eq:Rd and the hover blend), :mod:`.allocation` (eq:f_proj), :mod:`.adaptation`
  (eq:prediction_error, eq:th_adapt, eq:P_adapt, projection, Lyapunov function);
* :mod:`.config`: :class:`ControllerConfig` (``[controller]`` and the ``[controller.<id>]`` tables;
  validated when made, in Python as from a file); each law's settings class is exported here too
  (:class:`PIDSettings`, :class:`L1Settings`, ...);
* :mod:`.api`: :class:`Controller` for use in your own loop; :mod:`.trajectory`: references.

One tick
--------
``front_end`` (:mod:`.frontend`: dt check, sanitising, incident velocity, ``p~``, ``v_r``, ``v~``,
regressor ``Phi`` and the filters ``W``, ``a_m``, and whether adaptation may run) -> the law's
``update`` (its estimator, if any, then the force command ``f_r``) -> ``back_end``
(:mod:`.backend`: ``|f_r + g|`` limit, desired attitude, ``omega_d``, moment command, allocation
with theta-hat, output guard, diagnostics).

The control-law interface
-------------------------
A law is a module with these six names (:func:`.laws.check_law` checks them):

``Settings``
    A frozen dataclass of the law's own gains, every field declared with
    :func:`vtoladapt.config.setting` (unit and description). It is the scenario table
    ``[controller.<id>]`` and the field ``ControllerConfig.<id>``. Gains every law shares
    (``K_v``, ``Lambda_p``, ``Lambda_q``, ``K_omega``, limits, filters) stay in ``[controller]``
    and are read from the shared parameters; a law's field may not repeat one of their names.
    It derives from :class:`vtoladapt.config.Validated` (made in Python, it is checked as the
    table is) and is exported from this package under its class name (``PIDSettings``).
``PARAMS``, ``STATE``
    :class:`vtoladapt.layout.BlockLayout` of the law's own parameters and memory. They are laid
    after the shared blocks, at :data:`.layouts.P_LAW` and :data:`.layouts.S_LAW`; bind absolute
    offsets with ``law_offsets(PARAMS, P_LAW, "NAME", ...)`` (module constants, frozen into the
    compiled code). The shared offsets (``P_K_V``, ``S_THETA``, ``S_V_PREV``, ...) are in
    :mod:`.layouts`.
``fill_params(settings, ctx) -> ndarray``
    Python, once per run: the law's parameter block (``PARAMS.pack(...)``) from its settings and a
    :class:`.laws.LawContext` (the whole config, the vehicle, theta_0, P0, the nominal dt). Raise
    ``ConfigError`` (a ``ValueError``) naming the setting for a value the law cannot fly with this
    vehicle or prior (the sigma step's P0); a run adds the scenario file to the message.
``check_config(settings, config, source) -> None`` (optional)
    The rules the law's settings meet together with the shared ones (L1's ``a_s dt`` at
    ``config.loop_rate_hz``, INDI's filter against ``K_v``): a ``ConfigError`` starting with
    ``source``. :class:`ControllerConfig` runs it for its ``kind`` whenever it is made (from a file
    or in Python), a scenario for every law it compares.
``TUNABLE`` (optional)
    The law's own gains ``vtoladapt tune`` may search: a tuple of ``(setting, low, high,
    log_scale)``, the setting a key of the law's table (``"K_I[0:2]"`` for components of a tuple,
    ``"controller.<key>"`` for a shared key that is the law's gain and not already among the shared
    gains every law's search includes, :data:`.config.TUNABLE`); see
    :mod:`vtoladapt.experiments.tuning`. Absent or empty: only the shared gains are searched.
``init_state(params, state) -> None``
    Python, at start and reset: anything the law's memory needs beyond zeros (the shared start
    is theta-hat = theta_init, P^-1 = P0^-1, filters empty; ``state`` is the whole array).
``update(params, state, diag, dt, new_dt, may_adapt, Phi, R, v_W, v_r_dot, v_tilde, a_d)``
    Compiled (``@njit(cache=True)``), once per tick. ``dt`` (s) is the tick and ``new_dt`` says
    it changed (recompute dt-dependent gains); ``may_adapt``: the front end allows adapting
    theta-hat now; ``Phi`` the regressor (three rows of 8), ``R`` ``R_WB`` (three rows of 3),
    ``v_W`` velocity, ``v_r_dot`` the reference velocity's derivative, ``v_tilde`` the limited
    velocity error, ``a_d`` the desired acceleration (3-tuples, NED, SI). Returns
    ``(f_r, e, adapt_active, faults)``: the force command ``f_r`` (m/s^2 NED, gravity included,
    a 3-tuple of floats), the prediction error ``e`` of theta-hat before any update (m/s^2 body,
    3-tuple; ``frontend.prediction_error(state)``), whether theta-hat was updated (bool) and
    ``FAULT_*`` bits (int). An adaptive law updates theta-hat and ``P^-1`` in the shared
    estimate block (:data:`.adaptation.MEMORY` at ``S_ESTIMATE``). It may write the law-owned
    diagnostics ``P_diag_*``, ``projection_active_bounds`` and ``integrator_*``, which hold
    diag(P0), 0 and 0 otherwise. When ``update`` runs, ``diag``'s ``fault_flags`` column holds the
    front end's ``FAULT_*`` bits of this tick (e.g. ``FAULT_VELOCITY``: the velocity is the last
    good one, held because this tick's was not plausible); the back end then writes the column.

Adding a law is this module in :mod:`.laws` and one :class:`.registry.ControllerInfo` entry in
:data:`.registry.CONTROLLERS`: validation, scenarios, experiments, the API, the CLI and the
compiled step's dispatch all follow from the registry. ``tests/test_control_example_law.py``
adds a minimal law exactly that way.

Design notes
------------
* **Dispatch.** The compiled step unrolls (``numba.literal_unroll``) a loop over the tuple of the
  registered laws' ``update`` functions and calls the one whose registry index is in ``params``;
  each call is a direct call of that law's compiled code (no function pointer), the tuple is
  built from the registry at import, and the step caches on disk like every kernel
  (:mod:`vtoladapt._kernel_cache` drops the cache when any source file, the registry included,
  changes). The cost is one integer comparison per registered law per tick.
* **The model estimate is shared.** theta-hat and ``P^-1`` live in the shared state because the
  back end allocates the thrusters with theta-hat for every law and the simulator logs the
  Lyapunov function for every law; a law without adaptation leaves them at their start.
"""
from .api import Command, Controller, ControllerSnapshot, ControllerState, Measurement, Reference, controller_arrays
from .config import CONTROLLER_KINDS, ControllerConfig, controller_config_from_mapping, load_controller_config
from .registry import CONTROLLERS as _CONTROLLERS
from .kernel import CONTROLLER_DIAG_COLUMNS, controller_initial_state, controller_params, controller_step, \
    default_theta_bounds
from .trajectory import Hold, MinJerkWaypoints, PositionReference, VelocityProfile, trajectory_from_reference

# each registered law's settings class under its own name (PIDSettings, L1Settings, ...), from the registry,
# so that a new law needs no line here
_LAW_SETTINGS = {c.settings.__name__: c.settings for c in _CONTROLLERS.values()}
globals().update(_LAW_SETTINGS)

__all__ = sorted(_LAW_SETTINGS) + [
           "CONTROLLER_DIAG_COLUMNS", "CONTROLLER_KINDS", "Command", "Controller", "ControllerConfig",
           "ControllerSnapshot", "ControllerState", "Hold", "Measurement", "MinJerkWaypoints",
           "PositionReference", "Reference", "VelocityProfile", "controller_arrays",
           "controller_config_from_mapping", "controller_initial_state", "controller_params",
           "controller_step", "default_theta_bounds", "load_controller_config",
           "trajectory_from_reference"]
