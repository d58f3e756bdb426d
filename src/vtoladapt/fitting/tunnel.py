"""Virtual wind tunnel: force-balance sweeps of a simulated aircraft, written as force-balance CSV.

The sweep follows the paper's Model Fitting section: free-stream speeds up to 9 m/s, the wing
over the linear range of angle of attack with the motors off, static thrust steps of the pusher
and the lift rotors, and the lift rotors (propulsion only, no wing) at angles of attack from
-45 to 45 deg for the rotor side force (eq:model_Fs).

The "truth" is a function argument (:data:`TruthFunction`): by default the force-model kernels
of :mod:`vtoladapt.forces` with "true" coefficients (:func:`linear_model_truth`), i.e. the plant
with its unmodelled effects off. A plant with stall etc. can be swapped in with the same signature.

Noise model (a force balance): each axis of each reading gets independent Gaussian noise with
standard deviation ``sigma_abs_N + sigma_rel * |F_true|`` (default 0.02 N + 1 % of reading),
drawn from the :class:`numpy.random.Generator` passed in. Operating points (V, alpha, beta,
throttles) are taken as exact: the tunnel's set points are known far better than the forces.
"""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .. import forces
from ..config import Validated, build, setting
from ..models import THROTTLE_FULL_PCT, model_kernel_params, theta_to_scaled
from ..vehicle import PARAMETER_NAMES, ForceModelCoefficients, Vehicle
from .data import ForceBalanceData, FitDataError, incident_velocity_from_angles, write_force_balance_csv

TRUTH_FORMAT = "vtoladapt.tunnel-truth"
TRUTH_VERSION = 1
AERO_COLUMNS = slice(forces.I_CD0, forces.I_CL1 + 1)

