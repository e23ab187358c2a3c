"""The closed loop's serial work, cheaper with the same numbers: a block made anew (a candidate's
blocks on its extended round) is served the columns built for the same parameters, and the
segment index of a periodic candidate's rows is read in one pass when they are in order."""

from __future__ import annotations

import numpy as np
import pytest

import gearspec.diagnose as dg
from gearspec.diagnose.candidates import segment_index, side_by_side
from gearspec.simulate import effects as fx

from test_diagnose import recording


def _recording():
    rec, _ = recording([fx.drift(coefficient=2e-4), fx.cogging(count=7, amplitude=3e-3)])
    return rec


def test_a_block_made_anew_with_the_same_parameters_is_served_its_columns_from_the_cache():
    """A candidate makes its blocks anew in every round it is asked in (a grid value's block on the
    round and on its extended round): new ids, the same columns, built once."""
    from gearspec.diagnose.design import HarmonicBlock

    dd = dg.DiagnoseData.from_recording(_recording())
    law, decay = ((1, "exp"), (-1, "exp")), ((1, 0.1), (-1, 0.2))
    a = HarmonicBlock(key="l", frequency=0.37, law=law, decay=decay)
    b = HarmonicBlock(key="l", frequency=0.37, law=law, decay=decay)
    c = HarmonicBlock(key="l", frequency=0.37, law=law, decay=((1, 0.1), (-1, 0.3)))
    assert a.uid != b.uid
    cols = a.columns(dd)
    assert b.columns(dd) is cols                       # served: the same array
    other = c.columns(dd)
    assert other is not cols and not np.array_equal(other[:, 2:], cols[:, 2:])
    assert np.array_equal(other[:, :2], cols[:, :2])   # the direction whose decay is the same


@pytest.mark.parametrize("seg", [np.repeat([0, 3, 4, 9], [5, 1, 7, 2]),           # plateaus: in order
                                 np.array([4, 4, 0, 9, 3, 3, 0]),                 # out of order: sorted
                                 np.array([7]), np.zeros(0, int), np.array([2.0, 2.0, 5.0])])
def test_segment_index_is_unique_and_searchsorted(seg):
    sids, inv = segment_index(seg)
    want = np.unique(seg)
    assert np.array_equal(sids, want) and sids.dtype == want.dtype
    assert np.array_equal(inv, np.searchsorted(want, seg)) and inv.dtype == np.intp
    if len(seg):
        assert np.array_equal(sids[inv], seg)


def test_one_blocks_columns_go_to_the_fits_as_they_are_when_a_copy_would_be_the_same():
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(50, 2)), rng.normal(size=(50, 1))
    assert side_by_side([a]) is a                                     # C-ordered floats: no copy
    f = np.asfortranarray(a)                                          # another layout: the copy column_stack makes
    out, want = side_by_side([f]), np.column_stack([f])
    assert out is not f and np.array_equal(out, want)
    assert (out.flags.c_contiguous, out.flags.f_contiguous) == (want.flags.c_contiguous, want.flags.f_contiguous)
    v = a[:, :1]                                                      # a strided view: copied
    assert not v.flags.c_contiguous and side_by_side([v]) is not v
    ints = np.arange(6).reshape(3, 2)
    assert side_by_side([ints]) is not ints
    assert np.array_equal(side_by_side([a, b]), np.column_stack([a, b]))
