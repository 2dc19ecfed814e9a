"""The controller's tuning: every threshold is a named, documented field of exactly one phase's group."""

from __future__ import annotations

import ast
import dataclasses
import inspect
from typing import Any

import pytest

from stressbots.control import tuning as tuning_module
from stressbots.control.tuning import DockingTuning, GrossTuning, PairTuning, ParkingTuning, Tuning

GROUPS = (PairTuning, GrossTuning, DockingTuning, ParkingTuning)


def _names(cls) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)}


def test_groups_partition_the_fields():
    union: set[str] = set()
    for g in GROUPS:
        assert not (union & _names(g)), f"{g.__name__} repeats a field of another group"
        union |= _names(g)
    assert union == _names(Tuning)
    assert not Tuning.__annotations__, "Tuning's fields belong to a phase's group"


def _field_docs() -> dict[str, str | None]:
    """Each field of the group classes -> its attribute docstring (None when it has none)."""
    tree = ast.parse(inspect.getsource(tuning_module))
    docs: dict[str, str | None] = {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name in {g.__name__ for g in GROUPS}:
            body = node.body
            for k, st in enumerate(body):
                if isinstance(st, ast.AnnAssign) and isinstance(st.target, ast.Name):
                    nxt = body[k + 1] if k + 1 < len(body) else None
                    is_doc = isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant) and isinstance(nxt.value.value, str)
                    docs[st.target.id] = nxt.value.value if is_doc else None  # type: ignore[union-attr]
    return docs


def test_every_field_has_a_reason():
    docs = _field_docs()
    assert set(docs) == _names(Tuning)
    # a field without its own docstring is documented jointly: "(a, b) ..." on the last of them
    joint = {nm for d in docs.values() if d and d.startswith("(") for nm in d[1:d.index(")")].split(", ")}
    for name, doc in docs.items():
        assert doc is not None or name in joint, f"Tuning.{name} has no docstring saying why"
        assert doc is None or len(doc.split()) >= 5, f"Tuning.{name}'s docstring is too short to give a reason"


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
def test_groups_are_frozen_and_replaceable(group):
    t = Tuning()
    name = sorted(_names(group))[0]
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(t, name, getattr(t, name))
    value = getattr(t, name)
    other = value + 1 if isinstance(value, (int, float)) and not isinstance(value, bool) else value
    changes: dict[str, Any] = {name: other}
    assert getattr(dataclasses.replace(t, **changes), name) == other
    assert getattr(t, name) == value  # the default is untouched
