"""Transfer (habitsim.transfer, habitsim.transfer_methods, habitsim.models.transfer): the
method registry, the footfall schedule a transfer keeps, and conforming a decoded motion
(speed, height and heading bounds, levelling, frame count)."""

from __future__ import annotations

import numpy as np
import pytest

from habitsim.gaits import generate
from habitsim.motion import Motion
from habitsim.stance.policy import ConformPolicy
from habitsim.stance.schedule import transfer_contacts

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def test_transfer_labels_come_from_the_decoded_contacts_checked_against_the_source():
    src = generate("dog", "trot", seed=5, duration_s=2.0)
    out = Motion("horse", src.fps, src.root_positions * 2.0, src.rotations)
    labels, info = transfer_contacts(out, src, src.contacts)
    assert info["method"] == "decoded" and info["source_f1"] == [1.0] * 4
    np.testing.assert_array_equal(labels, src.contacts)
    # a decoded foot that disagrees with the source's footfalls takes the source's schedule
    bad = src.contacts.copy()
    bad[:, 2] = ~bad[:, 2]
    labels, info = transfer_contacts(out, src, bad)
    assert info["source_f1"][2] < ConformPolicy().min_source_agreement <= min(info["source_f1"][:2])
    assert info["feet_from_source"] == ["LH"]
    np.testing.assert_array_equal(labels, src.contacts)
    # a decoded foot that stands far longer than the source's (a high F1 all the same)
    # takes the source's schedule too
    long = src.contacts.copy()
    long[:, 0] |= np.roll(long[:, 0], 4) | np.roll(long[:, 0], 8)
    labels, info = transfer_contacts(out, src, long)
    assert info["duty"][0] - info["source_duty"][0] > ConformPolicy().max_duty_gap
    assert info["feet_from_source"] == ["LF"]
    np.testing.assert_array_equal(labels, src.contacts)
    # without decoded contacts (direct) the source's schedule is used as such
    labels, info = transfer_contacts(out, src)
    assert info["method"] == "source"
    np.testing.assert_array_equal(labels, src.contacts)
