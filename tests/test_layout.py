"""The block-layout helper: offsets derived from declarations, contiguous and non-overlapping."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vtoladapt.layout import BlockLayout, Field


@given(st.lists(st.integers(0, 12), min_size=1, max_size=20))
def test_fields_tile_the_array_without_gaps_or_overlaps(sizes):
    lay = BlockLayout("t", [Field(f"F{i}", s) for i, s in enumerate(sizes)])
    assert lay.size == sum(sizes)
    covered = np.zeros(lay.size, int)
    for i, s in enumerate(sizes):
        covered[lay.slice(f"F{i}")] += 1
    assert np.all(covered == 1)
    assert len(lay.columns) == lay.size


def test_nested_layout_offsets_are_absolute():
    inner = BlockLayout("inner", [Field("A", 2), Field("B", 3)])
    outer = BlockLayout("outer", [Field("X", 4), Field("IN", inner.size), Field("Y", 1)])
    assert outer.nested("IN", inner, "A", "B") == (4, 6)
    with pytest.raises(ValueError, match="size"):
        BlockLayout("bad", [Field("IN", 4)]).nested("IN", inner, "A")


def test_errors_name_the_layout_and_field():
    lay = BlockLayout("plant parameters", [Field("MASS", 1, "kg")])
    with pytest.raises(KeyError, match="plant parameters: no field 'MAS'"):
        lay.offset("MAS")
    with pytest.raises(ValueError, match="declared twice"):
        BlockLayout("t", [Field("A", 1), Field("A", 2)])
    with pytest.raises(ValueError, match="column names"):
        Field("V", 3, columns=("a", "b"))


def test_pack_and_view_round_trip():
    lay = BlockLayout("t", [Field("A", 1), Field("V", 3, columns=("vx", "vy", "vz"))])
    arr = lay.pack(A=2.0, V=[1.0, 2.0, 3.0])
    np.testing.assert_array_equal(lay.view(arr, "V"), [1.0, 2.0, 3.0])
    assert lay.columns == ("a", "vx", "vy", "vz")
