"""Videos of tracking runs: the reference as a ghost beside the body, stance marks, species
colours and the floor drawn low — all in the rendering scene, never in the model."""

from __future__ import annotations

import numpy as np
import pytest

from habitsim import render, render_side
from habitsim.qpos import load_species_model

pytestmark = [
    pytest.mark.skipif(
        not render.render_available(), reason="no OpenGL backend for off-screen rendering"
    ),
    pytest.mark.slow,
]

W, H = 320, 240


@pytest.fixture(scope="module")
def dog():
    return load_species_model("dog")


def _home(model, frames: int = 1) -> np.ndarray:
    return np.tile(model.key_qpos[model.key("home").id], (frames, 1))


def _mask(img: np.ndarray, rgb: tuple[int, int, int], tol: int = 40) -> np.ndarray:
    return np.all(np.abs(img.astype(int) - np.array(rgb)) < tol, axis=-1)


def test_ghost_is_drawn_beside_the_body(dog) -> None:
    q = _home(dog)
    green = render.GhostStyle(alpha=1.0, ghost_rgb=(0.0, 1.0, 0.0))
    plain = render.render_frames(
        dog, q, width=W, height=H, reference=q, species="dog", style=render.GhostStyle(alpha=0.0)
    )[0]
    ghost = render.render_frames(
        dog, q, width=W, height=H, reference=q, species="dog", style=green
    )[0]
    none = render.render_frames(dog, q, width=W, height=H, species="dog", camera=-1)[0]
    g = _mask(ghost, (0, 255, 0), 90)
    assert g.sum() > 500  # the ghost is there, in its colour
    assert _mask(none, (0, 255, 0), 90).sum() == 0
    # the body: pixels whose colour changes with the species' colour, same camera
    tiger = render.render_frames(
        dog, q, width=W, height=H, reference=q, species="tiger", style=render.GhostStyle(alpha=0.0)
    )[0]
    body = np.abs(tiger.astype(int) - plain.astype(int)).sum(-1) > 30
    assert body.sum() > 500
    # beside, not over: ghost and body barely share a pixel, and sit side by side
    assert (g & body).sum() < 0.05 * g.sum()
    gx = np.nonzero(g)[1].mean()
    bx = np.nonzero(body)[1].mean()
    assert abs(gx - bx) > W / 6


def test_stance_discs_follow_the_contacts(dog) -> None:
    q = _home(dog)
    red = render.GhostStyle(stance_rgba=(1.0, 0.0, 0.0, 1.0))
    # the flat discs are seen edge-on by the species camera: full size images
    down = render.render_frames(dog, q, contacts=np.ones((1, 4), bool), style=red)[0]
    up = render.render_frames(dog, q, contacts=np.zeros((1, 4), bool), style=red)[0]
    one = render.render_frames(dog, q, contacts=np.array([[True, False, False, False]]), style=red)[
        0
    ]
    n_down, n_up, n_one = (_mask(x, (255, 0, 0), 60).sum() for x in (down, up, one))
    assert n_up == 0 and n_down > 16 and 0 < n_one < n_down


def test_species_colour_and_floor_only_in_the_scene(dog) -> None:
    rgba, pos = dog.geom_rgba.copy(), dog.geom_pos.copy()
    q = _home(dog)
    a = render.render_frames(dog, q, width=W, height=H, species="tiger")[0]
    b = render.render_frames(dog, q, width=W, height=H, species="zebra")[0]
    assert np.abs(a.astype(int) - b.astype(int)).sum(-1).astype(bool).sum() > 500
    np.testing.assert_array_equal(dog.geom_rgba, rgba)  # the model itself is untouched
    np.testing.assert_array_equal(dog.geom_pos, pos)
    assert render.SPECIES_COLOURS["tiger"] != render.SPECIES_COLOURS["zebra"]


