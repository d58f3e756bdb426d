"""What a run writes of its log: a scenario's ``[output]`` table (``vtoladapt run --log-rate HZ /
--no-log``).

An hour at 250 Hz is a 1.2 GB log (issue #37). ``log_rate_hz`` keeps every k-th control tick,
``k = round(control rate / log_rate_hz)``: the rows are the state and signals at those ticks, as
logged, not averages (a decimated log is the full log's rows 0, k, 2k, ...). The metrics, figures and
report are computed from every tick whatever is kept: the run streams its full log to the output
folder as before, the analysis reads it there, and only then is it replaced by the kept rows
(:func:`thin_log`) -- or removed, with ``log = false``. So the disk holds the full log while the
run is analysed, and memory stays what it was (one row group at a time).

The table is applied where logs are written to an output folder (:func:`vtoladapt.experiments.run_experiment`,
``vtoladapt run``); :func:`vtoladapt.sim.simulate` returns every tick in memory whatever it says.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ..config import ConfigError, Validated, setting

MAX_LOG_RATE_HZ = 10_000.0
"""The fastest control rate a scenario may have (``dt_control_s`` >= 1e-4 s)."""


@dataclass(frozen=True)
class OutputConfig(Validated):
    """What a run keeps of its log (the metrics always use every control tick)."""

    config_section = "output"

    log: bool = setting("-", "write the run's log file(s) (false: metrics, figures and report only; "
                        "`vtoladapt run --no-log`)", default=True)
    log_rate_hz: Optional[float] = setting(
        "Hz", "rows per second kept in the log: every k-th control tick, k = round(control rate / "
        "log_rate_hz), at most the control rate (`--log-rate`); absent: every tick", default=None,
        gt=0.0, le=MAX_LOG_RATE_HZ)

    def every_ticks(self, dt_control_s: float) -> int:
        """``k``: the log keeps control ticks 0, k, 2k, ... (1: every tick)."""
        if self.log_rate_hz is None:
            return 1
        return max(1, int(round(1.0 / (dt_control_s * self.log_rate_hz))))

    def check_rate(self, dt_control_s: float, source: str) -> None:
        """A :class:`ConfigError` if ``log_rate_hz`` is above the control rate (no tick to log)."""
        rate = 1.0 / dt_control_s
        if self.log_rate_hz is not None and self.log_rate_hz > rate * (1 + 1e-9):
            raise ConfigError(f"{source}: [output] log_rate_hz = {self.log_rate_hz:g}: above the control rate; "
                              f"allowed: at most {rate:g} Hz (1 / dt_control_s)")

    @property
    def thinned(self) -> bool:
        """Whether the written log differs from the full one (thinned or not written)."""
        return not self.log or self.log_rate_hz is not None


def thin_log(path: Path, every: int, keep: bool = True) -> Optional[int]:
    """Replace the log at ``path`` by its rows 0, every, 2 every, ... (row group by row group, the
    footer's run metadata kept and told the decimation), or remove it if not ``keep``. Returns the
    rows kept (None if removed). Written atomically: an interrupted thinning leaves the full log."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from ..outputs import atomic_path, remove_output
    from .results import log_file_metadata, log_metadata_entries

    path = Path(path)
    if not keep:
        remove_output(path)
        return None
    if every <= 1:
        return pq.ParquetFile(path).metadata.num_rows
    source = pq.ParquetFile(path)
    metadata = log_file_metadata(path)
    dt = metadata.get("dt_control_s")
    metadata["log_every_ticks"] = every
    if dt:
        metadata["log_rate_hz"] = 1.0 / (float(dt) * every)
    start, kept = 0, 0  # row index (in the full log) of the current group's first row
    with atomic_path(path) as tmp, pq.ParquetWriter(tmp, source.schema_arrow.remove_metadata()) as writer:
        for g in range(source.num_row_groups):
            table = source.read_row_group(g).replace_schema_metadata(None)
            n = table.num_rows
            first = (-start) % every  # the first row of this group whose full-log index is a multiple of every
            rows = pa.array(range(first, n, every), type=pa.int64())
            if len(rows):
                writer.write_table(table.take(rows))
                kept += len(rows)
            start += n
        writer.add_key_value_metadata({k.decode(): v.decode() for k, v in log_metadata_entries(metadata).items()})
    return kept


__all__ = ["MAX_LOG_RATE_HZ", "OutputConfig", "thin_log"]
