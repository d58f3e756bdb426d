"""The container of a probe calibration: tunnel points with true flow and measured pressures.

Read from files by :func:`vtoladapt.probe.data.read_probe_data` (either format), simulated by
:func:`vtoladapt.probe.data.simulate_calibration_sweep`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vtoladapt.probe.errors import ProbeError
from vtoladapt.probe.flow import v_i_from_airspeed_angles


@dataclass(frozen=True, eq=False)
class ProbeCalibrationData:
    """Tunnel points of a probe calibration: true flow and measured differential pressures.

    Parameters
    ----------
    source : str
        Where the data came from (a path or a description), used in messages and outputs.
    alpha_deg, beta_deg : numpy.ndarray, shape (N,)
        True angle of attack and sideslip (deg).
    V_mps : numpy.ndarray, shape (N,)
        True airspeed (m/s).
    rho : numpy.ndarray, shape (N,)
        Air density (kg/m^3).
    q_Pa : numpy.ndarray, shape (N, 3)
        ``[q_inf, q_alpha, q_beta]`` (Pa).
    is_test : numpy.ndarray of bool, shape (N,)
        ``True`` for held-out test points, ``False`` for calibration points.
    info : dict
        Free-form metadata (e.g. probe serial, Mach number).
    """

    source: str
    alpha_deg: np.ndarray
    beta_deg: np.ndarray
    V_mps: np.ndarray
    rho: np.ndarray
    q_Pa: np.ndarray
    is_test: np.ndarray
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = np.asarray(self.alpha_deg).shape[0]
        for name in ("alpha_deg", "beta_deg", "V_mps", "rho"):
            arr = np.ascontiguousarray(getattr(self, name), dtype=float)
            if arr.shape != (n,):
                raise ProbeError(f"{self.source}: {name} has shape {arr.shape}, expected ({n},)")
            object.__setattr__(self, name, arr)
        q = np.ascontiguousarray(self.q_Pa, dtype=float)
        if q.shape != (n, 3):
            raise ProbeError(f"{self.source}: q_Pa has shape {q.shape}, expected ({n}, 3)")
        object.__setattr__(self, "q_Pa", q)
        t = np.ascontiguousarray(self.is_test, dtype=bool)
        if t.shape != (n,):
            raise ProbeError(f"{self.source}: is_test has shape {t.shape}, expected ({n},)")
        object.__setattr__(self, "is_test", t)

    def __len__(self) -> int:
        return int(self.alpha_deg.shape[0])

    @property
    def v_i_B(self) -> np.ndarray:
        """True incident velocity in body axes (m/s), shape (N, 3)."""
        return v_i_from_airspeed_angles(self.V_mps, np.radians(self.alpha_deg),
                                        np.radians(self.beta_deg))

    @property
    def cone_angle_deg(self) -> np.ndarray:
        """Angle between the probe axis and the flow (deg), shape (N,)."""
        c = np.cos(np.radians(self.alpha_deg)) * np.cos(np.radians(self.beta_deg))
        return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))

    @property
    def q_dyn_Pa(self) -> np.ndarray:
        """True dynamic pressure ``rho V^2 / 2`` (Pa)."""
        return 0.5 * self.rho * self.V_mps ** 2

    @property
    def has_test_points(self) -> bool:
        """Whether any point is marked as a test point."""
        return bool(np.any(self.is_test))

    def subset(self, mask, label: str = "") -> "ProbeCalibrationData":
        """The points selected by ``mask``.

        Parameters
        ----------
        mask : array_like
            Boolean mask or index array.
        label : str
            Recorded as ``info["subset"]`` (e.g. ``test``).

        Returns
        -------
        ProbeCalibrationData
        """
        idx = np.asarray(mask)
        info = dict(self.info)
        if label:
            info["subset"] = label
        return ProbeCalibrationData(
            source=self.source, alpha_deg=self.alpha_deg[idx], beta_deg=self.beta_deg[idx],
            V_mps=self.V_mps[idx], rho=self.rho[idx], q_Pa=self.q_Pa[idx],
            is_test=self.is_test[idx], info=info)

    def calibration_points(self) -> "ProbeCalibrationData":
        """The calibration (non-test) points."""
        return self.subset(~self.is_test, "calibration")

    def test_points(self) -> "ProbeCalibrationData":
        """The held-out test points."""
        return self.subset(self.is_test, "test")

    def select(self, points: str) -> "ProbeCalibrationData":
        """Points by name.

        Parameters
        ----------
        points : {'auto', 'test', 'calibration', 'all'}
            ``auto``: the test points if any, else all points.

        Returns
        -------
        ProbeCalibrationData

        Raises
        ------
        ProbeError
            For an unknown name, or ``test`` when the data has no test points.
        """
        if points == "auto":
            return self.test_points() if self.has_test_points else self.subset(
                np.ones(len(self), bool), "all")
        if points == "test":
            if not self.has_test_points:
                raise ProbeError(f"{self.source}: points = 'test': the data has no test points "
                                 "(no 'split' column, or no row with split = test)")
            return self.test_points()
        if points == "calibration":
            return self.calibration_points()
        if points == "all":
            return self.subset(np.ones(len(self), bool), "all")
        raise ProbeError(f"points = {points!r}: unknown; allowed: 'auto', 'test', "
                         "'calibration', 'all'")
