"""TrackAnimation packs the same set_animation command as meshcat's own Animation, byte for byte,
and keeps its keyframes as numbers."""

import tracemalloc

import numpy as np
import pinocchio as pin
import pytest

meshcat = pytest.importorskip("meshcat")
umsgpack = pytest.importorskip("umsgpack")

from meshcat.animation import Animation  # noqa: E402
from meshcat.commands import SetAnimation  # noqa: E402

from wholebody.report.animation_tracks import TrackAnimation  # noqa: E402


class _NoWindow:
    def send(self, command):
        pass


def _animate(animation, frames, seed=0):
    """Transforms, visibility and a scale on a few nodes; some frames out of order, one frame
    set twice, one node set at a few frames only."""
    vis = meshcat.Visualizer(window=_NoWindow())
    rng = np.random.default_rng(seed)
    order = [0, 5, 2, *range(3, frames), 4]
    for k in order:
        frame = animation.at_frame(vis, k)
        T = np.eye(4)
        T[:3, :3] = pin.Quaternion(*rng.normal(size=4)).normalized().toRotationMatrix()
        T[:3, 3] = rng.normal(size=3)
        frame["run0/robot/visuals/link"].set_transform(T)
        frame["run0/forces/foot"].set_property("visible", "bool", bool(k % 3))
        frame["run0/forces/foot"]["shaft"].set_property("scale", "vector3",
                                                         [1.0, float(rng.normal()), 1.0])
        if k in (0, 7):
            frame["run0/footsteps/0"].set_property("visible", "bool", k >= 7)
    return animation


@pytest.mark.parametrize("frames", [3, 40])
def test_packed_command_equals_meshcats(frames):
    expected = umsgpack.packb(SetAnimation(_animate(Animation(default_framerate=40.0), frames),
                                           play=False, repetitions=1).lower(),
                              force_float_precision="single")
    packed = _animate(TrackAnimation(default_framerate=40.0), frames).packed_command(
        play=False, repetitions=1)
    assert packed == expected
    command = umsgpack.unpackb(packed)
    assert command["type"] == "set_animation" and len(command["animations"]) == 4


def test_keyframes_cost_their_numbers():
    """Per keyframe of a transform (position and quaternion: 7 float32 and 2 frame numbers) the
    memory kept stays within a small multiple of those 44 bytes (meshcat's Animation keeps
    several hundred)."""
    frames = 3000
    vis = meshcat.Visualizer(window=_NoWindow())
    T = np.eye(4)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        animation = TrackAnimation(default_framerate=40.0)
        for k in range(frames):
            T[0, 3] = 1e-3 * k
            animation.at_frame(vis, k)["a"].set_transform(T)
        kept = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert kept < 3 * 44 * frames + 20_000, kept
