"""A meshcat animation kept as numbers and packed track by track: :class:`TrackAnimation`.

meshcat's own ``Animation`` keeps every keyframe as Python objects (a list of numpy scalars per
position, a dict per key once lowered) and packs the whole ``set_animation`` command at once: a
few hundred bytes per keyframe, several times over. A replay of a long run has millions of
keyframes. :class:`TrackAnimation` takes the same calls (``at_frame(vis, k)[path]`` then
``set_transform`` or ``set_property``) and stores each track's frames and values in numpy chunks
(:class:`~wholebody.sim.series.Series`; numbers as float32, which is the precision the packed
command carries anyway); :meth:`TrackAnimation.packed_command` writes the msgpack bytes of the
``set_animation`` command one clip at a time. The bytes are those meshcat's ``Animation`` would
give packed with ``force_float_precision="single"``.
"""

from __future__ import annotations

import struct

import numpy as np
from meshcat.animation import js_position, js_quaternion

from ..sim.series import Series


class _Track:
    """One property of one node: the frames it is set at and its values there."""

    def __init__(self, name: str, jstype: str):
        self.name, self.jstype = name, jstype
        self.frames = Series(np.int64)
        self.values: Series | list | None = None

    def add(self, frame: int, value) -> None:
        if self.values is None:
            kind = np.asarray(value).dtype.kind
            self.values = Series(bool if kind == "b" else np.float32) if kind in "bf" else []
        self.frames.append(int(frame))
        self.values.append(value)

    def lower(self) -> dict:
        """meshcat's lowered track: keys in order of frame (equal frames in the order set)."""
        frames = self.frames.array()
        order = np.argsort(frames, kind="stable")
        if isinstance(self.values, Series):
            values = self.values.array()[order].tolist()
        else:
            values = [self.values[i] for i in order]
        return {"name": "." + self.name, "type": self.jstype,
                "keys": [{"time": f, "value": v} for f, v in zip(frames[order].tolist(), values)]}


class _Clip:
    def __init__(self, fps: float):
        self.fps = fps
        self.tracks: dict[str, _Track] = {}

    def set_property(self, frame: int, prop: str, jstype: str, value) -> None:
        if prop not in self.tracks:
            self.tracks[prop] = _Track(prop, jstype)
        self.tracks[prop].add(frame, value)

    def packed(self, pack) -> bytes:
        """meshcat's lowered clip packed with ``pack``, one track at a time."""
        return b"".join([b"\x83", pack("fps"), pack(self.fps), pack("name"), pack("default"),
                         pack("tracks"), _array_header(len(self.tracks)),
                         *(pack(t.lower()) for t in self.tracks.values())])


class _FrameWriter:
    """``animation.at_frame(vis, k)``: sets properties of the nodes under ``path`` at frame k."""

    __slots__ = ("animation", "path", "frame")

    def __init__(self, animation: "TrackAnimation", path, frame: int):
        self.animation, self.path, self.frame = animation, path, frame

    def __getitem__(self, name: str) -> "_FrameWriter":
        return _FrameWriter(self.animation, self.path.append(name), self.frame)

    def set_transform(self, matrix) -> None:
        clip = self.animation.clip(self.path.lower())
        clip.set_property(self.frame, "position", "vector3", js_position(matrix))
        clip.set_property(self.frame, "quaternion", "quaternion", js_quaternion(matrix))

    def set_property(self, prop: str, jstype: str, value) -> None:
        self.animation.clip(self.path.lower()).set_property(self.frame, prop, jstype, value)


class TrackAnimation:
    """An animation of meshcat nodes (see the module docstring); ``default_framerate`` is the
    clips' frame rate (frames per second of the page's player)."""

    def __init__(self, default_framerate: float = 30):
        self.default_framerate = default_framerate
        self.clips: dict[str, _Clip] = {}

    def at_frame(self, visualizer, frame: int) -> _FrameWriter:
        return _FrameWriter(self, visualizer.path, frame)

    def clip(self, path: str) -> _Clip:
        if path not in self.clips:
            self.clips[path] = _Clip(self.default_framerate)
        return self.clips[path]

    def packed_command(self, play: bool = False, repetitions: int = 1) -> bytes:
        """The msgpack bytes of meshcat's ``set_animation`` command of this animation (floats in
        single precision), packed one clip at a time."""
        import umsgpack

        def pack(obj) -> bytes:
            return umsgpack.packb(obj, force_float_precision="single")

        parts = [b"\x84", pack("type"), pack("set_animation"), pack("animations"),
                 _array_header(len(self.clips))]
        for path, clip in self.clips.items():
            parts += [b"\x82", pack("path"), pack(path), pack("clip"), clip.packed(pack)]
        parts += [pack("options"), pack({"play": play, "repetitions": repetitions}),
                  pack("path"), pack("")]
        return b"".join(parts)


def _array_header(n: int) -> bytes:
    """The msgpack header of an array of ``n`` elements."""
    if n < 16:
        return bytes([0x90 | n])
    if n < 1 << 16:
        return b"\xdc" + struct.pack(">H", n)
    return b"\xdd" + struct.pack(">I", n)
