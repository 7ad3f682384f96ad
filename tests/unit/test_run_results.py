"""A run's result is never lost or false: summary.json is written whole or not at all, and a run
that ends with an error still leaves its summary, marked incomplete, with the reason."""

import json
import threading

from wholebody.cli import main
from wholebody.scenarios.base import Scenario, ScenarioResult


def _result(tag: str, size: int) -> ScenarioResult:
    return ScenarioResult("stand", "talos14", "standing", True,
                          {"tag": tag, "padding": [tag] * size}, {"duration": 1.0})


def test_concurrent_writers_never_leave_a_torn_summary(tmp_path):
    """Two writers of summaries of different sizes and a reader polling the file: every read
    that finds the file parses, as one writer's whole summary."""
    stop = threading.Event()
    bad, reads = [], [0]

    def writer(tag, size):
        result = _result(tag, size)
        while not stop.is_set():
            result.write(tmp_path)

    def reader():
        path = tmp_path / "summary.json"
        while not stop.is_set():
            try:
                text = path.read_text()
            except FileNotFoundError:
                continue
            reads[0] += 1
            try:
                summary = json.loads(text)
            except ValueError:
                bad.append(text[:80])
                continue
            if summary["metrics"]["padding"] != [summary["metrics"]["tag"]] * {
                    "a": 5000, "b": 50}[summary["metrics"]["tag"]]:
                bad.append("mixed")

    threads = [threading.Thread(target=writer, args=("a", 5000)),
               threading.Thread(target=writer, args=("b", 50)), threading.Thread(target=reader)]
    for t in threads:
        t.start()
    threading.Event().wait(3.0)
    stop.set()
    for t in threads:
        t.join()
    assert reads[0] > 100
    assert not bad, bad[:3]
    assert [p.name for p in tmp_path.iterdir()] == ["summary.json"]  # no temporary left


def test_a_scenario_error_leaves_a_summary_marked_incomplete(tmp_path, capsys, monkeypatch):
    """An error raised by the scenario (here after the robot was built and checked) ends the run
    with exit 1, one line on stderr, and summary.json with completed false and the reason."""
    def broken(self, *args, **kwargs):
        raise RuntimeError("the figure writer failed")

    monkeypatch.setattr(Scenario, "run", broken)
    out = tmp_path / "out"
    assert main(["run", "stand", "--robot", "talos14", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "ERROR: RuntimeError: the figure writer failed" in err and "Traceback" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and summary["success"] is False
    assert summary["error"] == "RuntimeError: the figure writer failed"
    assert summary["parameters"]["duration"] == 5.0


def test_a_run_that_ends_normally_is_complete(tmp_path):
    out = tmp_path / "out"
    assert main(["run", "stand", "--robot", "talos14", "--set", "duration=0.2", "--out",
                 str(out)]) in (0, 1)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is True and "error" not in summary


def test_a_figure_that_cannot_be_written_loses_nothing_else(tmp_path, monkeypatch):
    """A full disk when the figure is saved: the run keeps its verdict and metrics, its summary
    lists no figure and says which one was not written."""
    import errno

    from matplotlib.figure import Figure

    def full(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Figure, "savefig", full)
    out = tmp_path / "out"
    assert main(["run", "stand", "--robot", "talos14", "--set", "duration=0.3", "--out",
                 str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is True and summary["success"] is True
    assert summary["metrics"] and summary["figures"] == []
    assert any("not written" in note and "stand.png" in note for note in summary["notes"])
    assert not list(out.glob("*.png"))


def test_a_second_run_on_a_busy_output_folder_is_refused(tmp_path, capsys):
    """While one command holds the output folder (here this test, as a second process would),
    a run there exits 2 before simulating, naming the holder; once it is free, it runs."""
    from wholebody.outputs import claim_output

    out = tmp_path / "out"
    with claim_output(out):
        assert main(["run", "stand", "--set", "duration=0.2", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "in use by another wholebody command (pid" in err
        assert not (out / "summary.json").exists()
    assert main(["run", "stand", "--set", "duration=0.2", "--out", str(out)]) in (0, 1)
