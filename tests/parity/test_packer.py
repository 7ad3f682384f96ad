"""The compiled parameter packer (``wholebody._hierarchy_cycle.ParameterPacker``) against the Python
writers it replaces in the cycle (:meth:`wholebody.tasks.schema.Param.writer`, the reference):
for every form and every kind of value a controller may put on a task — Python and numpy
scalars, lists, tuples, float and int arrays, arrays of one entry, 0-d, strided and Fortran-order
arrays, wrong sizes, strings, None, flags — both write the same entries, or both raise the same
error with the same message; neither writes outside its view."""

from types import SimpleNamespace

import numpy as np
import pytest

from wholebody.cycle import native_available
from wholebody.tasks.schema import Param, Size

pytestmark = pytest.mark.skipif(not native_available(),
                                reason="wholebody._hierarchy_cycle not built (no C++ compiler)")


class Holder:
    """A task's stand-in: a name and the attribute ``value``, also held as ``inner.value``."""

    name = "holder"

    def __init__(self, value):
        self.value = value
        self.inner = SimpleNamespace(value=value)


def by_attribute(form, n):
    return Param("value", Size(n), form)


def by_get(form, n):
    return Param("value", Size(n), form, get=lambda task, layout, state: task.value)


def by_path(form, n):
    return Param("gain", Size(n), form, attribute="inner.value")


VALUES = [2.5, 3, -0, True, False, np.float64(1.5), np.float32(0.25), np.int64(4), np.bool_(True),
          [1.0, 2.0, 3.0], (1.0, 2.0, 3.0), [1, 2, 3], np.array([1.0, 2.0, 3.0]),
          np.array([1, 2, 3]), np.array([7.0]), np.array(5.0), np.arange(6.0)[::2],
          np.ones((1, 3)), np.eye(3), np.asfortranarray(np.arange(9.0).reshape(3, 3)),
          np.arange(9.0).reshape(3, 3).T, np.arange(9.0), np.ones(4), np.array([np.nan, 1.0, np.inf]),
          np.array([True, False, True]), "abc", None, 2 ** 2000, np.zeros((3, 1)), [[1.0, 2.0, 3.0]]]


def outcome(write, buffer):
    """What a write leaves: the buffer, or the error's type and message."""
    try:
        write()
    except Exception as exc:  # noqa: BLE001 - the comparison is of the error itself
        return type(exc), str(exc)
    return buffer.copy()


def same(a, b):
    if isinstance(a, tuple) or isinstance(b, tuple):
        return a == b
    return np.array_equal(a, b, equal_nan=True)


@pytest.mark.parametrize("make", [by_attribute, by_get, by_path])
@pytest.mark.parametrize("form,n", [("vector", 3), ("vector", 1), ("diagonal", 3), ("matrix", 9),
                                    ("matrix", 3), ("flag", 1)])
def test_packer_writes_what_the_python_writer_writes(make, form, n):
    from wholebody._hierarchy_cycle import ParameterPacker

    param = make(form, n)
    for value in VALUES:
        task = Holder(value)
        # the parameter's view in the middle of a larger array, sentinels either side
        python_buffer, packed_buffer = np.full(n + 4, -7.0), np.full(n + 4, -7.0)
        write = param.writer(task, python_buffer[2:2 + n], None, None)
        packer = ParameterPacker([param.source(task, packed_buffer[2:2 + n], None, None)])
        expected, got = outcome(write, python_buffer), outcome(packer.pack, packed_buffer)
        assert same(expected, got), f"{form}[{n}] {type(value).__name__} {value!r}: " \
                                    f"Python {expected}, packer {got}"


def test_packer_reads_the_current_value_every_pack():
    """A source holds the task, not its value: a reassigned or mutated attribute is packed."""
    from wholebody._hierarchy_cycle import ParameterPacker

    task = Holder(np.array([1.0, 2.0, 3.0]))
    buffer = np.zeros(3)
    packer = ParameterPacker([by_attribute("vector", 3).source(task, buffer, None, None)])
    packer.pack()
    task.value[1] = 5.0
    packer.pack()
    assert buffer.tolist() == [1.0, 5.0, 3.0]
    task.value = 0.5
    packer.pack()
    assert buffer.tolist() == [0.5, 0.5, 0.5]


@pytest.mark.parametrize("path", ["inner.missing", "missing.value", "inner.value.real.imag.x"])
def test_an_attribute_path_that_breaks_raises_as_python_does(path):
    """A path through a missing attribute: the packer raises Python's AttributeError, message
    and all, and writes nothing."""
    from wholebody._hierarchy_cycle import ParameterPacker

    param = Param("gain", Size(3), "vector", attribute=path)
    task = Holder(np.array([1.0, 2.0, 3.0]))
    python_buffer, packed_buffer = np.full(3, -7.0), np.full(3, -7.0)
    write = param.writer(task, python_buffer, None, None)
    packer = ParameterPacker([param.source(task, packed_buffer, None, None)])
    expected, got = outcome(write, python_buffer), outcome(packer.pack, packed_buffer)
    assert expected[0] is AttributeError and expected == got
    assert (packed_buffer == -7.0).all()


