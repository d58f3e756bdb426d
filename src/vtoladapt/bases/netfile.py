"""The learned basis's file: a small network's weights, its input normalisation and where it came from.

One ``.npz`` file (numpy's archive, read with ``allow_pickle=False``: no code in it) per trained
basis. Arrays: ``x_mean``, ``x_std`` (the input normalisation, one entry per feature of
:data:`FEATURES`), ``W1 (H1, F)``, ``b1``, ``W2 (H2, H1)``, ``b2``, ``W3 (3 h, H2)``, ``b3`` (the
network ``phi_net(x) = W3 tanh(W2 tanh(W1 z + b1) + b2) + b3`` with ``z = (x - x_mean) / x_std``,
output reshaped row-major to 3 x h: body axes by learned column), ``theta_mean``, ``theta_std``
(the prior of the h learned weights: the mean and spread of the per-flight weights the training
solved) and ``meta``, one JSON string: ``format``, ``vehicle`` (the vehicle family it was trained
on), ``physics`` (the physics basis whose columns come first), ``features`` (the input names, in
order), ``command`` and ``seed`` that made it, ``draws`` (the flights it was trained on), the
training's own settings and measured numbers.

:func:`read_net` refuses, in one line naming the file, a file that is not such an archive, a
wrong shape, a non-finite weight, a format it does not know, or inputs other than
:data:`FEATURES` (another vehicle's or another version's inputs); the vehicle check is the
basis's (:mod:`.learned`), which knows the vehicle it flies.
"""
from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config import ConfigError
from ..layout import BlockLayout, Field

FORMAT = "vtoladapt-learned-basis-1"
"""The file format this module reads and writes."""

FEATURE_LAYOUT = BlockLayout("learned basis features", [
    Field("V_I_B", 3, "m/s", "incident velocity the controller uses, body FRD", ("v_i_x_mps", "v_i_y_mps", "v_i_z_mps")),
    Field("AIRSPEED", 1, "m/s", "its norm", ("airspeed_mps",)),
    Field("VALID", 1, "-", "1 if the probe gave it", ("probe_valid",)),
    Field("U", 2, "-", "throttles through the nominal motor lag", ("u_x_frac", "u_z_frac")),
    Field("SIN_ALPHA", 1, "-", "sine of the flow's angle of attack", ("sin_alpha",)),
    Field("COS_ALPHA", 1, "-", "its cosine", ("cos_alpha",)),
    Field("SIGMA", 1, "-", "the model's stall weight", ("stall_weight",)),
    Field("G_B", 3, "-", "gravity direction in body axes (third row of R_WB)", ("g_x_B", "g_y_B", "g_z_B")),
    Field("OMEGA_B", 3, "rad/s", "body rate, FRD", ("omega_x_radps", "omega_y_radps", "omega_z_radps")),
])
"""The network's inputs, all from the basis input block (:data:`vtoladapt.bases.INPUT`): the incident
flow the controller uses (body) and its airspeed, whether the probe gave it, the throttles, the
flow's angle of attack (sine, cosine) and the model's stall weight, the gravity direction in body
axes (from the attitude: the heading is left out, it says nothing about the force) and the body
rates. Never the accelerometer."""
FEATURES = tuple(c for f in FEATURE_LAYOUT.fields for c in f.column_names)
"""The features' names, in order (a basis file states them; another list is refused)."""
N_FEATURES = FEATURE_LAYOUT.size
(FT_V_I_B, FT_AIRSPEED, FT_VALID, FT_U, FT_SIN_ALPHA, FT_COS_ALPHA, FT_SIGMA, FT_G_B, FT_OMEGA_B) = \
    FEATURE_LAYOUT.offsets(*(f.name for f in FEATURE_LAYOUT.fields))
ARRAYS = ("x_mean", "x_std", "W1", "b1", "W2", "b2", "W3", "b3", "theta_mean", "theta_std")


