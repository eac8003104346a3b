"""An animation of a skeleton: immutable, time-major arrays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usdhands.errors import InvalidAnimationError
from usdhands.model.rotations import check_quat, quat_slerp, trs_to_xform
from usdhands.model.skeleton import Skeleton, forward_kinematics, readonly

__all__ = ["Clip", "MAX_JOINT_FRAMES", "MAX_FILLED_JOINT_FRAMES", "FILL_RATIO", "clip_size_problem", "resampled_frames"]


#: Largest translation or scale component a clip may hold: far beyond any scene, and far
#: enough below 32-bit floats' 3.4e38 (glTF, USD) that unit conversions cannot overflow them.
MAX_MAGNITUDE = 1e30

#: Most frames x joints a reader allocates for one clip (80 bytes each as the clip's float64
#: rotations, translations and scales): an hour of capture at 120 fps on a 200-joint skeleton is
#: 86.4 million (6.9 GB), and reads.
MAX_JOINT_FRAMES = 100_000_000
#: Most frames x joints a reader fills in itself, where the file holds values for fewer than one in
#: :data:`FILL_RATIO` of them (keys far apart interpolated, joints without channels held at rest):
#: 800 MB of arrays, 43 minutes at 60 fps of 65 joints. A few bytes could otherwise ask for
#: gigabytes: a .usdz of 4 time samples, the last at time code 209,722, read 209,723 frames x 65
#: joints (2.2 GB); a 200 KB BVH of 6,001 joints, one with a channel, read 20,000 frames (15 GB).
MAX_FILLED_JOINT_FRAMES = 10_000_000
#: Joint-frames a clip may hold per joint-frame the file holds values for before
#: :data:`MAX_FILLED_JOINT_FRAMES` applies (a capture: 1; keys every 5th frame: 5; a BVH's End Sites: ~1.3).
FILL_RATIO = 16


def clip_size_problem(frames: int, joints: int, held) -> str | None:
    """Why a reader refuses a clip of ``frames`` x ``joints``, or None; called before any array is allocated.

    ``held``: the joint-frames the file holds values for (per animated joint, the key times of
    its channel with the most; a capture file of a key per joint and frame: ``frames * joints``),
    an int or a function of no arguments giving it (called only for a clip past
    :data:`MAX_FILLED_JOINT_FRAMES`: a reader's count over its channels costs nothing on small clips).
    The reader raises its own error with the message.
    """
    size = int(frames) * int(joints)
    if size > MAX_JOINT_FRAMES:
        return f"{frames:,} frames x {joints:,} joints: more than {MAX_JOINT_FRAMES:,} joint-frames are refused"
    if size > MAX_FILLED_JOINT_FRAMES and size > FILL_RATIO * (held := held() if callable(held) else held):
        return (f"{frames:,} frames x {joints:,} joints from values for {held:,} joint-frames: more than "
                f"{MAX_FILLED_JOINT_FRAMES:,} joint-frames, over {FILL_RATIO} per value the file holds, are refused")
    return None


def resampled_frames(num_frames: int, fps: float, to_fps: float) -> int:
    """Frames :meth:`Clip.resample` gives ``num_frames`` frames at ``fps`` resampled to ``to_fps``: those of
    ``[0, duration]`` at the new rate (the same count where the rates agree or there is one frame)."""
    if abs(to_fps - fps) < 1e-9 or num_frames < 2:
        return num_frames
    return int(np.floor((num_frames - 1) / fps * to_fps + 1e-6)) + 1


def _owned_readonly(a: np.ndarray, given) -> np.ndarray:
    """``a`` (float64, made from ``given``) read-only, copied only where it may still be written through ``given``.

    A conversion (float32 arrays of a reader, lists) already made a new array: that one
    is kept instead of copied a second time (a 10,000-frame, 65-joint clip: 26 MB less).
    A read-only, C-contiguous float64 array that owns its memory (another clip's, or one
    a reader made and locked) is shared as it is: nothing writes to it.
    """
    if a.base is not None or not a.flags.c_contiguous:
        return readonly(a)
    if given is not None and isinstance(given, np.ndarray) and np.may_share_memory(a, given):
        return a if not a.flags.writeable else readonly(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Clip:
    """A skeleton animated over time.

    Every joint of the skeleton has a value at every frame (readers fill joints the
    file does not animate from the rest pose).

    Parameters
    ----------
    skeleton : Skeleton
        The joints animated, J of them.
    fps : float
        Frames per second.
    rotations : (T, J, 4) float
        Local rotations, unit quaternions xyzw.
    translations : (T, J, 3) float, optional
        Local translations in asset units; the rest translations when omitted.
    scales : (T, J, 3) float, optional
        Local scales; the rest scales when omitted.
    name : str
        Name of the animation in its file.
    start_time : float
        Time of frame 0 in seconds (USD time code / fps, glTF seconds).
    """

    skeleton: Skeleton
    fps: float
    rotations: np.ndarray
    translations: np.ndarray | None = None
    scales: np.ndarray | None = None
    name: str = "animation"
    start_time: float = 0.0

    def __post_init__(self) -> None:
        sk = self.skeleton
        J = sk.num_joints
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"Expected fps > 0, got {self.fps}")
        q = check_quat(self.rotations, "rotations")
        if q.ndim != 3 or q.shape[1] != J:
            raise ValueError(f"Expected rotations to have shape (T, {J}, 4), got {q.shape}")
        T = q.shape[0]
        t = self.translations
        t = np.broadcast_to(sk.rest_translations, (T, J, 3)) if t is None else np.asarray(t, dtype=np.float64)
        if t.shape != (T, J, 3):
            raise ValueError(f"Expected translations to have shape ({T}, {J}, 3), got {t.shape}")
        s = self.scales
        s = np.broadcast_to(sk.rest_scales, (T, J, 3)) if s is None else np.asarray(s, dtype=np.float64)
        if s.shape != (T, J, 3):
            raise ValueError(f"Expected scales to have shape ({T}, {J}, 3), got {s.shape}")
        set_ = object.__setattr__
        set_(self, "fps", float(self.fps))
        set_(self, "rotations", _owned_readonly(q, self.rotations))
        set_(self, "translations", _owned_readonly(t, self.translations))
        set_(self, "scales", _owned_readonly(s, self.scales))
        set_(self, "start_time", float(self.start_time))

    # -- checks ---------------------------------------------------------------
    def validate(self, path: str | None = None) -> "Clip":
        """Raise :class:`InvalidAnimationError` for zero frames, NaN or zero-length quaternions, or
        translations and scales beyond :data:`MAX_MAGNITUDE`."""
        if self.num_frames == 0:
            raise InvalidAnimationError(f"animation {self.name!r} has zero frames", path=path)
        if self._plainly_valid():
            return self
        for label, arr in (("rotations", self.rotations), ("translations", self.translations),
                           ("scales", self.scales)):
            bad = ~np.isfinite(arr).all(axis=-1)
            if bad.any():
                f, j = np.argwhere(bad)[0]
                raise InvalidAnimationError(
                    f"animation {self.name!r} has NaN or infinite {label} "
                    f"(joint {self.skeleton.joint_names[j]!r}, frame {f})", path=path)
        for label, arr in (("translations", self.translations), ("scales", self.scales)):
            bad = (np.abs(arr) > MAX_MAGNITUDE).any(axis=-1)
            if bad.any():  # written as 32-bit floats they became infinite (BVH root positions of 1e308)
                f, j = np.argwhere(bad)[0]
                raise InvalidAnimationError(
                    f"animation {self.name!r} has {label} beyond {MAX_MAGNITUDE:g} "
                    f"(joint {self.skeleton.joint_names[j]!r}, frame {f})", path=path)
        norms = np.linalg.norm(self.rotations, axis=-1)
        bad = norms < 1e-6
        if bad.any():
            f, j = np.argwhere(bad)[0]
            raise InvalidAnimationError(
                f"animation {self.name!r} has a zero-length quaternion "
                f"(joint {self.skeleton.joint_names[j]!r}, frame {f})", path=path)
        return self

    def _plainly_valid(self) -> bool:
        """True when none of :meth:`validate`'s checks can fail, from whole-array extremes and the
        quaternions' squared lengths (a few passes, no temporary of an array's size: a 10,000-frame,
        65-joint clip in ~6 ms instead of ~42); False sends ``validate`` to its element-wise checks,
        which name the first bad value or pass. NaN makes every comparison false."""
        q = self.rotations
        if q.size == 0:
            return False
        with np.errstate(over="ignore", under="ignore", invalid="ignore"):
            if not (np.isfinite(q.min()) and np.isfinite(q.max())):
                return False
            if not np.einsum("...i,...i->...", q, q).min() > 1e-11:  # every length over 3.1e-6 (the check: 1e-6)
                return False
            for arr in (self.translations, self.scales):
                if not (-MAX_MAGNITUDE <= arr.min() and arr.max() <= MAX_MAGNITUDE):
                    return False
        return True

    # -- sizes ----------------------------------------------------------------
    @property
    def num_frames(self) -> int:
        """Number of frames T."""
        return self.rotations.shape[0]

    @property
    def num_joints(self) -> int:
        """Number of joints J."""
        return self.skeleton.num_joints

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return max(self.num_frames - 1, 0) / self.fps

    @property
    def times(self) -> np.ndarray:
        """Time of each frame in seconds, ``(T,)``."""
        return self.start_time + np.arange(self.num_frames) / self.fps

    # -- derived copies --------------------------------------------------------
    def replace(self, **changes) -> "Clip":
        """A copy with some fields changed (arrays are copied and validated)."""
        fields = dict(skeleton=self.skeleton, fps=self.fps, rotations=self.rotations,
                      translations=self.translations, scales=self.scales, name=self.name,
                      start_time=self.start_time)
        fields.update(changes)
        return Clip(**fields)

    def slice(self, start: int, stop: int | None = None) -> "Clip":
        """Frames ``start`` to ``stop`` (exclusive), like Python slicing with step 1."""
        sl = slice(start, stop)
        first = range(self.num_frames)[sl]
        t0 = self.start_time + (first[0] / self.fps if len(first) else 0.0)
        return self.replace(rotations=self.rotations[sl], translations=self.translations[sl],
                            scales=self.scales[sl], start_time=t0)

    def resample(self, fps: float) -> "Clip":
        """The same motion sampled at ``fps``: slerp for rotations, linear otherwise.

        The new frames cover ``[0, duration]``; the last frame lands on or before the
        old last frame's time.
        """
        fps = float(fps)
        if not fps > 0:
            raise ValueError(f"Expected fps > 0, got {fps}")
        if abs(fps - self.fps) < 1e-9 or self.num_frames < 2:
            return self.replace(fps=fps)
        n = resampled_frames(self.num_frames, self.fps, fps)
        src = np.arange(n) / fps * self.fps
        i0 = np.clip(np.floor(src).astype(int), 0, self.num_frames - 2)
        w = np.clip(src - i0, 0.0, 1.0)
        rot = quat_slerp(self.rotations[i0], self.rotations[i0 + 1], np.broadcast_to(w[:, None], (n, self.num_joints)))
        lin = lambda a: a[i0] * (1 - w)[:, None, None] + a[i0 + 1] * w[:, None, None]  # noqa: E731
        return self.replace(fps=fps, rotations=rot, translations=lin(self.translations),
                            scales=lin(self.scales))

    def with_joint_rotations(self, joints: list[int], rotations: np.ndarray) -> "Clip":
        """A copy with new local rotations ``(T, len(joints), 4)`` for the given joints."""
        rot = np.array(self.rotations)
        rot[:, joints] = rotations
        return self.replace(rotations=rot)

    def with_meters_per_unit(self, meters_per_unit: float) -> "Clip":
        """The same clip in other units (translations and rest rescaled)."""
        f = self.skeleton.meters_per_unit / float(meters_per_unit)
        return self.replace(skeleton=self.skeleton.with_meters_per_unit(meters_per_unit),
                            translations=self.translations * f)

    # -- kinematics ------------------------------------------------------------
    def local_xforms(self) -> np.ndarray:
        """Local transforms ``(T, J, 4, 4)``."""
        return trs_to_xform(self.translations, self.rotations, self.scales)

    def world_xforms(self) -> np.ndarray:
        """World transforms ``(T, J, 4, 4)`` by forward kinematics, asset units."""
        return forward_kinematics(self.skeleton.parents, self.local_xforms())

    def world_positions(self) -> np.ndarray:
        """World joint positions ``(T, J, 3)``, asset units."""
        return self.world_xforms()[..., :3, 3]

    def world_positions_cm(self) -> np.ndarray:
        """World joint positions ``(T, J, 3)`` in centimetres."""
        return self.world_positions() * (self.skeleton.meters_per_unit * 100.0)