def test_an_attribute_path_is_names_and_no_get():
    for path in ["", "inner..value", ".value", "inner."]:
        with pytest.raises(ValueError, match="dotted path"):
            Param("gain", Size(3), "vector", attribute=path)
    with pytest.raises(ValueError, match="dotted path"):
        Param("gain", Size(3), "vector", attribute="inner.value", get=lambda t, layout, state: 0)


def test_packer_refuses_a_view_it_cannot_write():
    from wholebody._hierarchy_cycle import ParameterPacker

    param = by_attribute("vector", 3)
    for view, why in [(np.zeros(6)[::2], "contiguous"), (np.zeros(3, dtype=np.float32), "float64"),
                      (np.zeros((1, 3)), "vector")]:
        with pytest.raises(ValueError, match=why):
            ParameterPacker([param.source(Holder(1.0), view, None, None)])


class Mapped:
    """A task's stand-in with a per-contact dict ``value`` and its stacking as the reference."""

    name = "mapped"

    def __init__(self, value):
        self.value = value


def stacked(default):
    """The reference ``get`` of a mapping: the entries of the layout's contacts, one after the
    other (``default`` where an entry is missing), written with numpy only."""
    def get(task, layout, state):
        return np.hstack([np.asarray(task.value.get(n, default), dtype=float).reshape(-1)
                          for n in layout.contacts])
    return get


MAPPINGS = [{"a": np.array([1.0, 2.0, 3.0]), "b": np.array([4.0, 5.0, 6.0])},
            {"b": np.array([4.0, 5.0, 6.0]), "a": np.array([-1.0, 0.0, 1e300])},  # any dict order
            {"a": np.array([1.0, 2.0, 3.0])},  # "b" missing: the default, or get's
            {}, {"a": np.array([1, 2, 3]), "b": np.array([4.0, 5.0, 6.0])},  # an int entry
            {"a": [1.0, 2.0, 3.0], "b": np.array([4.0, 5.0, 6.0])},  # a list entry
            {"a": np.arange(6.0)[::2], "b": np.ones(3)},  # a strided entry
            {"a": np.ones((1, 3)), "b": np.ones(3)},  # a 2-D entry
            {"a": np.array([np.nan, 1.0, np.inf]), "b": np.ones(3)},
            {"a": np.ones(3), "b": np.ones(3), "c": np.ones(3)},  # a contact not in the layout
            None, "abc"]


@pytest.mark.parametrize("default", [(0.0, 0.0, 1.0), None])
def test_packer_reads_a_mapping_as_its_reference_stacks_it(default):
    """A per-contact mapping (``Param.mapping``) read by the packer equals its ``get``'s value
    for every kind of dict and entry; where the packer cannot read it, ``get`` decides (its
    value, or its error with its message)."""
    from wholebody._hierarchy_cycle import ParameterPacker
    from wholebody.tasks.schema import LayoutContext

    layout = LayoutContext(None, contacts=("a", "b"))
    param = Param("value", Size(3, "contact"), "vector", get=stacked(default), mapping="value",
                  default=default)
    for value in MAPPINGS:
        task = Mapped(value)
        python_buffer, packed_buffer = np.full(10, -7.0), np.full(10, -7.0)
        write = param.writer(task, python_buffer[2:8], layout, None)
        packer = ParameterPacker([param.source(task, packed_buffer[2:8], layout, None)])
        expected, got = outcome(write, python_buffer), outcome(packer.pack, packed_buffer)
        assert same(expected, got), f"{value!r}: Python {expected}, packer {got}"


def test_a_mapping_param_is_a_per_contact_vector_with_its_reference():
    with pytest.raises(ValueError, match="mapping"):
        Param("value", Size(3, "contact"), "vector", mapping="value")  # no get
    with pytest.raises(ValueError, match="mapping"):
        Param("value", Size(3), "vector", get=stacked(None), mapping="value")
    with pytest.raises(ValueError, match="default"):
        Param("value", Size(3, "contact"), "vector", get=stacked(None), mapping="value",
              default=(0.0, 1.0))


def test_packer_reads_a_full_mapping_without_its_reference():
    """The compiled read is the one taken for float64 entries (or the default): ``get`` is not
    called; for another entry it is."""
    from wholebody._hierarchy_cycle import ParameterPacker
    from wholebody.tasks.schema import LayoutContext

    calls = []
    reference = stacked((0.0, 0.0, 1.0))

    def get(task, layout, state):
        calls.append(1)
        return reference(task, layout, state)

    param = Param("value", Size(3, "contact"), "vector", get=get, mapping="value",
                  default=(0.0, 0.0, 1.0))
    task = Mapped({"b": np.array([4.0, 5.0, 6.0])})
    buffer = np.zeros(6)
    packer = ParameterPacker([param.source(task, buffer, LayoutContext(None, ("a", "b")), None)])
    packer.pack()
    assert buffer.tolist() == [0.0, 0.0, 1.0, 4.0, 5.0, 6.0] and not calls
    task.value["a"] = [1, 2, 3]
    packer.pack()
    assert buffer.tolist() == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0] and len(calls) == 1
