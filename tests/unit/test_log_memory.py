"""The simulator's log and the scenarios' logs keep numbers, not an object per row: their content
is what a naive per-step list recording gives, and their memory grows by about 8 bytes per number
per step."""

import tracemalloc

import numpy as np
import pytest

from wholebody.scenarios.locomotion import GaitLog
from wholebody.sim.disturbance import Push
from wholebody.sim.series import FIRST_CHUNK, MAX_CHUNK, RowLog, Series, SeriesLog
from wholebody.sim.simulator import SimLog, Simulator


def test_series_equals_numpy_of_the_list_across_chunks_and_reads(rng):
    """Rows appended across several chunks, read in between, read again after more rows: always
    np.asarray of the list of rows, dtype included."""
    rows = [rng.normal(size=(4, 6)) for _ in range(3 * FIRST_CHUNK + 17)]
    series = Series()
    for k, row in enumerate(rows):
        series.append(row)
        if k in (0, FIRST_CHUNK - 1, FIRST_CHUNK, 2 * FIRST_CHUNK + 3):
            np.testing.assert_array_equal(series.array(), np.asarray(rows[:k + 1]))
    out = series.array()
    assert out.dtype == np.asarray(rows).dtype and len(series) == len(rows)
    np.testing.assert_array_equal(out, np.asarray(rows))
    assert series.array() is not out and np.shares_memory(series.array(), out)  # no new copy


@pytest.mark.parametrize("values", [[True, False, True], [0, 1, 2.5], [0, 0, 0], [True, 2, 0.5],
                                    [np.float32(1.5), 2.25], [0.5, np.float64(-0.0), 3, 2.5],
                                    [np.nan, 1.0, np.inf]])
def test_series_dtype_is_numpys(values):
    series = Series()
    for v in values:
        series.append(v)
    expected = np.asarray(values)
    assert series.array().dtype == expected.dtype
    np.testing.assert_array_equal(series.array(), expected)


def test_series_refuses_a_row_of_another_shape_and_writes_to_its_array():
    series = Series()
    series.append(np.zeros(3))
    with pytest.raises(ValueError, match="shape"):
        series.append(np.zeros(4))
    with pytest.raises(ValueError, match="shape"):
        series.append(1.0)
    with pytest.raises(ValueError):
        series.array()[0, 0] = 1.0
    assert Series(float).array().shape == (0,)


def test_series_log_needs_every_field():
    class Two(SeriesLog):
        FIELDS = ("a", "b")

    log = Two()
    log.append(a=1.0, b=[1, 2])
    with pytest.raises(ValueError, match="missing"):
        log.append(a=1.0)
    np.testing.assert_array_equal(log.b, [[1, 2]])
    assert len(log) == 1 and set(log.arrays()) == {"a", "b"}
    assert set(GaitLog().arrays()) == set(GaitLog.FIELDS)


class NaiveLog:
    """A SimObserver that records, at each step, what the simulator's log records: per-step
    lists of copies."""

    def __init__(self):
        self.rows = []

    def start(self, sim):
        self.rows = []

    def step(self, sim):
        q, v = sim.state()
        self.rows.append((sim.t, q, v, sim.contact_wrenches_array(),
                          sum((f for _, f in sim.active_pushes), np.zeros(3))))

    def controller_result(self, sim, result):
        pass


def _falling_run(robot, steps: int, observers=()):
    """``steps`` of a robot standing on the floor with a torque that changes every step (clipped
    at its limits some of the time) and a push."""
    sim = Simulator(robot, observers=observers)
    sim.add_push(Push(robot.model.frames[2].name, (0.0, 1.0, 0.0), 50.0, 0.005, 0.02))
    _, hi = robot.torque_bounds(robot.q_ref)
    taus = [np.sin(0.01 * k + np.arange(robot.na)) * 1.2 * hi for k in range(steps)]
    for tau in taus:
        sim.step(tau)
    return sim, np.asarray(taus)


