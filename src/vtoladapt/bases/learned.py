"""The learned basis: ``Phi(x) = [Phi_physics(x) | phi_net(x)]``, the extended physics columns and a learned block.

The first 13 columns are the extended physics basis's (:mod:`.extended`: the paper's eight first,
so the attitude, the flow-angle protection and the allocation keep inverting the physics); the
last ``h`` are a small network's outputs, ``phi_net(x)`` (3 x h), trained offline from flight logs
by meta-learning (``vtoladapt learn-basis``, :mod:`vtoladapt.learn`): every flight has its own
linear weights, the network is shared. Online the adaptation adapts all ``13 + h`` weights
linearly, as for any basis; the learned weights have their own prior (the mean and spread of the
per-flight weights the training solved, scaled by ``net_std_scale``), P0 and bounds.

The network is evaluated here, in the compiled regressor, from the weights in the basis's
constants block (no deep-learning framework at run time): 16 features of the input block
(:data:`.netfile.FEATURES`), normalised, two ``tanh`` layers and a linear output. The file
(:mod:`.netfile`) is the vehicle's shipped one (``bases/trained/<vehicle>.npz``) unless
``[basis_settings.learned] file`` names another; a file trained on another vehicle is refused
unless ``allow_other_vehicle = true`` (the held-out-airframe evaluation sets it).
"""
from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from .. import forces
from ..config import ConfigError, Validated, setting
from ..layout import BlockLayout, Field
from . import IN_FLOW, IN_OMEGA_B, IN_Q_WB, IN_U, IN_V_I_B, IN_V_I_VALID, BasisSpec, extended, regressor_kernel
from .netfile import (FT_AIRSPEED, FT_COS_ALPHA, FT_G_B, FT_OMEGA_B, FT_SIGMA, FT_SIN_ALPHA, FT_U, FT_V_I_B, FT_VALID,
                      N_FEATURES, NetFile, read_net)

TRAINED_DIR = Path(__file__).with_name("trained")
"""The shipped basis files, one per vehicle family (``<vehicle name>.npz``)."""

HEADER = BlockLayout("learned basis header", [
    Field("N_PHYS", 1, "-", "physics columns (the extended basis's 13)"),
    Field("H", 1, "-", "learned columns h"),
    Field("H1", 1, "-", "first hidden layer's width"),
    Field("H2", 1, "-", "second hidden layer's width"),
    Field("OFF_MEAN", 1, "-", "offset of x_mean in the block"),
    Field("OFF_STD", 1, "-", "offset of x_std"),
    Field("OFF_W1", 1, "-", "offset of W1 (H1 x F, row-major)"),
    Field("OFF_B1", 1, "-", "offset of b1"),
    Field("OFF_W2", 1, "-", "offset of W2 (H2 x H1)"),
    Field("OFF_B2", 1, "-", "offset of b2"),
    Field("OFF_W3", 1, "-", "offset of W3 (3 h x H2)"),
    Field("OFF_B3", 1, "-", "offset of b3"),
])
"""Fixed header after the extended basis's constants: the network's sizes and where its arrays are
(those offsets come from :func:`weights_layout`, a BlockLayout sized by the file)."""
HEADER_AT = extended.BLOCK.size
"""The header follows the extended basis's constants in the block."""
(H_N_PHYS, H_H, H_H1, H_H2, H_MEAN, H_STD, H_W1, H_B1, H_W2, H_B2, H_W3, H_B3) = tuple(
    HEADER_AT + o for o in HEADER.offsets(*(f.name for f in HEADER.fields)))


def weights_layout(net: NetFile) -> BlockLayout:
    """The network's arrays after the header, sized by ``net``."""
    H1, H2 = net.hidden
    return BlockLayout("learned basis weights", [
        Field("X_MEAN", N_FEATURES, "-", "feature means"), Field("X_STD", N_FEATURES, "-", "feature spreads"),
        Field("W1", H1 * N_FEATURES, "-", "layer 1"), Field("B1", H1, "-", "layer 1 bias"),
        Field("W2", H2 * H1, "-", "layer 2"), Field("B2", H2, "-", "layer 2 bias"),
        Field("W3", 3 * net.h * H2, "-", "output layer"), Field("B3", 3 * net.h, "-", "output bias"),
    ])


