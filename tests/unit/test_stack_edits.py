"""Stacks are edited by task name: insert before/after a named task, remove, replace."""

import pytest

from wholebody.formulation import Stack
from wholebody.tasks.base import Task


def _stack():
    return Stack([[Task("dynamics")], [Task("contacts"), Task("friction")],
                  [Task("momentum"), Task("posture"), Task("regularizer")]])


def _names(stack):
    return [[t.name for t in level] for level in stack.levels]


def test_insert_appends_to_the_level_by_default():
    stack = _stack()
    task = stack.insert(2, Task("unload"))
    assert task.name == "unload"
    assert _names(stack)[2] == ["momentum", "posture", "regularizer", "unload"]


def test_insert_before_and_after_a_named_task():
    stack = _stack()
    stack.insert(2, Task("joints"), before="posture")
    stack.insert(2, Task("swing"), before="posture")
    stack.insert(1, Task("cop"), after="contacts")
    assert _names(stack) == [["dynamics"], ["contacts", "cop", "friction"],
                             ["momentum", "joints", "swing", "posture", "regularizer"]]
    assert stack.locate("swing") == (2, 2)


def test_insert_rejects_a_wrong_level_a_duplicate_and_both_anchors():
    stack = _stack()
    with pytest.raises(ValueError, match="level 1, not 2"):
        stack.insert(2, Task("x"), before="friction")
    with pytest.raises(ValueError, match="already has a task named 'posture'"):
        stack.insert(2, Task("posture"))
    with pytest.raises(ValueError, match="not both"):
        stack.insert(2, Task("x"), before="posture", after="momentum")
    with pytest.raises(ValueError, match="level 3"):
        stack.insert(3, Task("x"))
    with pytest.raises(ValueError, match="no task named 'nothing'"):
        stack.insert(2, Task("x"), after="nothing")
    assert _names(stack) == _names(_stack())


def test_remove_returns_the_task_and_keeps_levels_non_empty():
    stack = _stack()
    posture = stack.find("posture")
    assert stack.remove("posture") is posture
    assert _names(stack)[2] == ["momentum", "regularizer"]
    with pytest.raises(ValueError, match="only task of level 0"):
        stack.remove("dynamics")
    with pytest.raises(ValueError, match="no task named 'posture'"):
        stack.remove("posture")


def test_replace_keeps_the_place():
    stack = _stack()
    new = Task("posture")
    old = stack.replace("posture", new)
    assert old.name == "posture" and old is not new and stack.find("posture") is new
    assert stack.locate("posture") == (2, 1)
    stack.replace("friction", Task("friction pyramid"))
    assert _names(stack)[1] == ["contacts", "friction pyramid"]
    with pytest.raises(ValueError, match="already has a task named 'momentum'"):
        stack.replace("regularizer", Task("momentum"))