def test_row_log_fields_read_back_as_appended_across_chunks(rng):
    """Fields stored side by side in one row read back, each in its own shape, as np.asarray of
    the values appended (across chunks and between reads); a row missing a field or naming an
    unknown one is refused, naming them."""
    shapes = {"t": (), "q": (5,), "w": (2, 6), "f": (3,)}
    log = RowLog(shapes)
    assert log.q.shape == (0, 5) and log.w.shape == (0, 2, 6) and len(log) == 0
    rows = [{name: rng.normal(size=shape) if shape else float(rng.normal())
             for name, shape in shapes.items()} for _ in range(2 * FIRST_CHUNK + 9)]
    for k, row in enumerate(rows):
        log.append(**row)
        if k in (0, FIRST_CHUNK, 2 * FIRST_CHUNK + 8):
            for name in shapes:
                np.testing.assert_array_equal(getattr(log, name),
                                              np.asarray([r[name] for r in rows[:k + 1]]))
    arrays = log.arrays()
    assert set(arrays) == set(shapes) and len(log) == len(rows)
    assert arrays["w"].shape == (len(rows), 2, 6) and arrays["t"].shape == (len(rows),)
    with pytest.raises(ValueError, match=r"missing \['f'\], unknown \['g'\]"):
        log.append(t=0.0, q=np.zeros(5), w=np.zeros((2, 6)), g=np.zeros(3))
    with pytest.raises(AttributeError):
        log.nothing


def test_sim_log_equals_a_naive_recording(robots):
    """Every series of the log, bit for bit, against per-step lists of the same quantities."""
    robot = robots["hyq"]
    naive = NaiveLog()
    sim, taus = _falling_run(robot, 2 * FIRST_CHUNK + 40, observers=[naive])
    log = sim.log.arrays()
    t, q, v, wrenches, push = (np.asarray(x) for x in zip(*naive.rows))
    np.testing.assert_array_equal(log["t"], t)
    np.testing.assert_array_equal(log["q"], q)
    np.testing.assert_array_equal(log["v"], v)
    np.testing.assert_array_equal(log["contact_wrenches"], wrenches)
    np.testing.assert_array_equal(log["push_force"], push)
    assert np.any(push) and np.any(wrenches)
    np.testing.assert_array_equal(log["tau_command"], taus)
    bounds = [robot.torque_bounds(qk) for qk in q]
    np.testing.assert_array_equal(log["tau_applied"], [np.clip(tk, lo, hi) for tk, (lo, hi)
                                                       in zip(taus, bounds)])
    assert np.any(log["tau_applied"] != log["tau_command"])
    assert list(log["contact_names"]) == list(robot.contact_names)
    sim.reset()
    assert len(sim.log) == 0 and sim.log.q.shape == (0, robot.nq)


def test_sim_log_memory_is_its_numbers(robots):
    """The memory a run keeps (traced by Python) is the log's arrays, about 8 bytes per number per
    step (at most one chunk unfilled), nothing per row besides."""
    robot = robots["hyq"]
    numbers = 1 + robot.nq + robot.nv + 2 * robot.na + 6 * len(robot.contact_names) + 3
    steps = 3000
    sim = Simulator(robot)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        _, hi = robot.torque_bounds(robot.q_ref)
        for k in range(steps):
            sim.step(0.3 * np.sin(0.01 * k) * hi)
        kept = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert len(sim.log) == steps
    data = 8 * numbers * steps
    assert sim.log.nbytes <= 8 * numbers * (steps + min(steps, MAX_CHUNK))
    assert kept <= sim.log.nbytes + 64_000, (kept, data)


def test_sim_log_growth_is_bounded_by_the_chunk():
    """Past MAX_CHUNK rows, the storage exceeds the numbers by at most one chunk of rows."""
    log = SimLog(("a",), 7, 6, 0)
    row = dict(t=0.0, q=np.zeros(7), v=np.zeros(6), tau_command=np.zeros(0),
               tau_applied=np.zeros(0), contact_wrenches=np.zeros((1, 6)), push_force=np.zeros(3))
    steps = 2 * MAX_CHUNK + 5
    for _ in range(steps):
        log.append(**row)
    numbers = 1 + 7 + 6 + 6 + 3
    assert 8 * numbers * steps <= log.nbytes <= 8 * numbers * (steps + MAX_CHUNK)
