"""The one registry of controllers: id, label, colour, what kind of law each is, and its module.

Configuration validation (the ``kind`` choices and the ``[controller.<id>]`` tables), scenarios,
experiments, the step API, the compiled step's dispatch and the CLI read the list of controllers
from here and nowhere else. A new control law is one new module in :mod:`vtoladapt.control.laws`
(the interface is in :mod:`vtoladapt.control`) and one entry below. :data:`CONTROLLERS` is the
``"law"`` kind of :mod:`vtoladapt.components` (the package's laws, then those registered by a call
or an entry point).
"""
from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType

from ..components import Registry
from .laws import check_law


@dataclass(frozen=True)
class ControllerInfo:
    """What the rest of the package needs to know about one control law.

    ``adaptive``: it adapts online (theta-hat, or an estimate of the unmodelled force, as L1 does);
    ``adapts_theta``: its theta-hat moves (a parameter-convergence experiment can judge it);
    ``composite``: it predicts the measured specific
    force with an adapted theta-hat (so its prediction error is one of the composite metrics);
    ``label`` and ``colour`` (a Matplotlib colour) are used in every figure and table;
    ``module``: the law's module, relative to :mod:`vtoladapt.control.laws` or absolute;
    ``paper``: its number in the paper's comparison (I to V), empty for laws the paper did not fly.
    """

    id: str
    label: str
    colour: str
    adaptive: bool
    composite: bool
    description: str
    module: str
    paper: str = ""
    adapts_theta: bool = False

    @property
    def law(self) -> ModuleType:
        """The law's module (imported and checked against the law interface on first use)."""
        return CONTROLLERS.module(self.id)

    @property
    def settings(self) -> type:
        """The law's settings dataclass (its ``[controller.<id>]`` table)."""
        return self.law.Settings


CONTROLLERS: Registry = Registry("law", check_law, (
    ControllerInfo("composite", "C. Adapt", "C0", True, True,
                   "the paper's composite adaptive law (eq:th_adapt, eq:P_adapt)", "composite", paper="I",
                   adapts_theta=True),
    ControllerInfo("composite_pconst", "C. Adapt, P const", "C2", True, True,
                   "the composite law with P held at P0 (the paper's controller II)", "composite_pconst", paper="II",
                   adapts_theta=True),
    ControllerInfo("tracking_only", "Tracking-error adapt", "C4", True, False,
                   "adaptation on the tracking error only, theta-hat' = k P0 Phi^T R^T v-tilde with k <= 1 from "
                   "the gain rule (the paper's III has k = 1: gain_rule = \"paper\")",
                   "tracking_only", paper="III", adapts_theta=True),
    ControllerInfo("pid", "PID", "C1", False, False,
                   "PX4-style velocity PID with the same force allocation, theta-hat = theta_0 (IV)", "pid", paper="IV"),
    ControllerInfo("pd", "PD", "C3", False, False,
                   "the PID without its integral (V)", "pd", paper="V"),
    ControllerInfo("nominal", "Nominal (no adapt)", "C7", False, False,
                   "the composite law with adaptation off, theta-hat = theta_0", "nominal"),
    ControllerInfo("indi", "INDI", "C5", False, False,
                   "incremental nonlinear dynamic inversion of the force loop on the filtered accelerometer, "
                   "theta-hat = theta_0 (Smeur et al. 2018)", "indi"),
    ControllerInfo("l1", "L1 adaptive", "C6", True, False,
                   "L1 adaptive control: eq:f_ctrl with theta-hat = theta_0 minus the low-passed estimate of a "
                   "velocity predictor's piecewise-constant adaptation (Hovakimyan & Cao 2010)", "l1"),
), package=f"{__package__}.laws")

CONTROLLER_IDS: tuple[str, ...] = tuple(CONTROLLERS)
ADAPTIVE_IDS: tuple[str, ...] = tuple(k for k, c in CONTROLLERS.items() if c.adaptive)
COMPOSITE_IDS: tuple[str, ...] = tuple(k for k, c in CONTROLLERS.items() if c.composite)
PAPER_ADAPTIVE_IDS: tuple[str, ...] = tuple(k for k, c in CONTROLLERS.items() if c.adaptive and c.paper)
"""The paper's adaptive controllers (I to III), which its comparison claims are about."""
PAPER_BASELINE_IDS: tuple[str, ...] = tuple(k for k, c in CONTROLLERS.items() if not c.adaptive and c.paper)
"""The paper's baselines (IV PID and V PD)."""
THETA_ADAPTIVE_IDS: tuple[str, ...] = tuple(k for k, c in CONTROLLERS.items() if c.adapts_theta)
"""The laws whose theta-hat moves (L1 adapts a force estimate and holds theta-hat = theta_0): the
only ones a parameter-convergence experiment can judge."""


def controller_info(controller_id: str) -> ControllerInfo:
    """The registry entry of ``controller_id``; ``KeyError`` naming the allowed ids otherwise."""
    try:
        return CONTROLLERS[controller_id]
    except KeyError:
        raise KeyError(f"unknown controller {controller_id!r}; allowed: {', '.join(CONTROLLER_IDS)}") from None


def law_index(controller_id: str) -> int:
    """The number the compiled step dispatches on: the law's position in :data:`CONTROLLER_IDS`."""
    controller_info(controller_id)
    return CONTROLLER_IDS.index(controller_id)