TruthFunction = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""``truth(v_i_B (N,3) m/s, u_x (N,) fraction, u_z (N,) fraction, wing_on (N,) bool,
rho (N,) kg/m^3) -> f_B (N,3)``: body FRD force per unit flight mass, m/s^2."""


@dataclass(frozen=True)
class TunnelDesign(Validated):
    """The tunnel points of a virtual force-balance campaign."""

    wing_airspeeds_mps: tuple[float, ...] = setting(
        "m/s", "airspeeds of the wing sweep (motors off)", default=(3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0),
        gt=0.0)
    wing_alpha_range_deg: tuple[float, ...] = setting(
        "deg", "first and last angle of attack of the wing sweep (the linear range)",
        default=(-10.0, 15.0), gt=-90.0, lt=90.0, length=2)
    wing_alpha_step_deg: float = setting("deg", "angle-of-attack step of the wing sweep", default=2.5,
                                         gt=0.0)
    static_throttles_pct: tuple[float, ...] = setting(
        "%", "throttle steps of the static thrust runs (pusher alone, then lift rotors alone)",
        default=(10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0), gt=0.0, le=100.0)
    rotor_airspeeds_mps: tuple[float, ...] = setting(
        "m/s", "airspeeds of the rotor side-force sweep (propulsion only)", default=(3.0, 5.0, 7.0, 9.0),
        gt=0.0)
    rotor_alpha_range_deg: tuple[float, ...] = setting(
        "deg", "first and last rotor angle of attack of the side-force sweep", default=(-45.0, 45.0),
        gt=-90.0, lt=90.0, length=2)
    rotor_alpha_step_deg: float = setting("deg", "angle step of the side-force sweep", default=7.5,
                                          gt=0.0)
    rotor_throttles_pct: tuple[float, ...] = setting(
        "%", "lift-rotor throttles of the side-force sweep", default=(30.0, 45.0, 60.0, 75.0),
        gt=0.0, le=100.0)
    rotor_beta_deg: tuple[float, ...] = setting(
        "deg", "sideslip angles of the side-force sweep", default=(0.0, 15.0), gt=-90.0, lt=90.0)
    repeats: int = setting("-", "how many times every point is measured", default=1, ge=1)

    def _check(self, source: str) -> None:
        for name in ("wing_alpha_range_deg", "rotor_alpha_range_deg"):
            lo, hi = getattr(self, name)
            if not lo <= hi:
                raise FitDataError(f"{source}: {name} = {[lo, hi]}: first must be <= last")


@dataclass(frozen=True)
class BalanceNoise(Validated):
    """Force-balance noise: per axis, std ``sigma_abs_N + sigma_rel * |reading|``."""

    sigma_abs_N: float = setting("N", "absolute noise of each force axis", default=0.02, ge=0.0)
    sigma_rel: float = setting("-", "noise as a fraction of each axis' reading", default=0.01, ge=0.0,
                               lt=1.0)


def make_design(**overrides) -> TunnelDesign:
    """A validated :class:`TunnelDesign` with some fields changed (e.g. ``repeats=4``)."""
    base = {f.name: getattr(TunnelDesign(), f.name) for f in dataclasses.fields(TunnelDesign)}
    base.update({k: (list(v) if isinstance(v, tuple) else v) for k, v in overrides.items()})
    base = {k: (list(v) if isinstance(v, tuple) else v) for k, v in base.items()}
    return build(TunnelDesign, base, source="tunnel design")


def _span(lo: float, hi: float, step: float) -> np.ndarray:
    n = int(math.floor((hi - lo) / step + 1e-9)) + 1
    return lo + step * np.arange(n)


def design_points(design: TunnelDesign) -> dict[str, np.ndarray]:
    """The operating points of ``design`` as arrays (each point ``design.repeats`` times).

    Returns
    -------
    dict
        ``airspeed_mps, alpha_deg, beta_deg, throttle_x_pct, throttle_z_pct`` (N,) floats and
        ``wing_on`` (N,) bool, in the order wing sweep, static thrust, rotor side-force sweep.
    """
    rows = []
    for V in design.wing_airspeeds_mps:
        for a in _span(*design.wing_alpha_range_deg, design.wing_alpha_step_deg):
            rows.append((V, a, 0.0, 0.0, 0.0, True))
    for u in design.static_throttles_pct:
        rows.append((0.0, 0.0, 0.0, u, 0.0, True))
    for u in design.static_throttles_pct:
        rows.append((0.0, 0.0, 0.0, 0.0, u, True))
    for V in design.rotor_airspeeds_mps:
        for u in design.rotor_throttles_pct:
            for b in design.rotor_beta_deg:
                for a in _span(*design.rotor_alpha_range_deg, design.rotor_alpha_step_deg):
                    rows.append((V, a, b, 0.0, u, False))
    arr = np.array([r[:5] for r in rows], float)
    wing = np.array([r[5] for r in rows], bool)
    arr = np.tile(arr, (design.repeats, 1))
    wing = np.tile(wing, design.repeats)
    return {"airspeed_mps": arr[:, 0], "alpha_deg": arr[:, 1], "beta_deg": arr[:, 2],
            "throttle_x_pct": arr[:, 3], "throttle_z_pct": arr[:, 4], "wing_on": wing}


def regressor_for_rows(v_i_B: np.ndarray, u_x: np.ndarray, u_z: np.ndarray, wing_on: np.ndarray,
                       rho_kgpm3: np.ndarray, rho_ref_kgpm3: float, aero_scale_ref_per_m: float,
                       k1: float, k2: float, stall_angle_deg: float) -> np.ndarray:
    """The control regressor (:func:`vtoladapt.forces.regressor_rows`) for tunnel rows, (N, 3, 8).

    Rows without the wing have zero aerodynamic columns; every row is scaled by
    ``rho / rho_ref`` (all forces of the model are proportional to density), so that
    ``Phi @ theta_scaled`` is the body force per unit mass at the row's density for coefficients
    referred to ``rho_ref``. Throttles ``u_x, u_z`` are fractions, theta in the adaptation scaling.
    """
    model = model_kernel_params(aero_scale_ref_per_m, k1, k2, stall_angle_deg)
    Phi = forces.regressor_rows(np.ascontiguousarray(v_i_B, dtype=float),
                                np.ascontiguousarray(u_x, dtype=float),
                                np.ascontiguousarray(u_z, dtype=float), model)
    Phi[~np.asarray(wing_on, bool), :, AERO_COLUMNS] = 0.0
    Phi *= (np.asarray(rho_kgpm3, float) / rho_ref_kgpm3)[:, None, None]
    return Phi


def linear_model_truth(coefficients: ForceModelCoefficients, vehicle: Vehicle) -> TruthFunction:
    """The paper's force model with given coefficients as a tunnel truth (no unmodelled effects).

    Parameters
    ----------
    coefficients : ForceModelCoefficients
        The "true" coefficients in Table I units (including k1, k2).
    vehicle : Vehicle
        Supplies the wing area, the flight mass and the reference density of the coefficients.
    """
    k1, k2 = coefficients.k1, coefficients.k2
    theta_s = theta_to_scaled(coefficients.as_table_theta(), k1)
    rho_ref = vehicle.envelope.air_density_kgpm3
    scale = vehicle.aero_scale_per_m
    stall = vehicle.envelope.stall_angle_deg

    def truth(v_i_B, u_x, u_z, wing_on, rho_kgpm3):
        Phi = regressor_for_rows(v_i_B, u_x, u_z, wing_on, rho_kgpm3, rho_ref, scale, k1, k2, stall)
        return Phi @ theta_s

    return truth


def true_coefficients(vehicle: Vehicle, perturb: bool = False,
                      rng: np.random.Generator | None = None) -> ForceModelCoefficients:
    """The truth's coefficients: the vehicle's Table I means, or a draw from Table I's spread.

    With ``perturb``, each of the ten coefficients is ``mean + std * z`` with ``z`` standard
    normal from ``rng``, redrawn (at most 100 times) until it satisfies the vehicle file's
    limits (e.g. ``CS >= 0``, ``0 < k1 < 2``, ``k2 > pi/2``).
    """
    fm = vehicle.force_model
    if not perturb:
        return fm
    if rng is None:
        raise ValueError("perturb=True needs rng (a numpy.random.Generator)")
    std = vehicle.force_model_std
    names = [f.name for f in dataclasses.fields(ForceModelCoefficients)]
    values = {}
    for name in names:
        mean, sd = getattr(fm, name), getattr(std, name)
        for _ in range(100):
            v = mean + sd * float(rng.standard_normal())
            try:
                build(ForceModelCoefficients, {**{n: getattr(fm, n) for n in names}, name: v},
                      source="perturbed truth")
            except ValueError:
                continue
            values[name] = v
            break
        else:  # pragma: no cover - needs a std far larger than the mean
            raise ValueError(f"could not draw a valid {name} from mean {mean} and std {sd}")
    return build(ForceModelCoefficients, values, source="perturbed truth")


@dataclass(frozen=True)
class TunnelRun:
    """A virtual tunnel campaign: the data and what produced it."""

    data: ForceBalanceData
    truth: ForceModelCoefficients | None
    noise: BalanceNoise
    design: TunnelDesign
    vehicle_name: str
    seed: int | None
    perturbed: bool

    def truth_info(self) -> dict:
        """The side file's content (JSON-serialisable)."""
        info = {
            "format": TRUTH_FORMAT, "format_version": TRUTH_VERSION,
            "vehicle": self.vehicle_name, "seed": self.seed, "perturbed": self.perturbed,
            "units": "Table I: throttle in percent, forces per unit flight mass (m/s^2), alpha in rad",
            "noise_model": {"sigma_abs_N": self.noise.sigma_abs_N, "sigma_rel": self.noise.sigma_rel,
                            "rule": "per axis std = sigma_abs_N + sigma_rel * |true force|"},
            "n_rows": self.data.n_rows,
            "mass_kg": self.data.mass_kg,
            "design": {f.name: getattr(self.design, f.name)
                       for f in dataclasses.fields(TunnelDesign)},
        }
        if self.truth is not None:
            info["coefficients"] = {f.name: getattr(self.truth, f.name)
                                    for f in dataclasses.fields(ForceModelCoefficients)}
        else:
            info["coefficients"] = None
        return info


