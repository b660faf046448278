"""Rigid body animation of scenes: keyframes (slerped rotations, linear translations), the presets
(``head_turn``, ``nod``, ``hairball``) and the ``[[bodies]]`` table of a scene file.

Rotations are :mod:`taichi_hair.rotation` quaternions, (x, y, z, w).  A scene file's
``quaternion = [w, x, y, z]`` keeps its documented order: it is converted when read, and the scene
description (the checkpoint fingerprint) keeps writing (w, x, y, z).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..rotation import (euler_to_matrix, quat_from_matrix_np, quat_from_wxyz, quat_slerp_np, quat_to_matrix_np,
                        quat_to_wxyz)
from .schema import Table, at_least, positive

PRESETS = ("still", "head_turn", "nod", "hairball")


@dataclass
class Keyframe:
    """One key of a rigid body animation.

    Attributes:
        time: time of the key [s].
        rotation: unit quaternion (x, y, z, w) of the body rotation (:mod:`taichi_hair.rotation`) [-].
        translation: body translation [m].
    """

    time: float
    rotation: np.ndarray
    translation: np.ndarray


@dataclass
class BodyAnimation:
    """Rigid transform of one body over time: keyframes, or a function of time.

    Attributes:
        keys: keyframes in increasing time (used when ``function`` is None).
        interpolation: ``"smooth"`` (smoothstep easing within each segment: the body stops at every
            key, so accelerations stay finite) or ``"linear"`` (constant angular velocity between keys).
        function: optional ``function(time [s]) -> 3x3 rotation`` (the named scenes' continuous motions).
        pivot: the rotation is about this point of the body frame [m]: T_total = T + pivot - R pivot.
        description: JSON-able description (for the checkpoint fingerprint and summaries).
    """

    keys: list = field(default_factory=list)
    interpolation: str = "smooth"
    function: object = None
    pivot: tuple = (0.0, 0.0, 0.0)
    description: dict = field(default_factory=dict)

    def transform(self, time: float):
        """(rotation 3x3 [-], translation (3,) [m]) at ``time`` [s]."""
        if self.function is not None:
            R, T = np.asarray(self.function(time), np.float64), np.zeros(3)
        elif not self.keys:
            R, T = np.eye(3), np.zeros(3)
        else:
            ks = self.keys
            if time <= ks[0].time:
                q, T = ks[0].rotation, ks[0].translation
            elif time >= ks[-1].time:
                q, T = ks[-1].rotation, ks[-1].translation
            else:
                i = int(np.searchsorted([k.time for k in ks], time, side="right")) - 1
                a, b = ks[i], ks[i + 1]
                u = (time - a.time) / (b.time - a.time)
                if self.interpolation == "smooth":
                    u = u * u * (3 - 2 * u)
                q = quat_slerp_np(a.rotation, b.rotation, u)
                T = (1 - u) * a.translation + u * b.translation
            R = quat_to_matrix_np(q)
        p = np.asarray(self.pivot, np.float64)
        return R, np.asarray(T, np.float64) + p - R @ p


def preset_keys(preset: str, axis, amplitude: float, period: float, start: float, cycles: int):
    """head_turn / nod as keys: rest, +amplitude, -amplitude, rest per cycle, about ``axis``."""
    keys = [Keyframe(0.0, np.array([0.0, 0, 0, 1]), np.zeros(3))]
    a = np.asarray(axis, np.float64)

    def q(angle_deg):
        h = math.radians(angle_deg) / 2
        return np.r_[math.sin(h) * a, math.cos(h)]

    t = start
    for _ in range(cycles):
        for frac, ang in ((0.25, amplitude), (0.75, -amplitude), (1.0, 0.0)):
            keys.append(Keyframe(t + frac * period, q(ang), np.zeros(3)))
        t += period
    if start > 0:
        keys.insert(1, Keyframe(start, np.array([0.0, 0, 0, 1]), np.zeros(3)))
    return keys


def body_from_table(t: Table) -> BodyAnimation:
    """The animation of one ``[[bodies]]`` table (keys or a preset), its description in the file's terms."""
    pivot = t.get("pivot", "vec3", (0.0, 0.0, 0.0))
    if t.has("preset") and t.has("keys"):
        t.fail("give either 'preset' or 'keys', not both")
    if t.has("keys"):
        interp = t.get("interpolation", "str", "smooth", lambda v: None if v in ("smooth", "linear") else
                       f"must be 'smooth' or 'linear', got {v!r}")
        raw = t.get("keys", "list")
        keys, desc_keys = [], []
        for i, k in enumerate(raw):
            kt = Table(t.path, f"{t.name}.keys[{i}]", k)
            time = kt.get("time", "float", None)
            if time is None:
                kt.fail("missing key 'time'")
            if kt.has("euler") and kt.has("quaternion"):
                kt.fail("give 'euler' or 'quaternion', not both")
            if kt.has("quaternion"):  # the file writes (w, x, y, z)
                q = np.asarray(kt.get("quaternion", "vec4"))
                if np.linalg.norm(q) < 1e-12:
                    kt.fail("must not be zero", "quaternion")
                q = quat_from_wxyz(q / np.linalg.norm(q))
            else:
                q = quat_from_matrix_np(euler_to_matrix(kt.get("euler", "vec3", (0.0, 0.0, 0.0))))
            tr = np.asarray(kt.get("translation", "vec3", (0.0, 0.0, 0.0)))
            kt.done()
            if keys and time <= keys[-1].time:
                kt.fail(f"times must increase (key {i - 1} is at {keys[-1].time} s)", "time")
            keys.append(Keyframe(time, q, tr))
            desc_keys.append([time, quat_to_wxyz(q).tolist(), tr.tolist()])  # (w, x, y, z): fingerprints keep
        t.done()
        return BodyAnimation(keys=keys, interpolation=interp, pivot=pivot,
                             description={"keys": desc_keys, "interpolation": interp, "pivot": list(pivot)})
    preset = t.get("preset", "str", "still", lambda v: None if v in PRESETS else
                   f"must be one of {', '.join(PRESETS)}, got {v!r}")
    desc = {"preset": preset, "pivot": list(pivot)}
    if preset == "still":
        t.done()
        return BodyAnimation(pivot=pivot, description=desc)
    if preset == "hairball":
        t.done()
        from .builtin import hairball_rotation

        return BodyAnimation(function=hairball_rotation, pivot=pivot, description=desc)
    default_amp = 40.0 if preset == "head_turn" else 15.0
    amp = t.get("amplitude", "float", default_amp)
    period = t.get("period", "float", 2.0 if preset == "head_turn" else 1.5, positive)
    start = t.get("start", "float", 0.25, at_least(0.0))
    cycles = t.get("cycles", "int", 1, at_least(1))
    t.done()
    axis = (0.0, 1.0, 0.0) if preset == "head_turn" else (1.0, 0.0, 0.0)
    desc.update(amplitude=amp, period=period, start=start, cycles=cycles)
    return BodyAnimation(keys=preset_keys(preset, axis, amp, period, start, cycles), pivot=pivot,
                         description=desc)