@dataclass(frozen=True)
class Settings(Validated):
    """The learned basis's own settings (the vehicle file's ``[basis_settings.learned]``)."""

    config_section = "basis_settings.learned"

    file: str = setting("-", "trained basis file (.npz); '' = the shipped one for the vehicle "
                        "(vtoladapt/bases/trained/<vehicle>.npz)", default="")
    allow_other_vehicle: bool = setting("-", "fly a file trained on another vehicle (held-out-airframe "
                                        "evaluation)", default=False)
    net_std_scale: float = setting("-", "the learned weights' prior std = this x their spread over the "
                                   "training flights", default=1.0, gt=0.0, le=100.0)
    net_P0: float = setting("adaptation units", "initial adaptation gain of each learned weight (chosen on tuning "
                            "draws, seed 3333: README)", default=0.002,
                            gt=0.0, le=1e6)


def shipped_architectures() -> tuple[tuple[int, int, int], ...]:
    """``(h, H1, H2)`` of the shipped files (:data:`TRAINED_DIR`), distinct, sorted: the sizes the compiled
    code is specialised for (:data:`SHIPPED_ARCHITECTURE`, :data:`vtoladapt.control.sizes.SPECIALISED_N`)."""
    found = set()
    for path in sorted(TRAINED_DIR.glob("*.npz")):
        try:
            net = read_net(path)
        except ConfigError:
            # a file being rewritten (training) must not stop the package from importing: its size just
            # runs the generic loops, and the test of the shipped files fails on it
            continue
        found.add((net.h, *net.hidden))
    return tuple(sorted(found))


SHIPPED_ARCHITECTURE = (shipped_architectures() or ((0, 0, 0),))[0]
"""``(h, H1, H2)`` of the shipped networks (one architecture for every vehicle family; ``(0, 0, 0)`` if
none): :func:`net_columns` runs it with constant sizes. Frozen into the compiled code when it is cached,
like :data:`vtoladapt.control.sizes.SPECIALISED_N`."""
SHIPPED_H = SHIPPED_ARCHITECTURE[0]
SHIPPED_H1 = SHIPPED_ARCHITECTURE[1]
SHIPPED_H2 = SHIPPED_ARCHITECTURE[2]


def net_path(vehicle, settings: Settings) -> Path:
    """The file ``settings`` names, relative paths against the vehicle file's folder; or the shipped one."""
    if settings.file:
        p = Path(os.path.expanduser(settings.file))
        if not p.is_absolute() and getattr(vehicle, "source_path", ""):
            p = Path(vehicle.source_path).parent / p
        return p
    return TRAINED_DIR / f"{vehicle.name}.npz"


@functools.lru_cache(maxsize=16)
def _read_cached(path: str, mtime_ns: int, size: int) -> NetFile:
    return read_net(path)


def load_net(vehicle, settings: Settings) -> NetFile:
    """The network for ``vehicle`` (read once per file version), checked against the vehicle."""
    path = net_path(vehicle, settings)
    if not settings.file and not path.is_file():
        raise ConfigError(f"{getattr(vehicle, 'source_path', '') or vehicle.name}: [basis_settings.learned] "
                          f"file = '': no shipped learned basis for vehicle {vehicle.name!r}; allowed: a vehicle "
                          f"of {sorted(p.stem for p in TRAINED_DIR.glob('*.npz'))} or a file "
                          "trained with `vtoladapt learn-basis`")
    st = path.stat() if path.is_file() else None
    net = _read_cached(str(path), st.st_mtime_ns if st else 0, st.st_size if st else 0)
    if net.physics != "extended":
        raise ConfigError(f"{path}: physics = {net.physics!r}; allowed: 'extended'")
    if net.vehicle != vehicle.name and not settings.allow_other_vehicle:
        raise ConfigError(f"{path}: vehicle = {net.vehicle!r}: trained on another vehicle's flights, flown on "
                          f"{vehicle.name!r}; allowed: {vehicle.name!r} (or [basis_settings.learned] "
                          "allow_other_vehicle = true)")
    return net


