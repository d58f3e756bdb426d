"""The one registry of controllers: id, label, colour, what kind of law each is, and its module.

Configuration validation (the ``kind`` choices and the ``[controller.<id>]`` tables), scenarios,
experiments, the step API and the CLI read the list of controllers from here and nowhere else,
and always *now* (the functions below, never a tuple frozen at import): a law registered after
import is accepted everywhere. A new control law is one new module (the interface is in
:mod:`vtoladapt.control`) and one :class:`ControllerInfo`: an entry below for the package's own,
``vtoladapt.components.register("law", info)`` or an entry point in the group ``vtoladapt.law``
for a user's. :data:`CONTROLLERS` is the ``"law"`` kind of :mod:`vtoladapt.components`. The
compiled step is handed the law's ``update`` as a first-class function
(:func:`vtoladapt.control.step.controller_functions`), so it needs no list of laws either.
"""
from __future__ import annotations

import zlib
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
    # after the laws of the shipped comparison, so their places (figure styles) do not move
    ControllerInfo("composite_indi", "C. Adapt + INDI", "C8", True, True,
                   "the composite law with INDI's measured residual on top of the adapted model: theta-hat carries "
                   "the model, the increment rejects force outside span(Phi) at the accelerometer's bandwidth",
                   "composite_indi", adapts_theta=True),
), package=f"{__package__}.laws")



def controller_ids() -> tuple[str, ...]:
    """The registered controllers' ids, in registration order (the package's first)."""
    return CONTROLLERS.ids()


def adaptive_ids() -> tuple[str, ...]:
    """The laws that adapt online (theta-hat, or a force estimate as L1 does)."""
    return tuple(k for k, c in CONTROLLERS.items() if c.adaptive)


def composite_ids() -> tuple[str, ...]:
    """The laws whose prediction error is one of the composite metrics."""
    return tuple(k for k, c in CONTROLLERS.items() if c.composite)


def paper_adaptive_ids() -> tuple[str, ...]:
    """The paper's adaptive controllers (I to III), which its comparison claims are about."""
    return tuple(k for k, c in CONTROLLERS.items() if c.adaptive and c.paper)


def paper_baseline_ids() -> tuple[str, ...]:
    """The paper's baselines (IV PID and V PD)."""
    return tuple(k for k, c in CONTROLLERS.items() if not c.adaptive and c.paper)


def theta_adaptive_ids() -> tuple[str, ...]:
    """The laws whose theta-hat moves (L1 adapts a force estimate and holds theta-hat = theta_0): the only
    ones a parameter-convergence experiment can judge."""
    return tuple(k for k, c in CONTROLLERS.items() if c.adapts_theta)


def controller_info(controller_id: str) -> ControllerInfo:
    """The registry entry of ``controller_id``; ``KeyError`` naming the allowed ids otherwise."""
    try:
        return CONTROLLERS[controller_id]
    except KeyError:
        raise KeyError(f"unknown controller {controller_id!r}; allowed: {', '.join(controller_ids())}") from None


def law_key(controller_id: str) -> float:
    """The number a controller's parameter array stores for its law: CRC-32 of the id (exact in a float64),
    so the look-up does not depend on the order in which laws were registered."""
    controller_info(controller_id)
    return float(zlib.crc32(controller_id.encode()))


def law_of_key(key: float) -> ControllerInfo:
    """The registered law whose :func:`law_key` is ``key``; ``KeyError`` otherwise."""
    for info in CONTROLLERS.values():
        if float(zlib.crc32(info.id.encode())) == key:
            return info
    raise KeyError(f"no registered control law has key {key!r} (registered: {', '.join(controller_ids())}); "
                   "was the law that built these parameters unregistered?")


__all__ = ["CONTROLLERS", "ControllerInfo", "adaptive_ids", "composite_ids", "controller_ids", "controller_info",
           "law_key", "law_of_key", "paper_adaptive_ids", "paper_baseline_ids", "theta_adaptive_ids"]
