"""Typed simulation results: time-indexed named signals, Parquet round trip, metrics.

A :class:`SimulationResult` holds one run: a 2-D array with time as the first axis and one named
column per signal (units in the names, see README "Log columns"), plus the scenario that produced
it and the run's metadata. ``result["v_N_mps"]`` is a 1-D array; grouped accessors return
``(T, 3)`` arrays.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from ..vehicle import PARAMETER_NAMES

PARQUET_FORMAT_VERSION = 1


@dataclass
class SimulationResult:
    """One simulation run. ``data[:, i]`` is the signal named ``columns[i]``."""

    columns: tuple[str, ...]
    data: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.data = np.asarray(self.data, dtype=float)
        if self.data.ndim != 2 or self.data.shape[1] != len(self.columns):
            raise ValueError(f"data has shape {self.data.shape}, expected (T, {len(self.columns)})")
        self._index = {name: i for i, name in enumerate(self.columns)}
        self._v_tilde: np.ndarray | None = None

    # --- access ---------------------------------------------------------------------------
    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[:, self._index[name]]
        except KeyError:
            raise KeyError(f"no column {name!r}; see .columns") from None

    def __contains__(self, name: str) -> bool:
        return name in self._index

    def columns_like(self, names) -> np.ndarray:
        """``(T, len(names))`` array of the named columns."""
        return self.data[:, [self._index[n] for n in names]]

    @property
    def time_s(self) -> np.ndarray:
        """Time of each tick (s), shape (T,)."""
        return self["t_s"]

    @property
    def position_W(self) -> np.ndarray:
        """True position, NED (m), shape (T, 3)."""
        return self.columns_like(("p_N_m", "p_E_m", "p_D_m"))

    @property
    def velocity_W(self) -> np.ndarray:
        """True velocity, NED (m/s), shape (T, 3)."""
        return self.columns_like(("v_N_mps", "v_E_mps", "v_D_mps"))

    @property
    def wind_W(self) -> np.ndarray:
        """Wind at the vehicle, NED (m/s), shape (T, 3)."""
        return self.columns_like(("wind_N_mps", "wind_E_mps", "wind_D_mps"))

    @property
    def velocity_error_W(self) -> np.ndarray:
        """The paper's velocity tracking error ``v~ = v - v_r`` (NED, m/s) from the true state.

        ``v_r = p_d' - Lambda_p (p - p_d)`` (eq:wr, with the run's ``Lambda_p`` and correction
        limit from the metadata), so a steady position offset shows as a velocity error, as in
        the paper's figures. Computed once and cached.
        """
        if self._v_tilde is None:
            # vtoladapt.control.tracking.reference_velocity's v_r, every row at once (a Python loop
            # over it held the GIL for a third of a comparison run's time): the correction
            # Lambda_p p~, scaled to its limit where longer
            lam = np.asarray(self.metadata["Lambda_p"], dtype=float)
            corr_max = float(self.metadata["velocity_correction_max_mps"])
            p_tilde = self.position_W - self.columns_like(("ref_p_N_m", "ref_p_E_m", "ref_p_D_m"))
            v_d = self.columns_like(("ref_v_N_mps", "ref_v_E_mps", "ref_v_D_mps"))
            c = lam * p_tilde
            n = np.sqrt(c[:, 0] * c[:, 0] + c[:, 1] * c[:, 1] + c[:, 2] * c[:, 2])
            saturated = ~(n <= corr_max)
            s = np.ones_like(n)
            s[saturated] = corr_max / n[saturated]
            self._v_tilde = self.velocity_W - (v_d - s[:, None] * c)
        return self._v_tilde

    @property
    def position_error_W(self) -> np.ndarray:
        """Position minus the reference position (NED, m)."""
        return self.position_W - self.columns_like(("ref_p_N_m", "ref_p_E_m", "ref_p_D_m"))

    @property
    def theta_names(self) -> tuple[str, ...]:
        """The names of theta-hat's entries: the controller's force-model basis's parameters (the paper's
        eight unless the run's metadata names others)."""
        return tuple(self.metadata.get("theta_names", PARAMETER_NAMES))

    @property
    def theta_hat(self) -> np.ndarray:
        """``(T, n)`` theta-hat in the adaptation scaling, if the controller logs it (columns :attr:`theta_names`)."""
        return self.columns_like([f"theta_hat_{n}" for n in self.theta_names])

    @property
    def diverged_at_s(self) -> float | None:
        """Time (s) the state left the scenario's envelope and the run stopped, or None."""
        return self.metadata.get("diverged_at_s")

    @property
    def divergence_reason(self) -> str | None:
        """One line on which envelope limit was hit, by how much and when, or None."""
        return self.metadata.get("divergence_reason")

    @property
    def diverged(self) -> bool:
        """Whether the run stopped early because it left its envelope."""
        return self.diverged_at_s is not None

    def raise_if_diverged(self) -> "SimulationResult":
        """Return ``self``, or raise :class:`vtoladapt.sim.monitor.DivergenceError` if the run diverged."""
        if self.diverged:
            from .monitor import DivergenceError

            raise DivergenceError(self)
        return self

    def __len__(self) -> int:
        return self.data.shape[0]

    # --- files ----------------------------------------------------------------------------
    def to_parquet(self, path: str | Path) -> Path:
        """Write the log (one float64 column per signal) with the metadata in the file's schema."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        table = pa.table({name: self.data[:, i] for i, name in enumerate(self.columns)})
        meta = {b"vtoladapt_format": str(PARQUET_FORMAT_VERSION).encode(),
                b"vtoladapt_metadata": json.dumps(self.metadata, default=_jsonable).encode()}
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), **meta})
        from ..outputs import atomic_path

        with atomic_path(path) as tmp:  # never a half-written log; recorded in the folder's manifest
            pq.write_table(table, tmp)
        return path

    @classmethod
    def from_parquet(cls, path: str | Path) -> "SimulationResult":
        """Read a log written by :meth:`to_parquet`."""
        table = pq.read_table(path)
        meta = table.schema.metadata or {}
        if meta.get(b"vtoladapt_format") != str(PARQUET_FORMAT_VERSION).encode():
            raise ValueError(f"{path}: not a vtoladapt log of format {PARQUET_FORMAT_VERSION}")
        data = np.column_stack([table.column(i).to_numpy() for i in range(table.num_columns)])
        return cls(tuple(table.column_names), data, json.loads(meta[b"vtoladapt_metadata"]))


def _jsonable(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot store {type(obj).__name__} in log metadata")