def pack_block(physics_block: np.ndarray, net: NetFile) -> np.ndarray:
    """The regressor's constants: the extended basis's, the header, the network's arrays."""
    wl = weights_layout(net)
    base = extended.BLOCK.size + HEADER.size
    off = {name: base + o for name, o in zip(("X_MEAN", "X_STD", "W1", "B1", "W2", "B2", "W3", "B3"),
                                             wl.offsets("X_MEAN", "X_STD", "W1", "B1", "W2", "B2", "W3", "B3"))}
    H1, H2 = net.hidden
    header = HEADER.pack(N_PHYS=extended.N, H=net.h, H1=H1, H2=H2, OFF_MEAN=off["X_MEAN"], OFF_STD=off["X_STD"],
                         OFF_W1=off["W1"], OFF_B1=off["B1"], OFF_W2=off["W2"], OFF_B2=off["B2"], OFF_W3=off["W3"],
                         OFF_B3=off["B3"])
    weights = wl.pack(X_MEAN=net.x_mean, X_STD=net.x_std, W1=net.W1.ravel(), B1=net.b1, W2=net.W2.ravel(),
                      B2=net.b2, W3=net.W3.ravel(), B3=net.b3)
    return np.concatenate([physics_block, header, weights])


def net_names(h: int) -> tuple[str, ...]:
    """The learned weights' parameter names, ``net0 .. net{h-1}`` (the log's ``theta_hat_net<j>`` columns)."""
    return tuple(f"net{j}" for j in range(h))


def describe(vehicle, settings: Settings) -> BasisSpec:
    """The extended basis for ``vehicle`` with the file's ``h`` learned columns appended."""
    from . import basis_settings

    # the physics columns' priors: the vehicle file's [basis_settings.extended], as when that basis flies
    p = extended.describe(vehicle, basis_settings("extended", vehicle))
    net = load_net(vehicle, settings)
    h = net.h
    std = np.maximum(settings.net_std_scale * net.theta_std, 1e-6)
    return BasisSpec(
        id="learned", names=p.names + net_names(h), units=p.units + ("m/s²",) * h,
        scaled_units=p.scaled_units + ("m/s²",) * h, scale=np.append(p.scale, np.ones(h)),
        theta_table=np.append(p.theta_table, net.theta_mean), std_table=np.append(p.std_table, std),
        P0_diag=np.append(p.P0_diag, np.full(h, settings.net_P0)), bound_fraction=np.append(p.bound_fraction,
                                                                                        np.ones(h)),
        bound_sigmas=p.bound_sigmas, sign=np.append(p.sign, np.zeros(h)), wing=np.append(p.wing, np.zeros(h, bool)),
        trained_spread=np.append(np.zeros(p.n, bool), np.ones(h, bool)),
        block=pack_block(p.block, net), regressor=regressor, work_size=N_FEATURES + sum(net.hidden),
        physics=p.physics + f" A learned block of {h} columns (a {N_FEATURES}-{net.hidden[0]}-{net.hidden[1]}-{3 * h} "
        "tanh network of the measured flow, throttles, attitude and rates).",
        source=p.source + f"; learned block: {net_path(vehicle, settings)} (trained on {net.vehicle}, "
        f"{len(net.meta.get('draws', []))} flights)")


def parameter_names(block) -> tuple[str, ...]:
    """The extended basis's 13, then ``net0 .. net{h-1}``."""
    return extended.parameter_names(block) + net_names(int(block[H_H]))