def test_bad_requests_are_render_errors(dog) -> None:
    q = _home(dog, 3)
    with pytest.raises(render.RenderError, match="reference must have shape"):
        render.render_frames(dog, q, reference=q[:2], width=W, height=H)
    with pytest.raises(render.RenderError, match="contacts must have shape"):
        render.render_frames(dog, q, contacts=np.ones((2, 4), bool), width=W, height=H)
    with pytest.raises(render.RenderError, match="'paw'"):
        render.render_frames(
            dog, q, contacts=np.ones((3, 1), bool), feet=["paw"], width=W, height=H
        )
    with pytest.raises(render.RenderError, match="4 stance columns but 1 feet"):
        render.render_frames(
            dog, q, contacts=np.ones((3, 4), bool), feet=["lf_foot"], width=W, height=H
        )


def test_render_options_frame_step_and_bad_values() -> None:
    """A video keeps every n-th frame, n the smallest that brings the rate to at most
    ``video_fps``; bad knobs are typed errors."""
    opts = render.RenderOptions(video_fps=30.0)
    assert [opts.frame_step(f) for f in (24.0, 30.0, 50.0, 60.0, 100.0, 500.0)] == [
        1,
        1,
        2,
        2,
        4,
        17,
    ]
    assert render.RenderOptions(video_fps=None).frame_step(500.0) == 1
    for bad in ({"multisamples": -1}, {"video_fps": 0.0}, {"preset": "instant"}):
        with pytest.raises(render.RenderError):
            render.RenderOptions(**bad)  # type: ignore[arg-type]


def test_video_is_drawn_at_the_video_rate_with_scene_flags(dog, tmp_path) -> None:
    """A 100 Hz clip becomes a 25 Hz video of a quarter of the frames, the clip's length;
    shadows are drawn only when asked (the frames differ), the caller's model untouched."""
    from PIL import Image

    q = _home(dog, 12)
    q[:, 0] += 0.05 * np.arange(12)  # moving, so that no two frames are alike
    path = render.render_video(dog, q, 100.0, tmp_path / "v.gif", width=64, height=48)
    with Image.open(path) as gif:
        assert gif.n_frames == 3
        assert gif.info["duration"] == 40
    samples, shadow_map = int(dog.vis.quality.offsamples), int(dog.vis.quality.shadowsize)
    plain = render.render_frames(dog, q[:1], width=W, height=H)[0]
    shaded = render.render_frames(
        dog, q[:1], width=W, height=H, options=render.RenderOptions(shadows=True, multisamples=4)
    )[0]
    assert np.abs(plain.astype(int) - shaded.astype(int)).sum() > 0
    assert int(dog.vis.quality.offsamples) == samples
    assert int(dog.vis.quality.shadowsize) == shadow_map


