"""A time series of fixed-shape numeric rows, appended one at a time and kept in numpy chunks.

A per-step log held as a Python list of small arrays costs an object header and a list slot per
row (about twice the numbers themselves for a robot's state); :class:`Series` keeps the numbers
only: rows are copied into preallocated chunks (``FIRST_CHUNK`` rows, each next chunk twice the
previous, up to ``MAX_CHUNK``), so memory grows with the rows stored plus at most one partly
filled chunk, and nothing is copied while the series grows. :meth:`Series.array` joins the chunks
into one array on demand (and keeps it: a second read copies nothing).

The values are those of ``np.asarray`` of the list of rows: the dtype is the first row's, widened
the way numpy would if a later row needs it (an int series that meets a float becomes float64).
"""

from __future__ import annotations

import numpy as np

#: rows of the first chunk, and the most rows one chunk holds
FIRST_CHUNK, MAX_CHUNK = 256, 16384
_FLOAT = np.dtype(np.float64)


class Series:
    """Rows of one shape appended with :meth:`append`; :meth:`array` is them all, (rows, *shape).

    ``dtype`` fixes the dtype (rows are cast to it); None: numpy's choice for the rows seen."""

    def __init__(self, dtype=None):
        self._fixed_dtype = None if dtype is None else np.dtype(dtype)
        self._chunks: list[np.ndarray] = []
        self._last: np.ndarray | None = None  # the last chunk, the one being filled
        self._shape: tuple = ()  # the rows' shape (the first row's)
        self._filled = 0  # rows used in the last chunk
        self._rows = 0

    def __len__(self) -> int:
        return self._rows

    @property
    def nbytes(self) -> int:
        """Bytes held by the chunks (filled or not)."""
        return sum(c.nbytes for c in self._chunks)

    def append(self, row) -> None:
        """Copy ``row`` (an array, a sequence of numbers or a number) in as the next row.
        ValueError if its shape differs from the first row's."""
        last = self._last
        if last is not None and self._filled < len(last) and (
                (type(row) is np.ndarray and row.dtype == last.dtype and row.shape == self._shape)
                or (type(row) is float and last.dtype == _FLOAT and not self._shape)):
            # a row as the chunk stores it (the per-step case): copied in as it is
            last[self._filled] = row
            self._filled += 1
            self._rows += 1
            return
        row = np.asarray(row, dtype=self._fixed_dtype)
        if last is None:
            self._shape = row.shape
            last = self._add_chunk(FIRST_CHUNK, row.dtype)
        elif row.shape != self._shape:
            raise ValueError(f"series: a row of shape {row.shape} after rows of shape "
                             f"{self._shape}")
        if row.dtype != last.dtype and not np.can_cast(row.dtype, last.dtype, "safe"):
            self._widen(np.result_type(last.dtype, row.dtype))
            last = self._last
        filled = self._filled
        if filled == len(last):
            last = self._add_chunk(min(max(2 * len(last), FIRST_CHUNK), MAX_CHUNK), last.dtype)
            filled = 0
        last[filled] = row
        self._filled = filled + 1
        self._rows += 1

    def _add_chunk(self, size: int, dtype) -> np.ndarray:
        """A new empty chunk of ``size`` rows, now the one being filled."""
        self._last = np.empty((size, *self._shape), dtype=dtype)
        self._chunks.append(self._last)
        self._filled = 0
        return self._last

    def array(self) -> np.ndarray:
        """All rows, (rows, *row shape), read-only (a view of the series' storage: copy it to
        write to it); with no row yet, ``np.asarray([])`` in the series' dtype."""
        if not self._chunks:
            return np.asarray([], dtype=self._fixed_dtype)
        if len(self._chunks) > 1 or self._filled < len(self._chunks[0]):
            joined = np.concatenate([*self._chunks[:-1], self._chunks[-1][:self._filled]])
            self._chunks, self._filled, self._last = [joined], len(joined), joined
        view = self._chunks[0].view()
        view.flags.writeable = False
        return view

    def _widen(self, dtype: np.dtype) -> None:
        self._chunks = [c.astype(dtype) for c in self._chunks]
        self._last = self._chunks[-1]


