"""Size ceilings that have nothing to do with the simulator, each derived from the memory its arrays
need against one budget: a campaign's plan, a virtual tunnel's design, an MCMC fit.

Every size a user chooses is checked before anything runs or is written, against
:data:`vtoladapt.config.MEMORY_BUDGET_BYTES` (6 GiB unless ``VTOLADAPT_MEMORY_BUDGET_GB`` says
otherwise); the message says how the bytes were counted. The simulator's own (its logs) are in
:mod:`vtoladapt.sim.limits`; docs/reference/errors.md ("Size ceilings") lists the resulting ceilings.
"""
from __future__ import annotations

import math
import pickle

from .config import MEMORY_BUDGET_BYTES, check_memory

FLOAT_BYTES = 8
FORCE_BALANCE_COLUMNS = 16
"""Float columns of a force-balance table in memory (inputs, forces, moments, derived values)."""
FIT_PARAMETERS_MAX = 8
"""Most dimensions the MCMC samples (k1, k2 and the noise model), an upper count for its chain."""
FIT_WORK_COPIES = 4
"""Residual arrays (walkers x rows x 3 axes) alive at once in one vectorised likelihood call."""
CAMPAIGN_ROW_BYTES = 4096
"""A campaign row (about forty metrics in a dict) and its Dask task record, generously."""


def check_campaign_runs(runs: int, base_mapping: dict, where: str = "--runs") -> None:
    """Refuse a campaign whose planned runs (each a scenario copy and a result row) exceed the budget."""
    per_run = len(pickle.dumps(base_mapping)) * 3 + CAMPAIGN_ROW_BYTES  # dict overhead ~3x pickle
    check_memory(f"{runs} runs x {per_run} bytes (scenario copy and result row)",
                 float(runs) * per_run, where, "split the campaign into several")


def check_tunnel_rows(points_per_repeat: int, repeats: int, where: str = "--repeats") -> None:
    """Refuse a tunnel design whose table (rows x columns x 8 bytes) exceeds the budget."""
    rows = float(points_per_repeat) * repeats
    check_memory(f"{points_per_repeat} points x {repeats} repeats x {FORCE_BALANCE_COLUMNS} "
                 f"columns x {FLOAT_BYTES} bytes", rows * FORCE_BALANCE_COLUMNS * FLOAT_BYTES, where)


def check_fit_size(walkers: int, max_steps: int, n_rows: int, where: str) -> None:
    """Refuse MCMC settings whose chain and vectorised residuals exceed the budget."""
    chain = float(walkers) * max_steps * FIT_PARAMETERS_MAX * FLOAT_BYTES
    work = float(walkers) * n_rows * 3 * FLOAT_BYTES * FIT_WORK_COPIES
    check_memory(f"chain {walkers} walkers x {max_steps} steps x {FIT_PARAMETERS_MAX} parameters "
                 f"x {FLOAT_BYTES} bytes + residuals {walkers} walkers x {n_rows} rows x 3 axes x "
                 f"{FLOAT_BYTES} bytes x {FIT_WORK_COPIES}", chain + work, where)


def ceiling(n_bytes_per_unit: float) -> int:
    """How many units of ``n_bytes_per_unit`` the budget holds."""
    return int(math.floor(MEMORY_BUDGET_BYTES / n_bytes_per_unit))
