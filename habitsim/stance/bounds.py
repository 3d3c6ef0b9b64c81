"""A decoded motion held to its source: its speed, root height and heading bounded.

A decoder off its training data can walk where the source stands, drift in height or
wag the whole body; each bound compares the decoded motion with the source frame for
frame and changes only what leaves the band.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..motion import Motion
from .policy import ConformPolicy, resolve_policy

__all__ = ["bound_speed", "bound_height", "bound_heading"]


def bound_speed(
    out: Motion, source: Motion, policy: ConformPolicy | None = None
) -> tuple[Motion, dict[str, Any] | None]:
    """The decoded motion with its horizontal root speed within ``policy.speed_band`` of the
    source's, and what was changed (``None``: nothing).

    The decoder reads a window of about two seconds; a source that stands and then walks
    off (a real clip's first seconds, a pause between runs) can decode as a target that
    walks the whole time, and legs planted on the source's footfalls (all four feet down
    while it stands) cannot carry a body that travels. Dynamic similarity gives the speed
    the target would have at the source's gait (equal Froude numbers v²/(g·L): v_target
    = v_source·√(L_target / L_source), L the leg length); each frame's decoded velocity
    is scaled so its smoothed speed lies within a factor ``policy.speed_band`` of that
    (below for a standing source, a zero speed). The direction of travel, the height and
    every joint stay the decoder's.
    """
    from scipy.ndimage import gaussian_filter1d

    policy = resolve_policy(policy)

    t = out.num_frames
    if t < 3 or source.num_frames != t:
        return out, None
    sigma = max(1.0, policy.speed_smooth_s * out.fps)
    step = np.diff(out.root_positions[:, :2], axis=0)
    src_step = np.diff(source.root_positions[:, :2], axis=0) * (out.fps / source.fps)
    ratio = float(np.sqrt(out.species_info.leg_length / source.species_info.leg_length))
    v_dec = gaussian_filter1d(np.linalg.norm(step, axis=1), sigma, mode="nearest")
    v_eq = gaussian_filter1d(np.linalg.norm(src_step, axis=1), sigma, mode="nearest") * ratio
    bounded = np.clip(v_dec, v_eq / policy.speed_band, v_eq * policy.speed_band)
    scale = np.where(v_dec > 1e-9, bounded / np.maximum(v_dec, 1e-9), 1.0)
    changed = np.abs(scale - 1.0) > 1e-3
    if not changed.any():
        return out, None
    root = np.array(out.root_positions, dtype=np.float64)
    root[1:, :2] = root[0, :2] + np.cumsum(step * scale[:, None], axis=0)
    moved = Motion(out.species, out.fps, root, out.rotations, out.contacts, dict(out.metadata))
    fps, leg = out.fps, out.species_info.leg_length
    return moved, {
        "frames": int(changed.sum()),
        "speed_per_leg": [
            round(float(v_dec.mean() * fps / leg), 3),
            round(float(bounded.mean() * fps / leg), 3),
        ],
    }


def bound_height(
    out: Motion, source: Motion, policy: ConformPolicy | None = None
) -> tuple[Motion, dict[str, Any] | None]:
    """The decoded motion with its root height's excursions within ``policy.height_band``
    of the source's, and what was changed (``None``: nothing).

    A decoded root height drifts over a clip (one window decodes lower than the next):
    a standing source whose pelvis moves by a few millimetres can come out as a target
    that rises from a crouch, which reads as the start of a jump. Each frame's deviation
    from the clip's median height, in leg lengths, is scaled down where its envelope
    (the largest deviation within ``policy.height_window_s``) exceeds the source's envelope
    times ``policy.height_band`` (at least ``policy.height_floor_per_leg``). A gait's bob, a
    sit or a jump keep their size: the source has it too.
    """
    from scipy.ndimage import gaussian_filter1d, maximum_filter1d

    policy = resolve_policy(policy)

    t = out.num_frames
    if t < 3 or source.num_frames != t:
        return out, None
    leg, src_leg = out.species_info.leg_length, source.species_info.leg_length
    z = out.root_positions[:, 2]
    mid = float(np.median(z))
    dev = (z - mid) / leg
    src_z = source.root_positions[:, 2]
    src_dev = (src_z - float(np.median(src_z))) / src_leg
    size = 2 * max(1, int(round(policy.height_window_s * out.fps))) + 1
    sigma = max(1.0, 0.5 * policy.height_window_s * out.fps)

    def envelope(x: np.ndarray) -> np.ndarray:
        return gaussian_filter1d(maximum_filter1d(np.abs(x), size, mode="nearest"), sigma)

    env, allowed = (
        envelope(dev),
        np.maximum(policy.height_band * envelope(src_dev), policy.height_floor_per_leg),
    )
    scale = np.minimum(1.0, allowed / np.maximum(env, 1e-12))
    changed = scale < 1.0 - 1e-3
    if not changed.any():
        return out, None
    root = np.array(out.root_positions, dtype=np.float64)
    root[:, 2] = mid + dev * scale * leg
    moved = Motion(out.species, out.fps, root, out.rotations, out.contacts, dict(out.metadata))
    return moved, {
        "frames": int(changed.sum()),
        "range_per_leg": [round(float(np.ptp(dev)), 4), round(float(np.ptp(dev * scale)), 4)],
    }


def bound_heading(
    out: Motion, source: Motion, policy: ConformPolicy | None = None
) -> tuple[Motion, dict[str, Any] | None]:
    """The decoded motion with its heading's departures from the source's slowed to
    ``policy.heading_max_rate`` and held within ``policy.heading_band``, and what was changed
    (``None``: nothing).

    A transfer keeps the source's action, turns included: where the decoded pelvis
    heading swings away from the source's faster than any trunk turns (a decoder off
    its training data can wag the whole body by ±90° a few times a second, or spin it
    round, on a backward walk), the heading difference is replaced by its low-pass
    (``policy.heading_smooth_s``), blended in where the swing exceeds the bound, and its
    swing about its own slow trend is clipped to the band. The body turns about the
    pelvis; the root path is kept. A decoded heading that departs slowly (a habitual
    drift, or a turn at the target's own rate) stays as decoded.
    """
    from scipy.ndimage import gaussian_filter1d, maximum_filter1d

    from ..rotations import heading_yaw, quat_from_axis_angle, quat_mul

    policy = resolve_policy(policy)

    t = out.num_frames
    if t < 3 or source.num_frames != t:
        return out, None
    sigma = max(1.0, policy.heading_smooth_s * out.fps)
    # against the source's heading low-passed alike (a mocap pelvis jitters in yaw)
    src = gaussian_filter1d(np.unwrap(heading_yaw(source.rotations[:, 0])), sigma, mode="nearest")
    dev = np.unwrap(heading_yaw(out.rotations[:, 0])) - src
    rate = np.abs(np.gradient(dev)) * out.fps
    new = dev
    if rate.max() > policy.heading_max_rate:
        size = 2 * int(round(sigma)) + 1
        env = gaussian_filter1d(maximum_filter1d(rate, size, mode="nearest"), sigma)
        w = np.clip(env / policy.heading_max_rate - 1.0, 0.0, 1.0)
        new = dev + w * (gaussian_filter1d(dev, sigma, mode="nearest") - dev)
    trend = gaussian_filter1d(dev, max(1.0, policy.heading_trend_s * out.fps), mode="nearest")
    new = trend + np.clip(new - trend, -policy.heading_band, policy.heading_band)
    turn = new - dev
    changed = np.abs(turn) > 1e-6
    if not changed.any():
        return out, None
    rot = np.array(out.rotations, dtype=np.float64, copy=True)
    axis = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (t, 3))
    rot[:, 0] = quat_mul(quat_from_axis_angle(axis, turn), rot[:, 0])
    moved = Motion(out.species, out.fps, out.root_positions, rot, out.contacts, dict(out.metadata))
    after = np.abs(np.gradient(new)) * out.fps
    return moved, {
        "frames": int(changed.sum()),
        "max_rate": [round(float(rate.max()), 2), round(float(after.max()), 2)],
        "max_departure_deg": [
            round(float(np.degrees(np.abs(dev).max())), 1),
            round(float(np.degrees(np.abs(new).max())), 1),
        ],
    }
