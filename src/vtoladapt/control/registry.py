"""The one registry of controllers: id, label, colour and what kind of law each is.

Configuration validation, scenarios, experiments, the step API and the CLI read the list of
controllers from here and nowhere else. A new control law adds one entry (and its own module).
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ControllerInfo:
    """What the rest of the package needs to know about one control law.

    ``adaptive``: it adapts theta-hat online; ``composite``: it predicts the measured specific force
    (so its prediction error is a metric); ``label`` and ``colour`` (a Matplotlib colour) are used
    in every figure and table.
    """

    id: str
    label: str
    colour: str
    adaptive: bool
    composite: bool
    description: str


CONTROLLERS: dict[str, ControllerInfo] = {c.id: c for c in (
    ControllerInfo("composite", "C. Adapt", "C0", True, True,
                   "the paper's composite adaptive law (eq:th_adapt, eq:P_adapt)"),
    ControllerInfo("composite_pconst", "C. Adapt, P const", "C2", True, True,
                   "the composite law with P held at P0 (the paper's controller II)"),
    ControllerInfo("tracking_only", "Tracking-error adapt", "C4", True, False,
                   "adaptation on the tracking error only, theta-hat' = P0 Phi^T R^T v-tilde (III)"),
    ControllerInfo("pid", "PID", "C1", False, False,
                   "PX4-style velocity PID with the same force allocation, theta-hat = theta_0 (IV)"),
    ControllerInfo("pd", "PD", "C3", False, False,
                   "the PID without its integral (V)"),
)}

CONTROLLER_IDS: tuple[str, ...] = tuple(CONTROLLERS)
ADAPTIVE_IDS: tuple[str, ...] = tuple(k for k, c in CONTROLLERS.items() if c.adaptive)
COMPOSITE_IDS: tuple[str, ...] = tuple(k for k, c in CONTROLLERS.items() if c.composite)


def controller_info(controller_id: str) -> ControllerInfo:
    """The registry entry of ``controller_id``; ``KeyError`` naming the allowed ids otherwise."""
    try:
        return CONTROLLERS[controller_id]
    except KeyError:
        raise KeyError(f"unknown controller {controller_id!r}; allowed: {', '.join(CONTROLLER_IDS)}") from None
