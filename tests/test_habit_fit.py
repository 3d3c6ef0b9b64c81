"""A habit latent from reference clips (habitsim.models.habit_fit) and the transfer that
uses it (``transfer(habit_from=...)``, ``habitsim transfer --habit-from``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import run_cli

from habitsim.errors import HabitReferenceError
from habitsim.gaits import generate
from habitsim.models import HabitFitOptions, habit_from_clips, transfer
from habitsim.motion import Motion, load_motion

pytestmark = pytest.mark.usefixtures("torch_one_thread")

FEW = 12  # fit steps: enough to move z, few enough to keep the tests fast


@pytest.fixture(scope="module")
def refs() -> list[Motion]:
    """Two short cat clips (one window each)."""
    return [
        generate("cat", "trot", seed=1, duration_s=2.0),
        generate("cat", "walk", seed=2, duration_s=2.0),
    ]


def test_fit_lowers_the_reference_error_below_the_neighbours_prior(refs):
    opts = HabitFitOptions(init="prior", habit_species="dog", steps=FEW)
    h = habit_from_clips(refs[:1], options=opts)
    assert h.habit_species == "dog" and h.method == "fit" and h.z.shape == (16,)
    assert h.loss < h.loss_start  # start: the dog prior's centre F(0)
    enc = habit_from_clips(refs[:1], options=HabitFitOptions(method="encoder"))
    assert enc.loss == enc.loss_start and enc.habit_species == "cat"


def test_k_shot_uses_every_clip(refs):
    opts = HabitFitOptions(steps=FEW)
    one = [habit_from_clips([r], options=opts) for r in refs]
    both = habit_from_clips(refs, options=opts, names=["a.npz", "b.npz"])
    assert both.windows == one[0].windows + one[1].windows
    assert both.to_metadata()["k"] == 2 and both.clips == ("a.npz", "b.npz")
    for single in one:
        assert not np.allclose(both.z, single.z)


def test_same_clips_and_options_give_the_same_latent(refs):
    opts = HabitFitOptions(steps=FEW)
    a, b = (habit_from_clips(refs[:1], options=opts) for _ in range(2))
    np.testing.assert_array_equal(a.z, b.z)


def test_reference_of_another_species_is_a_typed_error(refs):
    src = generate("dog", "trot", seed=3, duration_s=2.0)
    with pytest.raises(HabitReferenceError) as e:
        transfer(src, "cat", habit_from=[src])
    assert e.value.code == "species"
    assert "dog" in str(e.value) and "cat" in str(e.value)
    with pytest.raises(HabitReferenceError) as e:
        habit_from_clips([refs[0], src])
    assert e.value.code == "species"
    with pytest.raises(HabitReferenceError) as e:
        transfer(src, "cat", method="direct", habit_from=refs)
    assert e.value.code == "method"
    with pytest.raises(HabitReferenceError) as e:
        habit_from_clips(refs, options=HabitFitOptions(init="zero"))
    assert e.value.code == "options"


def test_cli_habit_from_names_the_reference(refs, tmp_path: Path, capsys):
    src, ref, out = tmp_path / "src.npz", tmp_path / "ref_cat.npz", tmp_path / "out.npz"
    generate("dog", "trot", seed=3, duration_s=2.0).save(src)
    refs[0].save(ref)
    argv = ["transfer", src, "--to", "cat", "--habit-from", ref, "--habit-steps", FEW]
    code, _ = run_cli([*argv, "--out", out], capsys)
    assert code == 0
    moved = load_motion(out)
    habit = moved.metadata["transfer"]["habit_from"]
    assert moved.species == "cat" and habit["clips"] == ["ref_cat.npz"] and habit["k"] == 1
    assert habit["fit_loss"] <= habit["fit_loss_start"]
    # a reference of another species: exit 2, nothing written
    out2 = tmp_path / "out2.npz"
    code, err = run_cli(
        ["transfer", src, "--to", "cat", "--habit-from", src, "--out", out2], capsys
    )
    assert code == 2 and "Traceback" not in err and not out2.exists()


def test_stats_objective_fits_the_habits_statistics(refs):
    opts = HabitFitOptions(habit_species="dog", steps=FEW, objective="stats")
    h = habit_from_clips(refs[:1], options=opts)
    frames = habit_from_clips(refs[:1], options=HabitFitOptions(habit_species="dog", steps=FEW))
    assert h.loss < h.loss_start and not np.allclose(h.z, frames.z)
    assert h.loss_start < frames.loss_start  # the statistics agree before the frames do
    with pytest.raises(HabitReferenceError) as e:
        habit_from_clips(refs, options=HabitFitOptions(objective="mean"))
    assert e.value.code == "options"


def test_text_mix_starts_on_the_own_description_and_drives_the_transfer(refs):
    opts = HabitFitOptions(habit_species="dog", steps=FEW, fit_text=True)
    h = habit_from_clips(refs[:1], options=opts)
    assert h.text is not None and h.text.ndim == 1
    w = h.text_weights
    assert list(w)[0] == "cat" and len(w) == 12 and sum(w.values()) == pytest.approx(1.0)
    assert h.loss <= h.loss_start and h.to_metadata()["text_weights"] == pytest.approx(w, abs=1e-4)
    plain = habit_from_clips(refs[:1], options=HabitFitOptions(habit_species="dog", steps=FEW))
    assert plain.text is None and plain.text_weights == {}
    src = generate("dog", "trot", seed=3, duration_s=2.0)
    a = transfer(src, "cat", habit_from=refs[:1], habit_options=opts)
    b = transfer(
        src,
        "cat",
        habit_from=refs[:1],
        habit_options=HabitFitOptions(
            habit_species="dog", steps=FEW, fit_text=True, text_start_share=0.5
        ),
    )
    assert not np.allclose(a.rotations, b.rotations)  # the mix reaches the decoder
