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

:func:`read_net` opens only the members it needs, each checked from the zip directory and its npy
header before a byte of data is decompressed, and refuses in one line naming the file and the member:

* a file that is not a zip archive (a ``.npy`` saved under a ``.npz`` name, a truncated archive), one
  larger than :data:`MAX_FILE_BYTES`, a missing member, or a member larger than its architecture allows
  (the zip directory's size: a highly compressible member is refused without being inflated);
* an array that is not float64 or float32 (complex, bool, integer, float16, text and object arrays are
  refused, object arrays never unpickled), of the wrong shape, or whose sizes exceed the architecture's
  caps (``h`` <= :data:`MAX_H`, hidden widths <= :data:`MAX_HIDDEN`: ``learn-basis``'s own caps);
* a non-finite value or one beyond its bound (:data:`BOUNDS`);
* a ``meta`` that is not a JSON object of the expected types (``format``, ``features``, ``vehicle``,
  ``physics``, ``draws``...), nested deeper than :data:`MAX_JSON_DEPTH` or larger than
  :data:`MAX_META_BYTES`, a format it does not know, or inputs other than :data:`FEATURES`.

The vehicle check is the basis's (:mod:`.learned`), which knows the vehicle it flies. :func:`write_net`
applies the same checks before writing, and writes atomically (a temporary file in the target's folder,
renamed; removed on any failure).
"""
from __future__ import annotations

import json
import os
import zipfile
import zlib
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


MAX_H = 30
"""Learned columns a file may have: ``learn-basis --h``'s cap."""
MAX_HIDDEN = 256
"""Width a hidden layer may have: ``learn-basis --hidden``'s cap (a 2000-wide file made a 2 s run take 4 s)."""
FEATURE_BOUND = 1e3
"""``|x_mean|`` and ``x_std`` at most this: the features are speeds (m/s), rates (rad/s) and numbers within +-1;
a mean or spread of a thousand m/s or rad/s is no flight's."""
X_STD_MIN = 1e-6
"""x_std at least this (training floors it at 1e-3, :data:`vtoladapt.learn.basis.FEATURE_STD_FLOOR`): a
smaller spread turns any input into an overflow of the normalised feature."""
WEIGHT_BOUND = 1e3
"""``|W1|``, ``|b1|``, ``|W2|``, ``|b2|``, ``|W3|``, ``|b3|`` at most this: weight decay keeps trained weights of order one (the
shipped files' largest is 0.9); the tanh layers saturate long before. With it the network's every output
is within ``(H2 + 1) WEIGHT_BOUND``."""
THETA_BOUND = 1e3
"""``|theta_mean|`` and ``theta_std`` at most this (m/s^2 per unit of the network's output; the shipped files'
largest is 2.7): the learned block's force stays finite at every step of the adaptation (``theta_mean`` x
1e300 passed the old check and divided by zero inside the compiled loop)."""
BOUNDS = {"x_mean": (-FEATURE_BOUND, FEATURE_BOUND), "x_std": (X_STD_MIN, FEATURE_BOUND),
          **{k: (-WEIGHT_BOUND, WEIGHT_BOUND) for k in ("W1", "b1", "W2", "b2", "W3", "b3")},
          "theta_mean": (-THETA_BOUND, THETA_BOUND), "theta_std": (0.0, THETA_BOUND)}
"""Each array's closed range ``(low, high)``; theta_std must also be > 0."""
MAX_META_BYTES = 32 * 2**20
"""``meta`` as numpy stores it (4 bytes a character): about 7000 flights' draw records."""
MAX_JSON_DEPTH = 32
"""Nesting ``meta`` may have (the files written have 4)."""
MAX_NPY_HEADER = 4096
"""Bytes an npy member's header may take (numpy writes 128)."""
MAX_FILE_BYTES = MAX_META_BYTES + 16 * 2**20
"""A file larger than this is refused before its zip directory is read."""
_MAX_ELEMENTS = {"x_mean": N_FEATURES, "x_std": N_FEATURES, "W1": MAX_HIDDEN * N_FEATURES, "b1": MAX_HIDDEN,
                 "W2": MAX_HIDDEN * MAX_HIDDEN, "b2": MAX_HIDDEN, "W3": 3 * MAX_H * MAX_HIDDEN, "b3": 3 * MAX_H,
                 "theta_mean": MAX_H, "theta_std": MAX_H}
ARCHITECTURE = (f"x_mean, x_std ({N_FEATURES},), W1 (H1, {N_FEATURES}), b1 (H1,), W2 (H2, H1), b2 (H2,), "
                "W3 (3 h, H2), b3 (3 h,), theta_mean, theta_std (h,)")


def _architecture(shapes: dict[str, tuple], where: str, member: str = "") -> dict[str, tuple]:
    """Every array's expected shape, from W1, W2 and W3's; one-line ConfigError naming the array at fault
    (``member``: "member " when the arrays are a file's)."""
    F = N_FEATURES

    def matrix(name, cols, cols_text, rows_cap, rows_text):
        shape = shapes[name]
        if len(shape) == 2 and 1 <= shape[0] <= rows_cap and shape[1] != cols:
            raise ConfigError(f"{where}: {member}{name} has shape {shape}; allowed: {(shape[0], cols)} ({ARCHITECTURE})")
        if len(shape) != 2 or not 1 <= shape[0] <= rows_cap:
            raise ConfigError(f"{where}: {member}{name} has shape {shape}; allowed: ({rows_text}, {cols_text}) with "
                              f"1 <= {rows_text} <= {rows_cap} ({ARCHITECTURE})")
        return shape[0]

    H1 = matrix("W1", F, str(F), MAX_HIDDEN, "H1")
    H2 = matrix("W2", H1, f"H1 = {H1}", MAX_HIDDEN, "H2")
    h3 = matrix("W3", H2, f"H2 = {H2}", 3 * MAX_H, "3 h")
    if h3 % 3:
        raise ConfigError(f"{where}: {member}W3 has shape {shapes['W3']}: {h3} rows; allowed: a multiple of 3 (3 h rows, "
                          f"one per body axis and learned column)")
    return {"x_mean": (F,), "x_std": (F,), "W1": (H1, F), "b1": (H1,), "W2": (H2, H1), "b2": (H2,),
            "W3": (h3, H2), "b3": (h3,), "theta_mean": (h3 // 3,), "theta_std": (h3 // 3,)}


def _check_shapes(shapes: dict[str, tuple], where: str, member: str = "") -> None:
    expected = _architecture(shapes, where, member)
    for name in ARRAYS:
        if shapes[name] != expected[name]:
            H1, H2, h = expected["W1"][0], expected["W2"][0], expected["theta_mean"][0]
            raise ConfigError(f"{where}: {member}{name} has shape {shapes[name]}; allowed: {expected[name]} (from W1, W2, "
                              f"W3: H1 = {H1}, H2 = {H2}, h = {h})")


def _check_values(name: str, a: np.ndarray, where: str, member: str = "") -> None:
    """Finite and within :data:`BOUNDS` (theta_std also > 0)."""
    bad = np.size(a) - np.count_nonzero(np.isfinite(a))
    if bad:
        raise ConfigError(f"{where}: {member}{name} holds {bad} non-finite values; allowed: finite numbers")
    lo, hi = BOUNDS[name]
    if a.size and (a.min() < lo or a.max() > hi or (name == "theta_std" and a.min() <= 0.0)):
        worst = a.min() if a.min() < lo or (name == "theta_std" and a.min() <= 0.0) else a.max()
        low = "> 0" if name == "theta_std" else f">= {lo:g}"
        raise ConfigError(f"{where}: {member}{name} holds {float(worst):.6g}; allowed: {low} and <= {hi:g} (the bounds of "
                          "vtoladapt.bases.netfile.BOUNDS)")


def check_shapes(net: NetFile, where: str) -> None:
    """Raise ConfigError (one line, ``where`` first) if the arrays do not fit together, are not finite or are
    beyond their bounds (:data:`BOUNDS`)."""
    _check_shapes({k: tuple(np.shape(getattr(net, k))) for k in ARRAYS}, where)
    for name in ARRAYS:
        _check_values(name, np.asarray(getattr(net, name)), where)


def _json_depth(obj) -> int:
    """Nesting depth of parsed JSON (iterative: a deep value must not exhaust the stack here either)."""
    depth, stack = 0, [(obj, 1)]
    while stack:
        o, d = stack.pop()
        if isinstance(o, (dict, list)):
            depth = max(depth, d)
            if depth > MAX_JSON_DEPTH:
                return depth
            stack.extend((v, d + 1) for v in (o.values() if isinstance(o, dict) else o))
    return depth


_META_TYPES = {"vehicle": (str, "text"), "physics": (str, "text"), "command": (str, "text"),
               "draws": (list, "a list"), "settings": (dict, "a table"), "summary": (dict, "a table"),
               "held_out": (dict, "a table")}


def check_meta(meta, where: str) -> dict:
    """``meta`` (parsed) as the file must hold it; a one-line ConfigError naming the key otherwise."""
    if not isinstance(meta, dict):
        raise ConfigError(f"{where}: JSON {type(meta).__name__}; allowed: a JSON object")
    if meta.get("format") != FORMAT:
        raise ConfigError(f"{where}: format = {_shown(meta.get('format'))}; allowed: {FORMAT!r}")
    features = meta.get("features")
    if not isinstance(features, list) or tuple(features) != FEATURES:
        raise ConfigError(f"{where}: features = {_shown(features, 400)}: inputs this version does not compute; "
                          f"allowed: {list(FEATURES)}")
    for key in ("vehicle", "physics"):
        if key not in meta:
            raise ConfigError(f"{where}: no {key}; allowed: a basis file written by learn-basis")
    for key, (tp, text) in _META_TYPES.items():
        if key in meta and not isinstance(meta[key], tp):
            raise ConfigError(f"{where}: {key} = {_shown(meta[key])}; allowed: {text}")
    seed = meta.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
        raise ConfigError(f"{where}: seed = {_shown(seed)}; allowed: a whole number or null")
    return meta


def _shown(value, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 20] + "..." + text[-10:]


def _npy_header(zf: zipfile.ZipFile, info: zipfile.ZipInfo) -> tuple[tuple, bool, np.dtype]:
    """``(shape, fortran_order, dtype)`` of an npy member, read from its header only."""
    from numpy.lib import format as npy

    with zf.open(info) as fp:
        version = npy.read_magic(fp)
        if version == (1, 0):
            return npy.read_array_header_1_0(fp, max_header_size=MAX_NPY_HEADER)
        if version == (2, 0):
            return npy.read_array_header_2_0(fp, max_header_size=MAX_NPY_HEADER)
        raise ValueError(f"npy format version {version}; allowed: 1.0 or 2.0")


def _allowed_bytes(name: str) -> int:
    return MAX_NPY_HEADER + 16 + (MAX_META_BYTES if name == "meta" else 8 * _MAX_ELEMENTS[name])


_MEMBER_ERRORS = (ValueError, EOFError, OSError, zipfile.BadZipFile, zlib.error, NotImplementedError, RuntimeError,
                  SyntaxError)
"""What reading a damaged or foreign member raises (a bad header, a truncated or encrypted member, a
compression zipfile does not know)."""


def read_net(path: str | Path) -> NetFile:
    """Read and check a learned basis file; a bad one is a one-line :class:`ConfigError` naming file and member."""
    path = Path(path)
    where = str(path)
    if not path.is_file():
        raise ConfigError(f"{where}: learned basis file not found")
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise ConfigError(f"{where}: {size} bytes; allowed: a learned basis file of at most {MAX_FILE_BYTES} bytes")
    with open(path, "rb") as fh:
        head = fh.read(6)
    if head == b"\x93NUMPY":
        raise ConfigError(f"{where}: a single numpy array (.npy), not a learned basis file; allowed: the .npz "
                          "archive vtoladapt learn-basis writes")
    try:
        with zipfile.ZipFile(path) as zf:
            return _read_members(zf, where)
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError, RuntimeError) as exc:
        if isinstance(exc, ConfigError):
            raise
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError(f"{where}: not a learned basis file (numpy .npz archive): {text}") from None


def _read_members(zf: zipfile.ZipFile, where: str) -> NetFile:
    infos = {}
    for info in zf.infolist():
        if info.filename in infos:  # which copy counts would be the reader's guess
            raise ConfigError(f"{where}: member {_shown(info.filename)} twice; allowed: each member once")
        infos[info.filename] = info
    foreign = sorted(set(infos) - {f"{k}.npy" for k in ARRAYS + ("meta",)})
    if foreign:
        raise ConfigError(f"{where}: member {_shown(foreign[0])}: not a member of a learned basis file; allowed: "
                          f"{', '.join(ARRAYS)} and meta")
    missing = [k for k in ARRAYS + ("meta",) if f"{k}.npy" not in infos]
    if missing:
        raise ConfigError(f"{where}: not a learned basis file: missing member {', '.join(missing)}; allowed: an "
                          f"archive of {', '.join(ARRAYS)} and meta")
    headers = {}
    for name in ("meta",) + ARRAYS:
        info = infos[f"{name}.npy"]
        member = f"{where}: member {name}"
        if info.file_size > _allowed_bytes(name):
            raise ConfigError(f"{member}: {info.file_size} bytes uncompressed; allowed: at most {_allowed_bytes(name)} "
                              f"(h <= {MAX_H}, hidden widths <= {MAX_HIDDEN}, {N_FEATURES} features)")
        try:
            shape, fortran, dtype = _npy_header(zf, info)
        except _MEMBER_ERRORS as exc:
            raise ConfigError(f"{member}: not a numpy array ({' '.join(str(exc).split())[:200]})") from None
        if name == "meta":
            if dtype.kind != "U" or shape != ():
                raise ConfigError(f"{member}: {dtype} array of shape {shape}; allowed: one text value (JSON)")
        elif dtype.kind != "f" or dtype.itemsize not in (4, 8):
            raise ConfigError(f"{member}: dtype {dtype}; allowed: float64 or float32 (real numbers)")
        headers[name] = (shape, fortran, dtype)
    _check_shapes({k: headers[k][0] for k in ARRAYS}, where, "member ")
    data = {}
    for name in ("meta",) + ARRAYS:
        try:
            with zf.open(infos[f"{name}.npy"]) as fp:
                data[name] = np.lib.format.read_array(fp, allow_pickle=False, max_header_size=MAX_NPY_HEADER)
        except _MEMBER_ERRORS as exc:
            raise ConfigError(f"{where}: member {name}: unreadable ({' '.join(str(exc).split())[:200]})") from None
    try:
        meta = json.loads(str(data["meta"][()]))
    except RecursionError:
        raise ConfigError(f"{where}: member meta: JSON nested too deeply; allowed: at most {MAX_JSON_DEPTH} "
                          "levels") from None
    except ValueError as exc:
        raise ConfigError(f"{where}: member meta is not JSON: {exc}") from None
    if _json_depth(meta) > MAX_JSON_DEPTH:
        raise ConfigError(f"{where}: member meta: JSON nested more than {MAX_JSON_DEPTH} levels; allowed: at most "
                          f"{MAX_JSON_DEPTH}")
    check_meta(meta, f"{where}: member meta")
    arrays = {k: np.ascontiguousarray(data[k], dtype=np.float64) for k in ARRAYS}
    for name in ARRAYS:
        _check_values(name, arrays[name], where, "member ")
    return NetFile(**arrays, meta=meta)


def write_net(path: str | Path, net: NetFile) -> Path:
    """Write ``net`` to ``path``: checked as :func:`read_net` checks a file, then written to a temporary file in
    the same folder and renamed (never half-written; the temporary file is removed on any failure)."""
    from ..outputs import atomic_path

    path = Path(path)
    where = str(path)
    meta = {"format": FORMAT, "features": list(FEATURES), **{k: v for k, v in net.meta.items()
                                                               if k not in ("format", "features")}}
    check_shapes(net, where)
    check_meta(meta, f"{where}: meta")
    text = json.dumps(meta, sort_keys=True)
    if 4 * len(text) > MAX_META_BYTES or _json_depth(meta) > MAX_JSON_DEPTH:
        raise ConfigError(f"{where}: meta of {len(text)} characters, {_json_depth(meta)} levels deep; allowed: "
                          f"at most {MAX_META_BYTES // 4} characters and {MAX_JSON_DEPTH} levels")
    if path.is_dir():
        raise ConfigError(f"{where}: is a folder; allowed: a file name")
    if not path.parent.is_dir():
        raise ConfigError(f"{where}: folder {path.parent} does not exist; allowed: a file in an existing folder")
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, meta=np.array(text), **net.arrays())
        fh.flush()
        os.fsync(fh.fileno())
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
