"""Watch a simulation live in MuJoCo's passive viewer, as a
:class:`~wholebody.sim.simulator.SimObserver`: each simulation opens a window that is synced at
``fps`` and paced to real time (``speed`` x), with contact forces, pushes and the CoM shown.

MuJoCo ends the whole process when GLFW cannot start (no display), so :func:`display_problem`
first tries the viewer in a child process.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import threading
import time

import mujoco
import numpy as np

log = logging.getLogger(__name__)

# os._exit: skip the interpreter's teardown, which can hang once the viewer's thread has run
_PROBE = """
import os
import mujoco, mujoco.viewer
m = mujoco.MjModel.from_xml_string("<mujoco/>")
viewer = mujoco.viewer.launch_passive(m, mujoco.MjData(m), show_left_ui=False, show_right_ui=False)
viewer.sync()
running = viewer.is_running()
viewer.close()
os._exit(0 if running else 3)
"""


def display_problem(timeout: float = 60.0) -> str | None:
    """Why MuJoCo's viewer cannot open here, or None if it can: no DISPLAY/WAYLAND_DISPLAY (on
    Linux), or a trial launch in a child process fails."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        return "no display (neither DISPLAY nor WAYLAND_DISPLAY is set)"
    try:
        probe = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                               timeout=timeout)
    except subprocess.TimeoutExpired:
        return f"MuJoCo's viewer did not open within {timeout:g} s"
    if probe.returncode != 0:
        lines = [x for x in (probe.stderr + probe.stdout).splitlines() if x.strip()]
        why = lines[-1].strip() if lines else f"exit code {probe.returncode}"
        return f"MuJoCo's viewer could not open ({why})"
    return None


class LiveView:
    """Shows each simulation it observes in ``mujoco.viewer.launch_passive`` (the twin with the
    robot's skeleton). Closing the window stops the showing, not the simulation. Use as a context
    manager (closes the last window)."""

    draws_twin = True

    def __init__(self, speed: float = 1.0, fps: float = 60.0):
        if not speed > 0 or not fps > 0:
            raise ValueError(f"speed and fps must be > 0, got {speed}, {fps}")
        self.speed, self.fps = float(speed), float(fps)
        self._handle = None

    def start(self, sim) -> None:
        import mujoco.viewer

        self.close()
        before = set(threading.enumerate())
        self._handle = mujoco.viewer.launch_passive(sim.model, sim.data, show_left_ui=False,
                                                    show_right_ui=False)
        self._threads = [t for t in threading.enumerate() if t not in before]
        h = float(sim.robot.q_ref[2])
        with self._handle.lock():
            cam = self._handle.cam  # follows the robot's root body, robot-relative distance
            cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING
            cam.trackbodyid = sim.twin.joint_bodies[sim.robot.model.names[1]]
            cam.distance = 3.0 * h
            cam.azimuth, cam.elevation = 135.0, -15.0
            flags = self._handle.opt.flags
            for flag in (mujoco.mjtVisFlag.mjVIS_CONTACTFORCE, mujoco.mjtVisFlag.mjVIS_PERTFORCE,
                         mujoco.mjtVisFlag.mjVIS_COM):
                flags[flag] = True
        self._every = max(1, int(round(1.0 / (self.fps * sim.dt))))
        self._steps = 0
        self._t0, self._wall0 = sim.t, time.perf_counter()
        self._closed_logged = False
        self._handle.sync()

    def step(self, sim) -> None:
        self._steps += 1
        if self._handle is None or self._steps % self._every:
            return
        if not self._handle.is_running():
            if not self._closed_logged:
                log.info("live view: window closed; the simulation goes on")
                self._closed_logged = True
            return
        self._handle.sync()
        ahead = (sim.t - self._t0) / self.speed - (time.perf_counter() - self._wall0)
        if ahead > 0:
            time.sleep(float(np.minimum(ahead, 1.0)))

    def controller_result(self, sim, result) -> None:
        """The view shows the twin only."""

    def close(self) -> None:
        """Close the window and wait for the viewer's thread to end (a process that exits while
        that thread tears down GLFW crashes)."""
        if self._handle is not None:
            self._handle.close()
            self._handle = None
            for thread in self._threads:
                thread.join(timeout=10.0)

    def __enter__(self) -> "LiveView":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