def test_bench_render_prints_figures_and_its_target(capsys) -> None:
    import json

    from helpers import run_cli

    from habitsim.cli import main

    assert main(["bench", "render", "--frames", "20", "--before-frames", "4", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert [r["setting"] for r in doc["rows"]] == ["defaults", "MuJoCo's own"]
    defaults = doc["rows"][0]
    assert defaults["frames_drawn"] == 10  # a 50 Hz clip drawn at 25 frames a second
    assert defaults["x_real_time"] > 0 and doc["targets"][0]["verdict"] in ("met", "MISSED")
    assert run_cli(["bench", "render", "--species", "hores"], capsys)[0] == 2


def test_floor_box_replaces_the_infinite_plane_and_keeps_its_pattern(dog) -> None:
    """The floor plane becomes a thin box in the scene only: its top where the plane is,
    reaching the far clipping distance, its centre under the body on whole texture periods
    (so the checker does not slide), and a textured plane stretched over is left alone."""
    import mujoco

    floors = {i for i in range(dog.ngeom) if dog.geom_type[i] == mujoco.mjtGeom.mjGEOM_PLANE}
    boxes = render._floor_boxes(dog, floors)
    assert set(boxes) == floors
    d = mujoco.MjData(dog)
    d.qpos[:] = _home(dog)[0]
    d.qpos[:2] = (3.37, -1.21)  # the body away from the origin, off the texture's period
    mujoco.mj_forward(dog, d)
    scn = mujoco.MjvScene(dog, maxgeom=1000)
    opt, cam = mujoco.MjvOption(), mujoco.MjvCamera()
    mujoco.mjv_updateScene(dog, d, opt, None, cam, mujoco.mjtCatBit.mjCAT_ALL, scn)
    plane = [scn.geoms[i] for i in range(scn.ngeom) if scn.geoms[i].objid in floors]
    z0 = plane[0].pos[2]
    render._box_floors(scn, boxes, d.xpos[1])
    box = [scn.geoms[i] for i in range(scn.ngeom) if scn.geoms[i].objid in floors][0]
    assert box.type == mujoco.mjtGeom.mjGEOM_BOX
    assert box.pos[2] + box.size[2] == pytest.approx(z0)
    far = dog.vis.map.zfar * dog.stat.extent
    assert box.size[0] == pytest.approx(far) and box.size[1] == pytest.approx(far)
    period = 2.0 / dog.mat_texrepeat[dog.geom_matid[min(floors)]]
    for k in range(2):
        assert abs(box.pos[k] - d.xpos[1][k]) <= period[k] / 2 + 1e-9
        assert box.pos[k] / period[k] == pytest.approx(round(box.pos[k] / period[k]))
    stretched = dog.__copy__()
    stretched.mat_texuniform[dog.geom_matid[min(floors)]] = 0
    assert render._floor_boxes(stretched, floors) == {}


def test_floor_box_frame_looks_like_the_plane(dog) -> None:
    q = _home(dog)
    box = render.render_frames(dog, q, width=W, height=H)[0].astype(int)
    plane = render.render_frames(
        dog, q, width=W, height=H, options=render.RenderOptions(floor_box=False)
    )[0].astype(int)
    bare = render.render_frames(dog, q, width=W, height=H, species="dog")[0].astype(int)
    low = slice(H // 2, H)  # the floor under the body; the horizon may differ (haze)
    same = np.abs(box[low] - plane[low]).mean()
    assert same < 1.0, same
    assert np.abs(box[low] - bare[low]).mean() > same  # a visible change moves the figure


def test_skybox_only_when_asked(dog) -> None:
    q = _home(dog)
    plain = render.render_frames(dog, q, width=W, height=H)[0]
    sky = render.render_frames(
        dog, q, width=W, height=H, options=render.RenderOptions(skybox=True)
    )[0]
    top = slice(0, H // 10)  # above the horizon
    assert plain[top].max() == 0
    assert sky[top].mean() > 10


def _run(model, q: np.ndarray, fps: float = 30.0, species: str = "dog"):
    from types import SimpleNamespace

    return SimpleNamespace(
        model=model,
        qpos=q,
        fps=fps,
        reference_qpos=q,
        contacts=None,
        reference_contacts=None,
        species=species,
    )


def test_side_by_side_panels_and_the_shorter_run_holds(dog, tmp_path) -> None:
    cat = load_species_model("cat")
    a, b = _run(dog, _home(dog, 3)), _run(cat, _home(cat, 1), species="cat")
    frames, fps = render_side.side_by_side_frames([a, b], width=W, height=H)
    got = list(frames)
    assert fps == 30.0 and len(got) == 3 and got[0].shape == (H, 2 * W, 3)
    alone = [
        np.array(f)
        for f in render.iter_frames(
            cat, _home(cat, 1), width=W, height=H, reference=_home(cat, 1), species="cat"
        )
    ]
    assert np.array_equal(got[2][:, W:], alone[0])  # the cat's last frame held
    assert not np.array_equal(got[0][:, :W], got[0][:, W:])  # two bodies, two panels
    path = render_side.render_side_by_side([a, b], tmp_path / "pair.gif", width=W, height=H)
    assert path.is_file()
    with pytest.raises(render.RenderError):
        render_side.side_by_side_frames([a], width=W, height=H)
    with pytest.raises(render.RenderError, match="one video rate"):
        render_side.side_by_side_frames([a, _run(cat, _home(cat, 2), fps=24.0)], width=W, height=H)