def _check_fields(log, row: dict, fields: dict) -> None:
    """ValueError naming ``log``'s class unless ``row`` has exactly the keys of ``fields``."""
    if row.keys() != fields.keys():
        missing, unknown = fields.keys() - row.keys(), row.keys() - fields.keys()
        raise ValueError(f"{type(log).__name__}.append: missing {sorted(missing)}, unknown "
                         f"{sorted(unknown)}")


class SeriesLog:
    """Named :class:`Series` appended together, one row each per :meth:`append`; a subclass names
    them in ``FIELDS`` and may fix some dtypes in ``DTYPES`` (name -> dtype). Each series reads as
    an attribute of its name (its :meth:`Series.array`); :meth:`arrays` gives them all."""

    FIELDS: tuple[str, ...] = ()
    DTYPES: dict[str, object] = {}

    def __init__(self):
        self._series = {name: Series(self.DTYPES.get(name)) for name in self.FIELDS}

    def append(self, **row) -> None:
        """One row of every series (keywords: the ``FIELDS``, all of them)."""
        _check_fields(self, row, self._series)
        series = self._series
        for name, value in row.items():
            series[name].append(value)

    def __len__(self) -> int:
        return len(self._series[self.FIELDS[0]]) if self.FIELDS else 0

    def __getattr__(self, name: str) -> np.ndarray:
        series = self.__dict__.get("_series", {})
        if name in series:
            return series[name].array()
        raise AttributeError(f"'{type(self).__name__}' object has no attribute '{name}'")

    @property
    def nbytes(self) -> int:
        """Bytes held by the series' storage."""
        return sum(s.nbytes for s in self._series.values())

    def arrays(self) -> dict[str, np.ndarray]:
        """Every series as an array (read-only views), by name."""
        return {name: s.array() for name, s in self._series.items()}


class RowLog:
    """Named fields of fixed shapes appended together (the same keywords as
    :meth:`SeriesLog.append`), stored side by side in one :class:`Series` of flat float64 rows:
    per append, one copy of each field into a row buffer and one row appended — a per-step log's
    cheapest form. Each field reads as an attribute of its name, a view (rows, *shape) of the
    stored rows; :meth:`arrays` gives them all. ``shapes``: field name -> shape (``()``: a number).
    A value takes its field's shape by numpy's assignment rules (broadcast)."""

    def __init__(self, shapes: dict[str, tuple[int, ...]]):
        self._shapes = {name: tuple(shape) for name, shape in shapes.items()}
        sizes = [int(np.prod(shape, dtype=int)) for shape in self._shapes.values()]
        self._row = np.empty(sum(sizes))
        self._slices, start = {}, 0
        self._views = {}  # field -> its part of the row buffer, in the field's shape
        for (name, shape), size in zip(self._shapes.items(), sizes):
            self._slices[name] = slice(start, start + size)
            self._views[name] = self._row[start:start + size].reshape(shape)
            start += size
        self._rows = Series(np.float64)

    def append(self, **row) -> None:
        """One row of every field (keywords: the fields, all of them)."""
        views = self._views
        _check_fields(self, row, views)
        for name, value in row.items():
            views[name][...] = value
        self._rows.append(self._row)

    def __len__(self) -> int:
        return len(self._rows)

    def __getattr__(self, name: str) -> np.ndarray:
        slices = self.__dict__.get("_slices", {})
        if name in slices:
            return self._field(name)
        raise AttributeError(f"'{type(self).__name__}' object has no attribute '{name}'")

    def _field(self, name: str) -> np.ndarray:
        rows = self._rows.array()
        if rows.ndim == 1:  # no row yet
            rows = rows.reshape(0, len(self._row))
        return rows[:, self._slices[name]].reshape(len(rows), *self._shapes[name])

    @property
    def nbytes(self) -> int:
        """Bytes held by the rows' storage."""
        return self._rows.nbytes

    def arrays(self) -> dict[str, np.ndarray]:
        """Every field as an array (read-only views), by name."""
        return {name: self._field(name) for name in self._shapes}
