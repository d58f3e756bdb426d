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
        the paper's figures. A result :meth:`measured_with` another ``Lambda_p`` uses that one
        instead of the gain it flew. Computed once and cached.
        """
        if self._v_tilde is None:
            # vtoladapt.control.tracking.reference_velocity's v_r, every row at once (a Python loop
            # over it held the GIL for a third of a comparison run's time): the correction
            # Lambda_p p~, scaled to its limit where longer
            lam = np.asarray(self.metadata.get("metric_Lambda_p") or self.metadata["Lambda_p"], dtype=float)
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

    def measured_with(self, Lambda_p) -> "SimulationResult":
        """The same run (its log shared, not copied) whose :attr:`velocity_error_W` is measured with the
        position gain ``Lambda_p`` (3 values, 1/s) instead of the one it flew (metadata
        ``metric_Lambda_p``).

        ``v~ = v - v_r`` weighs the position error by ``Lambda_p``: laws that fly different position
        gains are compared on one yardstick only if their errors are measured with the same one
        (``vtoladapt tune`` searches ``Lambda_p``; :mod:`vtoladapt.experiments.tuning`).
        """
        lam = [float(x) for x in Lambda_p]
        if len(lam) != 3 or not all(np.isfinite(lam)):
            raise ValueError(f"measured_with: Lambda_p = {Lambda_p!r}: three finite values (1/s)")
        out = SimulationResult(self.columns, self.data, {**self.metadata, "metric_Lambda_p": lam})
        if lam == [float(x) for x in self.metadata["Lambda_p"]]:
            out._v_tilde = self._v_tilde
        return out

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
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), **log_metadata_entries(self.metadata)})
        from ..outputs import atomic_path

        with atomic_path(path) as tmp:  # never a half-written log; recorded in the folder's manifest
            pq.write_table(table, tmp)
        return path

    @classmethod
    def from_parquet(cls, path: str | Path) -> "SimulationResult":
        """Read a log written by :meth:`to_parquet` or streamed (:func:`vtoladapt.sim.longrun.stream_to_parquet`)."""
        meta = log_file_metadata(path)
        table = pq.read_table(path)
        data = np.column_stack([table.column(i).to_numpy() for i in range(table.num_columns)])
        return cls(tuple(table.column_names), data, meta)


def log_file_metadata(path: str | Path) -> dict:
    """The run metadata of a vtoladapt log file: in the Arrow schema (:meth:`SimulationResult.to_parquet`)
    or in the Parquet footer (a streamed log, whose metadata is known only when the run ends)."""
    f = pq.ParquetFile(path)
    meta = dict(f.schema_arrow.metadata or {})
    meta.update(f.metadata.metadata or {})
    if meta.get(b"vtoladapt_format") != str(PARQUET_FORMAT_VERSION).encode():
        raise ValueError(f"{path}: not a vtoladapt log of format {PARQUET_FORMAT_VERSION}")
    return json.loads(meta[b"vtoladapt_metadata"])


def log_metadata_entries(metadata: dict) -> dict[bytes, bytes]:
    """The key-value entries a log file carries for ``metadata`` (schema or footer)."""
    return {b"vtoladapt_format": str(PARQUET_FORMAT_VERSION).encode(),
            b"vtoladapt_metadata": json.dumps(metadata, default=_jsonable).encode()}


class LoggedResult(SimulationResult):
    """A run whose log stays in its Parquet file (streamed by :func:`vtoladapt.sim.longrun.stream_to_parquet`).

    A column is read from the file the first time it is used and then kept, so memory holds the
    columns the metrics and figures use (:attr:`loaded_columns`), never the whole log; ``data``
    reads every column (the whole log in memory: avoid it for long runs).
    """

    def __init__(self, path: str | Path, columns, metadata: dict, n_rows: int):
        self.path = Path(path)
        self.columns = tuple(columns)
        self.metadata = dict(metadata)
        self._n = int(n_rows)
        self._index = {name: i for i, name in enumerate(self.columns)}
        self._loaded: dict[str, np.ndarray] = {}
        self._v_tilde = None

    @classmethod
    def open(cls, path: str | Path) -> "LoggedResult":
        """The log at ``path`` (a file written by :meth:`SimulationResult.to_parquet` or streamed)."""
        f = pq.ParquetFile(path)
        return cls(path, f.schema_arrow.names, log_file_metadata(path), f.metadata.num_rows)

    @property
    def data(self) -> np.ndarray:
        """Every column, ``(T, n_columns)``: the whole log in memory."""
        return np.column_stack([self[c] for c in self.columns]) if self.columns else np.empty((self._n, 0))

    @property
    def loaded_columns(self) -> tuple[str, ...]:
        """The columns read so far (what this result holds in memory)."""
        return tuple(self._loaded)

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._index:
            raise KeyError(f"no column {name!r}; see .columns")
        col = self._loaded.get(name)
        if col is None:
            col = pq.read_table(self.path, columns=[name]).column(0).to_numpy()
            self._loaded[name] = col
        return col

    def columns_like(self, names) -> np.ndarray:
        """``(T, len(names))`` array of the named columns (each read once)."""
        return np.column_stack([self[n] for n in names]) if len(names) else np.empty((self._n, 0))

    def __len__(self) -> int:
        return self._n


def _jsonable(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot store {type(obj).__name__} in log metadata")
