"""No offset into a kernel's flat array is typed by hand in the simulator's kernel modules.

Offsets come from :class:`vtoladapt.layout.BlockLayout` declarations (``A, B = LAYOUT.offsets("A",
"B")``), so a field added, removed or resized moves every offset with it. This scan of the source
(:mod:`ast`) refuses, at module level in the modules of :data:`SCANNED`, the three ways offsets used
to be typed: an integer constant (``_C_STATE = 1``), a chain of them (``_C_WIND = _C_STATE +
X_SIZE``) and positional unpacking (``SET_MODE, SET_DT = range(2)``). An integer that is not an
offset (a capacity, a count, a stream id) is listed in :data:`NOT_OFFSETS` with what it is.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import vtoladapt

PACKAGE_DIR = Path(vtoladapt.__file__).resolve().parent
SCANNED = ("layout.py", "parts.py", "sim", "wind", "sensors", "gym", "control", "bases", "forces.py", "models.py")
"""The kernel modules (files and folders of the package): the simulator's, the controller's and the
force model's."""

NOT_OFFSETS: dict[str, str] = {
    "N_SPECIALISED_SLOTS": "count: basis sizes the adaptation's kernels are compiled for with constant loops",
    "ADAPT_COMPOSITE": "enum: adaptation mode", "ADAPT_PCONST": "enum: adaptation mode",
    "ADAPT_TRACKING": "enum: adaptation mode", "ADAPT_NONE": "enum: adaptation mode",
    "ADAPT_KALMAN": "enum: adaptation mode",
    "PROJECTION_MAX_ITER": "iteration cap of the projection",
    "MAX_ITERATIONS": "iteration cap of the airflow estimate",
    "MAX_ITERATIONS_COLD": "iteration cap of the airflow estimate from a cold start",
    "MAX_HALVINGS": "step halvings of the airflow estimate's line search",
    "MAX_PARAMETERS": "capacity: parameters a basis may declare",
    **{f"FAULT_{k}": "bit flag of the controller's fault word" for k in (
        "POSITION", "VELOCITY", "ATTITUDE", "GYRO", "ACCEL", "PROBE", "REFERENCE", "COMMAND", "ADAPTATION", "DT")},
    "CHUNKS_PER_WORKER": "gym threading: chunks per thread",
    "MIN_CHUNK_ENVS": "gym threading: environments per chunk at least",
    "_CACHE_LINE_DOUBLES": "float64s in a 64-byte cache line (the prefetch stride)",
    "MOCAP_RING_SIZE": "capacity: ticks of motion-capture history",
    "LATENCY_RING_TICKS": "capacity: ticks of the fault latency ring",
    "MAX_FAULTS": "capacity: entries of a fault schedule",
    "MAX_BREAKPOINTS": "capacity: fan schedule breakpoints",
    "MAX_GUSTS": "capacity: gusts",
    "PLANT_DRAW_STREAM": "the id of the Table I draw's random stream",
    "PHYSICAL_DRAW_STREAM": "the id of the physical parameters' draw's random stream",
    "N_SURFACES": "capacity: control-surface slots of an airframe",
    "N_OUT": "count: the outputs the allocator realises (lift and three moments)",
    "ROTOR_TERMS_SIZE": "the length of the tuple plant.rotor_terms returns",
    "NORMALS_PER_STEP": "a part's draws per step (the interface of vtoladapt.parts)",
    "UNIFORMS_PER_STEP": "a part's draws per step (the interface of vtoladapt.parts)",
    "PARQUET_FORMAT_VERSION": "the log file format's version",
    "POSTERIOR_VERSION": "the posterior file format's version (bases/posterior.py, moved from fitting/)",
    "ANALYSIS_COLUMNS_PER_RUN": "memory model: values per tick a run's analysis reads back",
    "ANALYSIS_TRANSIENT_COLUMNS": "memory model: values per tick the analysis creates and drops",
    "STREAM_ROW_GROUP_ROWS": "memory model: rows of a streamed log's row group",
    "MAX_WAYPOINTS": "capacity: rows of [reference] waypoints",
    "MAX_H": "cap: learned columns a network file may have (learn-basis --h's)",
    "MAX_HIDDEN": "cap: width of a network file's hidden layer (learn-basis --hidden's)",
    "MAX_JSON_DEPTH": "cap: nesting of a network file's meta JSON",
    "MAX_NPY_HEADER": "cap: bytes of a network file member's npy header",
}


def _leaves(node: ast.expr) -> list[ast.expr]:
    """The operands of a chain of ``+`` and ``-``."""
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub)):
        return _leaves(node.left) + _leaves(node.right)
    return [node]


def findings(source: str, where: str = "<source>") -> list[str]:
    """What the module-level code of ``source`` types by hand (see the module docstring)."""
    out = []
    for node in ast.parse(source).body:
        if not isinstance(node, (ast.Assign, ast.AnnAssign)) or node.value is None:
            continue
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        names = [n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)]
        value = node.value
        text = f"{where}:{node.lineno}: {ast.unparse(node)[:100]}"
        if isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id == "range":
            out.append(text + "  (positional unpacking: use a BlockLayout's offsets or a names tuple's index)")
        elif isinstance(value, ast.Constant) and type(value.value) is int:
            if not all(n in NOT_OFFSETS for n in names):
                out.append(text + "  (an integer typed by hand: an offset comes from a BlockLayout)")
        elif isinstance(value, ast.BinOp) and isinstance(value.op, (ast.Add, ast.Sub)):
            # names and integers added up; a sum of layouts' sizes (``A.size + B.field("X").size``) is a size
            leaves = _leaves(value)
            if all(isinstance(n, ast.Name) or (isinstance(n, ast.Constant) and type(n.value) is int)
                   for n in leaves) and any(isinstance(n, ast.Name) for n in leaves):
                out.append(text + "  (an offset chain: declare the fields in a BlockLayout)")
    return out


def _scanned_files() -> list[Path]:
    files = []
    for item in SCANNED:
        path = PACKAGE_DIR / item
        files += sorted(path.rglob("*.py")) if path.is_dir() else [path]
    return files


def test_no_offsets_typed_by_hand_in_the_simulators_kernel_modules():
    found = []
    for path in _scanned_files():
        found += findings(path.read_text(encoding="utf-8"), str(path.relative_to(PACKAGE_DIR)))
    assert found == [], "\n".join(found)


@pytest.mark.parametrize("source, n", [
    ("_C_STATE = 1\n_C_WIND = _C_STATE + X_SIZE\n", 2),
    ("SET_MODE, SET_DT = range(2)\n", 1),
    ("_S_HEAD, _S_RING = STATE.offsets('HEAD', 'RING')\nMAX_FAULTS = 30\nG = 9.8 + 0.0\n", 0),
    ("N = A.size + B.field('X').size\nO = _BASE + 3\n", 1),
    ("def f():\n    x = 4\n", 0),
])
def test_the_scan_sees_what_it_refuses(source, n):
    assert len(findings(source)) == n
