"""The built-in demonstrations: one pair built alone is the row the whole set holds for it."""

from __future__ import annotations

import lance
import pytest

from dexcanvas_core import builtin
from dexcanvas_core.demos import builtin_pairs, builtin_plan, feasible_pairs
from dexcanvas_core.demos.build import _generate_one
from dexcanvas_core.demos.operators import OPERATORS
from dexcanvas_core.errors import DatasetError
from dexcanvas_core.io import write_dataset
from dexcanvas_core.loaders.selection import load_demonstration


def _cheap_item():
    """A built-in plan item of a table-supported type (no grasp search: a fraction of a
    second to generate) whose operator is not the first: a pair planned alone would get
    ``operators[0]`` and differ from the whole set's row."""
    ops = list(OPERATORS)
    for i, item in enumerate(builtin_plan()):
        if item[0].manipulation_type.name in ("rolling", "sliding") and item[1] != ops[0]:
            return i, item
    raise AssertionError(
        "the built-in set has no rolling or sliding pair planned with a later operator; pick "
        "another cheap pair for these tests"
    )


def test_builtin_plan_is_the_whole_sets_and_refuses_other_pairs():
    plan = builtin_plan()
    assert [p for p, _, _ in plan] == builtin_pairs()
    _, item = _cheap_item()
    assert builtin_plan([str(item[0])]) == [item]
    other = next(p for p in feasible_pairs() if p not in builtin_pairs())
    with pytest.raises(DatasetError, match=rf"no built-in demonstration of {other}; the built-in"):
        builtin_plan([other])


def test_one_pair_is_built_alone_as_the_whole_set_holds_it(tmp_path, monkeypatch):
    monkeypatch.setenv("DEXCANVAS_CACHE_DIR", str(tmp_path / "cache"))
    _, (pair, op, seed) = _cheap_item()
    assert builtin.builtin_demonstration_cached(pair) is None
    traj = load_demonstration(str(pair))  # builds the pair alone
    path = builtin.builtin_pair_path(pair)
    assert builtin.builtin_demonstration_cached(pair) == path
    assert (path.parent / (path.name + ".report.json")).is_file()
    assert not (tmp_path / "cache" / builtin.builtin_dataset_name()).exists()  # not the whole set
    assert traj.operator == op
    # the whole set's row for this pair: the same plan item generated and written the same way
    demo, _ = _generate_one((pair, op, seed))
    ref = write_dataset([demo.trajectory], tmp_path / "whole_set_row.lance")
    a, b = lance.dataset(str(path)).to_table(), lance.dataset(str(ref)).to_table()
    assert a.schema.equals(b.schema, check_metadata=False)
    for name in a.schema.names:
        assert a.column(name).combine_chunks().equals(b.column(name).combine_chunks()), name
    # a second use reads the cache: no rebuild
    stamp = path.stat().st_mtime_ns
    assert load_demonstration(str(pair)).uuid == traj.uuid
    assert path.stat().st_mtime_ns == stamp
