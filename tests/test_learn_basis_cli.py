"""The docs' "Training a basis on your own flights" (docs/howto/bases.md) runs as written (three short flights, a small basis, flown),
and ``vtoladapt learn-basis`` refuses bad input in one line with status 2, writing nothing."""
from __future__ import annotations

import contextlib
import io
import re

import numpy as np
import pytest

from vtoladapt.bases.netfile import read_net
from vtoladapt.cli import main

from test_readme_extensions import section_blocks


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """The README block run in a temporary folder: what it printed, and the folder."""
    import os

    folder = tmp_path_factory.mktemp("readme_learn")
    blocks = section_blocks("Training a basis on your own flights")
    assert len(blocks) == 1
    cwd = os.getcwd()
    out = io.StringIO()
    os.chdir(folder)
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(blocks[0], "docs/howto/bases.md", "exec"), {"__name__": "readme_learn"})
    finally:
        os.chdir(cwd)
    return blocks[0], out.getvalue(), folder


def test_the_readme_training_recipe_runs_and_prints_what_it_says(trained):
    block, printed, _ = trained
    expected = [m.group(1) for m in re.finditer(r"^print\(.*\)\s+# (.*)$", block, flags=re.M)]
    lines = printed.splitlines()
    assert len(lines) == len(expected) == 2
    for got, comment in zip(lines, expected):
        assert comment.startswith(got), (got, comment)


def test_the_trained_file_records_its_flights_and_command(trained):
    _, _, folder = trained
    net = read_net(folder / "mine.npz")
    assert net.h == 2 and net.hidden == (8, 8) and net.vehicle == "caltech_vtol"
    assert len(net.meta["draws"]) == 3 and net.meta["seed"] == 0
    s = net.meta["summary"]
    assert s["flights"] == 3 and s["loss_final"] < s["loss_physics_only"]


def test_the_same_logs_and_seed_give_the_same_file(trained, tmp_path):
    _, _, folder = trained
    args = ["learn-basis", str(folder / "my_logs"), "--h", "2", "--hidden", "8", "--iterations", "30"]
    assert main(args + ["--out", str(tmp_path / "again.npz")]) == 0
    a, b = read_net(folder / "mine.npz"), read_net(tmp_path / "again.npz")
    for k, v in a.arrays().items():
        np.testing.assert_array_equal(v, b.arrays()[k])


@pytest.mark.parametrize("extra, message", [
    (["--h", "0"], r"--h = 0: out of range; allowed: 1 to 30"),
    (["--iterations", "-3"], r"--iterations = -3: out of range"),
    (["--vehicle", "px4_standard_vtol"], r"allowed: one vehicle family per basis|no flight"),
    (["--adversarial", "-0.1"], r"--adversarial = -0\.1: out of range; allowed: 0 to 1000"),
    (["--adversarial", "nan"], r"--adversarial = nan: out of range"),
    (["--adversarial", "0.1", "--adversarial-rounds", "0"], r"--adversarial-rounds = 0: out of range"),
])
def test_bad_input_is_refused_in_one_line(trained, tmp_path, capsys, extra, message):
    _, _, folder = trained
    out = tmp_path / "x.npz"
    code = main(["learn-basis", str(folder / "my_logs"), "--out", str(out), *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2 and re.search(message, err) and "\n" not in err, err
    assert not out.exists()


def test_refusals_before_anything_is_read(tmp_path, capsys):
    existing = tmp_path / "keep.npz"
    existing.write_bytes(b"mine")
    assert main(["learn-basis", str(tmp_path), "--out", str(existing)]) == 2
    assert "exists; allowed: a new file, or --force" in capsys.readouterr().err
    assert existing.read_bytes() == b"mine"
    assert main(["learn-basis", "--out", str(tmp_path / "n.npz")]) == 2
    assert "no logs" in capsys.readouterr().err
    assert main(["learn-basis", str(tmp_path / "nothing_here"), "--out", str(tmp_path / "n.npz")]) == 2
    assert "no such log file or folder" in capsys.readouterr().err


def test_adversarial_training_records_how_well_the_conditions_can_be_told_apart(trained, tmp_path, capsys):
    """With --adversarial the file records the term's weight and, as every file does, how well a classifier tells
    the flights' conditions from the trained outputs (three logs without campaign conditions: three flights)."""
    _, _, folder = trained
    out = tmp_path / "adv.npz"
    assert main(["learn-basis", str(folder / "my_logs"), "--out", str(out), "--h", "2", "--hidden", "6",
                 "--iterations", "12", "--adversarial", "0.01", "--adversarial-rounds", "3"]) == 0
    err = capsys.readouterr().err
    assert "a classifier tells the flights' 3 conditions" in err, err
    meta = read_net(out).meta
    assert meta["settings"]["adversarial"] == 0.01 and meta["settings"]["adversarial_rounds"] == 3
    s = meta["summary"]
    assert s["conditions"] == 3 and s["condition_chance"] >= 0.333 and 0.0 <= s["condition_accuracy"] <= 1.0