def run_virtual_tunnel(vehicle: Vehicle, rng: np.random.Generator, *,
                       design: TunnelDesign | None = None, noise: BalanceNoise | None = None,
                       truth: TruthFunction | None = None, perturb: bool = False,
                       air_density_kgpm3: float | None = None, seed: int | None = None) -> TunnelRun:
    """Sweep the simulated aircraft through ``design`` and return noisy force-balance data.

    Parameters
    ----------
    vehicle : Vehicle
        The aircraft (mass, wing area, reference density, Table I coefficients).
    rng : numpy.random.Generator
        Source of the perturbation of the truth (if ``perturb``) and of the balance noise.
    design : TunnelDesign, optional
        Tunnel points (default :class:`TunnelDesign`).
    noise : BalanceNoise, optional
        Balance noise (default 0.02 N + 1 % of reading).
    truth : TruthFunction, optional
        The simulated aircraft; default :func:`linear_model_truth` of :func:`true_coefficients`.
        When given, ``perturb`` must be False and the run records no coefficients.
    perturb : bool
        Draw the true coefficients from Table I's std (see :func:`true_coefficients`).
    air_density_kgpm3 : float, optional
        Tunnel air density written in every row (default the vehicle's reference density).
    seed : int, optional
        Recorded in the side file only (the randomness comes from ``rng``).
    """
    design = design or TunnelDesign()
    noise = noise or BalanceNoise()
    coeffs = None
    if truth is None:
        coeffs = true_coefficients(vehicle, perturb, rng)
        truth = linear_model_truth(coeffs, vehicle)
    elif perturb:
        raise ValueError("perturb applies to the default truth only; perturb your own truth instead")
    pts = design_points(design)
    rho = float(air_density_kgpm3 or vehicle.envelope.air_density_kgpm3)
    if not rho > 0.0:
        raise ValueError(f"air_density_kgpm3 = {air_density_kgpm3!r}: must be > 0 (kg/m^3)")
    n = pts["airspeed_mps"].shape[0]
    deg = np.pi / 180.0
    v_i_B = incident_velocity_from_angles(pts["airspeed_mps"], pts["alpha_deg"] * deg,
                                          pts["beta_deg"] * deg)
    rho_rows = np.full(n, rho)
    f_true = np.asarray(truth(v_i_B, pts["throttle_x_pct"] / THROTTLE_FULL_PCT,
                              pts["throttle_z_pct"] / THROTTLE_FULL_PCT, pts["wing_on"], rho_rows),
                        dtype=float)
    if f_true.shape != (n, 3):
        raise ValueError(f"truth returned shape {f_true.shape}, expected ({n}, 3)")
    mass = vehicle.mass.mass_kg
    F_true = f_true * mass
    sd = noise.sigma_abs_N + noise.sigma_rel * np.abs(F_true)
    F_meas = F_true + sd * rng.standard_normal((n, 3))
    data = ForceBalanceData(
        airspeed_mps=pts["airspeed_mps"], alpha_rad=pts["alpha_deg"] * deg,
        beta_rad=pts["beta_deg"] * deg, throttle_x_pct=pts["throttle_x_pct"],
        throttle_z_pct=pts["throttle_z_pct"], force_B_N=F_meas, air_density_kgpm3=rho_rows,
        mass_kg=mass, wing_on=pts["wing_on"], source=f"virtual tunnel ({vehicle.name})")
    return TunnelRun(data=data, truth=coeffs, noise=noise, design=design, vehicle_name=vehicle.name,
                     seed=seed, perturbed=bool(perturb))


