"""The .npz motion format (habitsim.motion): bad fields, foreign files and zip bombs are refused
with a typed error; absurd values in a Motion too."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from habitsim.errors import HabitsimError, MotionFileError


def _motion_arrays() -> dict[str, np.ndarray]:
    from habitsim.gaits import generate

    m = generate("dog", "walk", seed=0, duration_s=0.3)
    with np.load(_save(m)) as z:
        return {k: z[k] for k in z.files}


def _save(m) -> Path:
    import tempfile

    p = Path(tempfile.mkdtemp()) / "m.npz"
    m.save(p)
    return p


@pytest.fixture(scope="module")
def arrays() -> dict[str, np.ndarray]:
    return _motion_arrays()


def write_npz(tmp_path: Path, arrays: dict[str, np.ndarray], **changes) -> Path:
    d = {**arrays, **changes}
    d = {k: v for k, v in d.items() if v is not None}
    p = tmp_path / "m.npz"
    with p.open("wb") as fh:
        np.savez(fh, **d)
    return p


NPZ_CASES = {
    "format_version_str": dict(format_version=np.array("1")),
    "format_version_array": dict(format_version=np.array([1, 1])),
    "format_version_nan": dict(format_version=np.array(np.nan)),
    "joint_names_0d": dict(joint_names=np.array("pelvis")),
    "joint_names_numbers": dict(joint_names=np.arange(27)),
    "fps_array": dict(fps=np.array([30.0, 30.0])),
    "fps_str": dict(fps=np.array("30")),
    "fps_huge": dict(fps=np.array(1e300)),
    "fps_tiny": dict(fps=np.array(1e-300)),
    "species_array": dict(species=np.array(["dog", "cat"])),
    "species_number": dict(species=np.array(3)),
    "rotations_str": dict(rotations=np.array([["a"]])),
    "root_str": dict(root_positions=np.array(["x", "y", "z"])),
    "contacts_str": dict(contacts=np.array([["a"] * 4])),
    "metadata_list": dict(metadata_json=np.array("[1, 2]")),
    "metadata_deep": dict(metadata_json=np.array("[" * 100_000 + "]" * 100_000)),
    "metadata_deep_object": dict(metadata_json=np.array('{"a":' + "[" * 200 + "]" * 200 + "}")),
    "metadata_bytes": dict(metadata_json=np.array(b"{}")),
    # an integer past Python's 4,300-digit conversion limit (a raw ValueError before)
    "metadata_big_int": dict(metadata_json=np.array('{"seed": ' + "9" * 5000 + "}")),
    # fields habitsim reads back, of the wrong type
    "metadata_fps_str": dict(metadata_json=np.array('{"fps": "30"}')),
    "metadata_froude_str": dict(metadata_json=np.array('{"froude": "fast"}')),
    "metadata_seed_float": dict(metadata_json=np.array('{"seed": 1.5}')),
    "metadata_params_list": dict(metadata_json=np.array('{"params": [1]}')),
    "metadata_action_number": dict(metadata_json=np.array('{"action": 3}')),
}


@pytest.mark.parametrize("case", sorted(NPZ_CASES))
def test_npz_bad_fields_are_typed(tmp_path: Path, arrays, case: str) -> None:
    from habitsim.motion import load_motion

    p = write_npz(tmp_path, arrays, **NPZ_CASES[case])
    with pytest.raises(HabitsimError) as ei:
        load_motion(p)
    assert len(str(ei.value)) < 400


def test_npz_root_far_away(tmp_path: Path, arrays) -> None:
    from habitsim.errors import InvalidMotionError
    from habitsim.motion import load_motion

    root = arrays["root_positions"].copy()
    root[0, 0] = 1e300
    with pytest.raises(InvalidMotionError, match="root_positions reach"):
        load_motion(write_npz(tmp_path, arrays, root_positions=root))


def test_npy_under_npz_name(tmp_path: Path) -> None:
    from habitsim.motion import load_motion

    p = tmp_path / "m.npz"
    with p.open("wb") as fh:
        np.save(fh, np.zeros(3))
    with pytest.raises(MotionFileError, match="single .npy array"):
        load_motion(p)


def test_non_npz_refused_in_our_words(tmp_path: Path, arrays) -> None:
    from habitsim.motion import load_motion

    p = tmp_path / "m.npz"
    np.savez(p, **arrays, extra=np.array([object()], dtype=object))
    with pytest.raises(MotionFileError) as ei:
        load_motion(p)
    assert "allow_pickle" not in str(ei.value) and "never loads" in str(ei.value)
    p.write_text("hello")
    with pytest.raises(MotionFileError, match="not a zip"):
        load_motion(p)


def test_npz_zip_bomb_is_refused_from_the_headers(tmp_path: Path, arrays) -> None:
    import tracemalloc

    from habitsim.motion import load_motion

    big = np.zeros((40_000, 27, 4, 8))  # 276 MB of zeros, compresses to < 1 MB
    p = tmp_path / "bomb.npz"
    np.savez_compressed(p, **{**arrays, "rotations": big})
    del big
    assert p.stat().st_size < 2 * 2**20
    tracemalloc.start()
    try:
        with pytest.raises(MotionFileError, match="decompress"):
            load_motion(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20 * 2**20


def test_npz_corrupt_array_header(tmp_path: Path, arrays) -> None:
    """A member whose .npy header dict is cut short (numpy raises tokenize.TokenError)."""
    import io
    import zipfile

    from habitsim.motion import load_motion

    p = tmp_path / "m.npz"
    with zipfile.ZipFile(p, "w") as zf:
        for k, v in arrays.items():
            buf = io.BytesIO()
            np.save(buf, v)
            raw = buf.getvalue()
            if k == "fps":  # the header dict left open: {'descr': '<f8', ... (no '}')
                raw = raw.replace(b"}", b" ", 1)
            zf.writestr(f"{k}.npy", raw)
    with pytest.raises(MotionFileError, match="not a readable"):
        load_motion(p)


@pytest.mark.parametrize(
    "kw",
    [
        dict(fps=1e300),
        dict(fps=1e-300),
        dict(fps="30"),
        dict(fps=np.array([30.0])),
        dict(root=1e300),
        dict(root="x"),
    ],
)
def test_motion_absurd_but_finite(kw) -> None:
    from habitsim.motion import Motion
    from habitsim.skeleton import get_skeleton

    root, rot = get_skeleton("dog").standing_pose()
    rp = np.repeat(root[None], 3, axis=0)
    if "root" in kw:
        rp = np.full((3, 3), kw["root"], dtype=object if isinstance(kw["root"], str) else float)
    with pytest.raises(HabitsimError):
        Motion("dog", kw.get("fps", 30.0), rp, np.repeat(rot[None], 3, axis=0))


@pytest.mark.parametrize(
    "case",
    [
        "metadata_big_int",
        "metadata_fps_str",
        "metadata_froude_str",
        "metadata_seed_float",
        "metadata_params_list",
        "metadata_action_number",
    ],
)
def test_npz_metadata_is_a_motion_file_error(tmp_path: Path, arrays, case: str) -> None:
    from habitsim.motion import load_motion

    with pytest.raises(MotionFileError):
        load_motion(write_npz(tmp_path, arrays, **NPZ_CASES[case]))