@dataclass(frozen=True, eq=False)
class NetFile:
    """A learned basis's network and its metadata (:func:`read_net`, :func:`write_net`)."""

    x_mean: np.ndarray
    x_std: np.ndarray
    W1: np.ndarray
    b1: np.ndarray
    W2: np.ndarray
    b2: np.ndarray
    W3: np.ndarray
    b3: np.ndarray
    theta_mean: np.ndarray
    theta_std: np.ndarray
    meta: dict = field(default_factory=dict)

    @property
    def h(self) -> int:
        """Number of learned columns."""
        return self.W3.shape[0] // 3

    @property
    def hidden(self) -> tuple[int, int]:
        """Widths of the two hidden layers."""
        return self.W1.shape[0], self.W2.shape[0]

    @property
    def vehicle(self) -> str:
        """The vehicle family the network was trained on."""
        return str(self.meta.get("vehicle", ""))

    @property
    def physics(self) -> str:
        """The physics basis whose columns come before the network's."""
        return str(self.meta.get("physics", ""))

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays by name (:data:`ARRAYS`), as the file stores them."""
        return {k: getattr(self, k) for k in ARRAYS}


def check_shapes(net: NetFile, where: str) -> None:
    """Raise ConfigError (one line, ``where`` first) if the arrays do not fit together or are not finite."""
    F = N_FEATURES
    H1, H2 = net.W1.shape[0] if net.W1.ndim == 2 else -1, net.W2.shape[0] if net.W2.ndim == 2 else -1
    h3 = net.W3.shape[0] if net.W3.ndim == 2 else -1
    expected = {"x_mean": (F,), "x_std": (F,), "W1": (H1, F), "b1": (H1,), "W2": (H2, H1), "b2": (H2,),
                "W3": (h3, H2), "b3": (h3,), "theta_mean": (h3 // 3,), "theta_std": (h3 // 3,)}
    for name in ARRAYS:
        a = getattr(net, name)
        if a.shape != expected[name] or min(H1, H2, h3) < 1 or h3 % 3:
            raise ConfigError(f"{where}: {name} has shape {a.shape}; allowed: {expected[name]} (W1 (H1, {F}), "
                              f"W2 (H2, H1), W3 (3 h, H2), h >= 1)")
        if not np.all(np.isfinite(a)):
            raise ConfigError(f"{where}: {name} holds {int(np.size(a) - np.count_nonzero(np.isfinite(a)))} "
                              "non-finite values; allowed: finite numbers")
    for name in ("x_std", "theta_std"):
        a = getattr(net, name)
        if not np.all(a > 0.0):
            raise ConfigError(f"{where}: {name} = {a.tolist()} has entries <= 0; allowed: > 0")


def read_net(path: str | Path) -> NetFile:
    """Read and check a learned basis file; a bad one is a one-line :class:`ConfigError`."""
    path = Path(path)
    where = str(path)
    if not path.is_file():
        raise ConfigError(f"{where}: learned basis file not found")
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: np.array(z[k]) for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ConfigError(f"{where}: not a learned basis file (numpy .npz): {str(exc).splitlines()[0]}") from None
    missing = [k for k in ARRAYS + ("meta",) if k not in data]
    if missing:
        raise ConfigError(f"{where}: not a learned basis file: missing {', '.join(missing)}")
    try:
        meta = json.loads(str(data["meta"]))
    except ValueError as exc:
        raise ConfigError(f"{where}: meta is not JSON: {exc}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else meta
        raise ConfigError(f"{where}: format = {got!r}; allowed: {FORMAT!r}")
    features = tuple(meta.get("features", ()))
    if features != FEATURES:
        raise ConfigError(f"{where}: features = {list(features)}: inputs this version does not compute; "
                          f"allowed: {list(FEATURES)}")
    net = NetFile(**{k: np.ascontiguousarray(data[k], dtype=float) for k in ARRAYS}, meta=meta)
    check_shapes(net, where)
    return net


def write_net(path: str | Path, net: NetFile) -> Path:
    """Write ``net`` to ``path`` (checked first; written to a temporary name, then renamed: never half-written)."""
    path = Path(path)
    meta = {"format": FORMAT, "features": list(FEATURES), **{k: v for k, v in net.meta.items()
                                                               if k not in ("format", "features")}}
    check_shapes(net, str(path))
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as fh:
        np.savez(fh, meta=np.array(json.dumps(meta, sort_keys=True)), **net.arrays())
    tmp.replace(path)
    return path


def features_rows(x: np.ndarray) -> np.ndarray:
    """:data:`FEATURES` (N, F) of basis input rows ``x`` (N, INPUT.size): the numpy twin of the compiled
    :func:`vtoladapt.bases.learned.features_into` (the tests hold the two equal)."""
    from . import IN_FLOW, IN_OMEGA_B, IN_Q_WB, IN_U, IN_V_I_B, IN_V_I_VALID
    from ..forces import F_COS_ALPHA, F_SIGMA, F_SIN_ALPHA, F_V

    x = np.atleast_2d(x)
    q = x[:, IN_Q_WB:IN_Q_WB + 4]
    w, qx, qy, qz = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    z = np.empty((x.shape[0], N_FEATURES))
    z[:, FT_V_I_B:FT_V_I_B + 3] = x[:, IN_V_I_B:IN_V_I_B + 3]
    z[:, FT_AIRSPEED] = x[:, IN_FLOW + F_V]
    z[:, FT_VALID] = x[:, IN_V_I_VALID]
    z[:, FT_U:FT_U + 2] = x[:, IN_U:IN_U + 2]
    z[:, FT_SIN_ALPHA] = x[:, IN_FLOW + F_SIN_ALPHA]
    z[:, FT_COS_ALPHA] = x[:, IN_FLOW + F_COS_ALPHA]
    z[:, FT_SIGMA] = x[:, IN_FLOW + F_SIGMA]
    # third row of R_WB (world down in body axes): the gravity direction the accelerometer does not see
    z[:, FT_G_B] = 2.0 * (qx * qz - w * qy)
    z[:, FT_G_B + 1] = 2.0 * (qy * qz + w * qx)
    z[:, FT_G_B + 2] = w * w - qx * qx - qy * qy + qz * qz
    z[:, FT_OMEGA_B:FT_OMEGA_B + 3] = x[:, IN_OMEGA_B:IN_OMEGA_B + 3]
    return z


def forward(net_arrays: dict[str, Any], z: np.ndarray) -> tuple[np.ndarray, tuple]:
    """The network on normalised features ``z`` (N, F): output (N, 3 h) and the hidden activations
    ``(a1, a2)`` the training's backward pass needs. Float64 throughout."""
    a1 = np.tanh(z @ net_arrays["W1"].T + net_arrays["b1"])
    a2 = np.tanh(a1 @ net_arrays["W2"].T + net_arrays["b2"])
    return a2 @ net_arrays["W3"].T + net_arrays["b3"], (a1, a2)


def net_rows(net: NetFile, x: np.ndarray) -> np.ndarray:
    """``phi_net`` (N, 3, h) at basis input rows ``x`` in numpy (the training's forward pass)."""
    z = (features_rows(x) - net.x_mean) / net.x_std
    out, _ = forward(net.arrays(), z)
    return out.reshape(-1, 3, net.h)