@njit(cache=True, inline="always")
def features_into(x, work) -> None:
    """The features (:data:`.netfile.FEATURE_LAYOUT`) into ``work[0:N_FEATURES]`` (twin of
    :func:`.netfile.features_rows`)."""
    f = IN_FLOW
    for i in range(3):
        work[FT_V_I_B + i] = x[IN_V_I_B + i]
        work[FT_OMEGA_B + i] = x[IN_OMEGA_B + i]
    work[FT_AIRSPEED] = x[f + forces.F_V]
    work[FT_VALID] = x[IN_V_I_VALID]
    work[FT_U] = x[IN_U]
    work[FT_U + 1] = x[IN_U + 1]
    work[FT_SIN_ALPHA] = x[f + forces.F_SIN_ALPHA]
    work[FT_COS_ALPHA] = x[f + forces.F_COS_ALPHA]
    work[FT_SIGMA] = x[f + forces.F_SIGMA]
    w, qx, qy, qz = x[IN_Q_WB], x[IN_Q_WB + 1], x[IN_Q_WB + 2], x[IN_Q_WB + 3]
    work[FT_G_B] = 2.0 * (qx * qz - w * qy)
    work[FT_G_B + 1] = 2.0 * (qy * qz + w * qx)
    work[FT_G_B + 2] = w * w - qx * qx - qy * qy + qz * qz


@njit(cache=True, inline="always")
def net_columns(block, x, phi, n, work) -> None:
    """The network's ``3 x h`` outputs as the columns after the physics ones (``block[N_PHYS]``) of ``phi``.

    The shipped architecture (:data:`SHIPPED_ARCHITECTURE`) runs with its sizes as constants (loops of
    constant length, 1.6 times as fast), any other with the same code at run-time sizes: the same sums in
    the same order, so the same numbers bit for bit.
    """
    h = int(block[H_H])
    H1 = int(block[H_H1])
    H2 = int(block[H_H2])
    if h == SHIPPED_H and H1 == SHIPPED_H1 and H2 == SHIPPED_H2:
        _net(block, x, phi, n, work, SHIPPED_H, SHIPPED_H1, SHIPPED_H2)
    else:
        _net(block, x, phi, n, work, h, H1, H2)


@njit(cache=True, inline="always")
def _net(block, x, phi, n, work, h, H1, H2) -> None:
    """The body of :func:`net_columns` for a network of ``h`` outputs per axis and hidden widths ``H1``, ``H2``."""
    F = N_FEATURES
    n_phys = int(block[H_N_PHYS])
    om, osd = int(block[H_MEAN]), int(block[H_STD])
    ow1, ob1, ow2, ob2 = int(block[H_W1]), int(block[H_B1]), int(block[H_W2]), int(block[H_B2])
    ow3, ob3 = int(block[H_W3]), int(block[H_B3])
    features_into(x, work)
    # contiguous views of each array, taken once: the loops then index from a base that does not move
    # (about a third faster than offsets added inside every loop)
    x_mean, x_std = block[om:om + F], block[osd:osd + F]
    W1, b1 = block[ow1:ow1 + H1 * F], block[ob1:ob1 + H1]
    W2, b2 = block[ow2:ow2 + H2 * H1], block[ob2:ob2 + H2]
    W3, b3 = block[ow3:ow3 + 3 * h * H2], block[ob3:ob3 + 3 * h]
    z, a1, a2 = work[0:F], work[F:F + H1], work[F + H1:F + H1 + H2]
    for i in range(F):
        z[i] = (z[i] - x_mean[i]) / x_std[i]
    # each hidden layer's sums first, then its tanh (a loop without calls, then one of calls)
    for j in range(H1):
        s = b1[j]
        for i in range(F):
            s += W1[j * F + i] * z[i]
        a1[j] = s
    for j in range(H1):
        a1[j] = np.tanh(a1[j])
    for j in range(H2):
        s = b2[j]
        for i in range(H1):
            s += W2[j * H1 + i] * a1[i]
        a2[j] = s
    for j in range(H2):
        a2[j] = np.tanh(a2[j])
    for o in range(3 * h):
        s = b3[o]
        for i in range(H2):
            s += W3[o * H2 + i] * a2[i]
        # output o is row o // h (body axis), learned column o % h
        phi[(o // h) * n + n_phys + (o % h)] = s


@regressor_kernel
def regressor(block, x, phi, work):
    """The extended physics columns, then the network's."""
    n = int(block[H_N_PHYS]) + int(block[H_H])
    extended.extended_columns(block, x, phi, n)
    net_columns(block, x, phi, n, work)