def truth_path_for(csv_path: str | Path) -> Path:
    """The side file that goes with a tunnel CSV: ``DATA.csv`` -> ``DATA.truth.json``."""
    p = Path(csv_path)
    return p.with_name(p.stem + ".truth.json")


def write_tunnel_run(run: TunnelRun, csv_path: str | Path) -> tuple[Path, Path]:
    """Write the run's CSV and its side file (true coefficients, noise model, design)."""
    csv_path = Path(csv_path)
    comments = [f"vtoladapt virtual wind tunnel, vehicle {run.vehicle_name}, seed {run.seed}",
                f"noise per axis: {run.noise.sigma_abs_N:g} N + {100 * run.noise.sigma_rel:g} % of reading",
                f"true coefficients: {truth_path_for(csv_path).name}"]
    write_force_balance_csv(csv_path, run.data, comments)
    side = truth_path_for(csv_path)
    side.write_text(json.dumps(run.truth_info(), indent=2) + "\n", encoding="utf-8")
    return csv_path, side


def read_truth(path: str | Path) -> dict:
    """Read a tunnel side file; returns its dict with ``theta_table`` (8,) added when present."""
    path = Path(path)
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FitDataError(f"{path}: file not found") from None
    except json.JSONDecodeError as exc:
        raise FitDataError(f"{path}: not valid JSON: {exc}") from None
    if info.get("format") != TRUTH_FORMAT:
        raise FitDataError(f"{path}: format = {info.get('format')!r}: expected {TRUTH_FORMAT!r}")
    c = info.get("coefficients")
    if c is not None:
        info["theta_table"] = np.array([c[n] for n in PARAMETER_NAMES], float)
    return info


__all__ = ["BalanceNoise", "TRUTH_FORMAT", "TruthFunction", "TunnelDesign", "TunnelRun",
           "design_points", "linear_model_truth", "make_design", "read_truth",
           "regressor_for_rows", "run_virtual_tunnel", "true_coefficients", "truth_path_for",
           "write_tunnel_run"]
