"""The paper's composite adaptive controller and its baselines, one module per control law.

Package map
-----------
* :mod:`.registry`: the one list of controllers (id, label, colour, adaptive or not, law module),
  read at use time (a law registered after import counts);
* :mod:`.laws`: one module per law (:mod:`.laws.composite`, :mod:`.laws.composite_pconst`,
  :mod:`.laws.tracking_only`, :mod:`.laws.pid`, :mod:`.laws.pd`, ...), each with its settings,
  its parameter, state and diagnostics blocks and its compiled update;
* :mod:`.frontend` (dt, sanitised inputs, incident velocity and the wind-estimate fallback,
  tracking errors, the basis's regressor and the filters) and :mod:`.backend` (force limit,
  heading and flow-angle protection, desired attitude, moment, allocation, output guard,
  diagnostics): what every law shares, each a sequence of named stages;
* :mod:`.step`: the compiled step ``controller_step(fns, params, state, meas, ref, dt, cmd, diag)``
  (front end, the law's update, back end), :func:`.step.controller_functions` (the ``fns`` of a
  parameter array), the parameter and state builders, state accessors, the diagnostics' names;
* :mod:`.blocks`: the shared parameter, state and diagnostics blocks, the per-tick block
  :data:`.blocks.TICK` and the layout of one law and one basis (``BlockLayout``);
* the equations: :mod:`.tracking` (eq:wr, eq:f_ctrl, eq:m_ctrl), :mod:`.attitude` (eq:fbar_solve,
  eq:alphad, eq:Rd and the hover blend), :mod:`.allocation` (eq:f_proj), :mod:`.adaptation`
  (eq:prediction_error, eq:th_adapt, eq:P_adapt, projection, Lyapunov function; its n x n linear algebra
  in :mod:`.linalg`, the constant-P step in :mod:`.exact_step`);
* :mod:`.settings`: :class:`ControllerConfig` (``[controller]`` and the ``[controller.<id>]``
  tables; validated when made, in Python as from a file); each law's settings class is exported
  here too (:class:`PIDSettings`, :class:`L1Settings`, ...);
* :mod:`.api`: :class:`Controller` for use in your own loop; :mod:`.trajectory`: references.

The force model the controller adapts is a basis of :mod:`vtoladapt.bases` (``Phi(x) theta``, n
parameters; the paper's eight by default): its regressor is compiled code the step calls, and n
sizes theta-hat, P, the filters, the prior, the scratch and the diagnostics.

One tick
--------
``front_end`` (:mod:`.frontend`: dt check, sanitising, incident velocity, ``p~``, ``v_r``, ``v~``,
the basis's ``Phi`` and the filters ``W``, ``a_m``, the prediction error, and whether adaptation may
run) writes the tick block :data:`.blocks.TICK` -> the law's ``update`` reads it (its estimator, if
any, then the force command ``f_r``, written back into it) -> ``back_end`` (:mod:`.backend`:
``|f_r + g|`` limit, heading, desired attitude, ``omega_d``, moment command, allocation with
theta-hat's physics part and the basis's extra force, output guard, diagnostics).

The control-law interface
-------------------------
A law is a module with these seven names, and two optional ones (:func:`.laws.check_law` checks them):

``Settings``
    A frozen dataclass of the law's own gains, every field declared with
    :func:`vtoladapt.config.setting` (unit and description). It is the scenario table
    ``[controller.<id>]`` and the attribute ``ControllerConfig.<id>``. Gains every law shares
    (``K_v``, ``Lambda_p``, ``Lambda_q``, ``K_omega``, limits, filters) stay in ``[controller]``
    and are read from the shared parameters; a law's field may not repeat one of their names.
    It derives from :class:`vtoladapt.config.Validated` (made in Python, it is checked as the
    table is).
``PARAMS``, ``STATE``, ``DIAG``
    :class:`vtoladapt.layout.BlockLayout` of the law's own parameters, memory and diagnostics
    columns (logged as they are named, units in the names). They are laid after the shared
    blocks, at :data:`.blocks.P_LAW`, :data:`.blocks.S_LAW` and :data:`.blocks.D_LAW`; bind
    absolute offsets with ``law_offsets(PARAMS, P_LAW, "NAME", ...)`` (module constants, frozen
    into the compiled code). The shared offsets (``P_K_V``, ``S_V_PREV``, ``T_V_TILDE``, ...) are in
    :mod:`.blocks`; the blocks sized by the basis (theta-hat, ``P^-1``, ``W``, ``Phi``, the
    prior) are found through ``params`` (``int(params[A_THETA])``, ``int(params[A_N])``, ...).
``fill_params(settings, ctx) -> ndarray``
    Python, once per run: the law's parameter block (``PARAMS.pack(...)``) from its settings and a
    :class:`.laws.LawContext` (the whole config, the vehicle, theta_0, P0, the nominal dt, the
    basis). Raise ``ConfigError`` (a ``ValueError``) naming the setting for a value the law cannot
    fly with this vehicle or prior (the sigma step's P0); a run adds the scenario file to the message.
``check_config(settings, config, source) -> None`` (optional)
    The rules the law's settings meet together with the shared ones (L1's ``a_s dt`` at
    ``config.loop_rate_hz``, INDI's filter against ``K_v``): a ``ConfigError`` starting with
    ``source``. :class:`ControllerConfig` runs it for its ``kind`` whenever it is made (from a file
    or in Python), a scenario for every law it compares.
``TUNABLE`` (optional)
    The law's own gains ``vtoladapt tune`` may search: a tuple of ``(setting, low, high,
    log_scale)``, the setting a key of the law's table (``"K_I[0:2]"`` for components of a tuple,
    ``"controller.<key>"`` for a shared key that is the law's gain and not already among the shared
    gains every law's search includes, :data:`.settings.TUNABLE`); see
    :mod:`vtoladapt.experiments.tuning`. Absent or empty: only the shared gains are searched.
``init_state(params, state) -> None``
    Python, at start and reset: anything the law's memory needs beyond zeros (the shared start
    is theta-hat = theta_init, P^-1 = P0^-1, filters empty; ``state`` is the whole array).
``update(params, state, tick, diag)``
    Compiled, once per tick: a Numba ``cfunc`` of :data:`.laws.UPDATE_SIGNATURE` (decorate it with
    :func:`.laws.law_update`; it must not allocate). ``params``, ``state`` and ``diag`` are the
    whole arrays, ``tick`` the tick block (:data:`.blocks.TICK`, offsets ``T_*``): ``DT`` (s) and
    ``NEW_DT`` (recompute dt-dependent gains), ``MAY_ADAPT`` (the front end allows adapting
    theta-hat now), ``ACCEL_OK`` (the filtered accelerometer is usable, the probe or not), ``FAULTS`` (the front end's ``FAULT_*`` bits of this tick, e.g.
    ``FAULT_VELOCITY``: the velocity is the last good one, held because this tick's was not
    plausible), ``R_WB``, ``V_W``, ``V_R_DOT``, ``V_TILDE``, ``A_D``, the prediction error ``E``
    of theta-hat before any update, ...; the regressor ``Phi`` (3 x n) is at ``state[A_PHI]``. It
    writes the force command ``F_R`` (m/s^2 NED, gravity included), ``ADAPT_ACTIVE`` and
    ``LAW_FAULTS`` (``FAULT_*`` bits) with :func:`.laws.finish`, and its own ``DIAG`` columns. An
    adaptive law updates theta-hat and ``P^-1`` in the shared estimate and writes ``P_diag_*``
    (diag(P0) otherwise).

Adding a law is this module and one :class:`.registry.ControllerInfo`: an entry in
:data:`.registry.CONTROLLERS` for the package's own, ``vtoladapt.components.register("law", info)``
or an entry point (group ``vtoladapt.law``) for a user's. Validation, scenarios, experiments, the
API and the CLI read the registry when they need it; the compiled step receives the law's
``update`` as a first-class function (README "Adding a controller"; ``tests/test_extension_law.py``
flies a law from a module outside the package through ``simulate`` and the Gymnasium environment).

Design notes
------------
* **Dispatch.** The step takes ``fns = (law update, basis regressor)``, Numba first-class
  functions of the two fixed signatures: it is compiled and cached on disk once, whatever law and
  basis fly, and calls them indirectly (a few ns). :func:`.step.controller_functions` gives
  ``fns`` for a parameter array (which holds the law's and the basis's keys, CRC-32 of their ids).
* **The model estimate is shared.** theta-hat and ``P^-1`` live in the shared state because the
  back end allocates the thrusters with theta-hat for every law and the simulator logs the
  Lyapunov function for every law; a law without adaptation leaves them at their start.
"""
from .api import Command, Controller, ControllerSnapshot, ControllerState, Measurement, Reference, controller_arrays
from .settings import ControllerConfig, controller_config_from_mapping, load_controller_config
from .registry import CONTROLLERS as _CONTROLLERS
from .step import (controller_functions, controller_initial_state, controller_params, controller_step,
                   default_theta_bounds, diagnostics_columns)
from .trajectory import Hold, MinJerkWaypoints, PositionReference, VelocityProfile, trajectory_from_reference

# each registered law's settings class under its own name (PIDSettings, L1Settings, ...), from the registry,
# so that a new law needs no line here
_LAW_SETTINGS = {c.settings.__name__: c.settings for c in _CONTROLLERS.values()}
globals().update(_LAW_SETTINGS)

__all__ = sorted(_LAW_SETTINGS) + [
           "Command", "Controller", "ControllerConfig", "controller_functions", "diagnostics_columns",
           "ControllerSnapshot", "ControllerState", "Hold", "Measurement", "MinJerkWaypoints",
           "PositionReference", "Reference", "VelocityProfile", "controller_arrays",
           "controller_config_from_mapping", "controller_initial_state", "controller_params",
           "controller_step", "default_theta_bounds", "load_controller_config",
           "trajectory_from_reference"]
