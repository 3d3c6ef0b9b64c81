"""The tracking runner: known answers, failure handling, parallel paths, CLI, rendering."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from habitsim import UnknownSpeciesError
from habitsim.controllers import PDController
from habitsim.metrics.dynamic import DYNAMIC_KEYS
from habitsim.metrics.kinematic import KINEMATIC_KEYS, kinematic_metrics
from habitsim.metrics.simulated import SIMULATED_KEYS
from habitsim.motion import Motion, load_motion
from habitsim.qpos import QposTrajectory, load_species_model, qpos_to_motion, species_model
from habitsim.sim import (
    CONTROLLERS,
    FallCause,
    FallDetector,
    FallOptions,
    SimulationError,
    TrackOptions,
    servo_model,
    track,
    track_many,
)

FPS = 30.0


@pytest.fixture(scope="module")
def dog():
    return load_species_model("dog")


def _still(model, seconds: float = 2.0, lift: float = 0.0) -> Motion:
    q = np.tile(model.key_qpos[model.key("home").id], (int(seconds * FPS) + 1, 1))
    q[:, 2] += lift
    return qpos_to_motion(model, q, "dog", FPS)


@pytest.fixture(scope="module")
def walk():
    from habitsim.gaits import generate

    return generate("dog", "walk", seed=0, duration_s=1.5, trunk_sway=0.0)


# ------------------------------------------------------------------ known answers
def test_still_standing_pose_survives_without_skating(dog) -> None:
    r = track(_still(dog))
    assert r.survival == 1.0 and not r.fell and not r.unstable
    assert r.metrics["survival"] == 1.0 and r.metrics["fell"] is False
    assert r.qpos.shape == r.reference_qpos.shape
    km = kinematic_metrics(r.motion(), contacts=r.contacts)
    assert km["skate_mm"] < 0.5  # feet stay put (sub-millimetre settling)
    assert r.metrics["contact_f1"] > 0.98  # all four feet loaded (frame 0 just touches)
    assert r.metrics["sim_mpjpe_per_leg"] < 0.05
    assert r.metrics["assist_force_mg"] == 0.0
    assert set(r.metrics) == set(SIMULATED_KEYS)


def test_root_assist_carries_a_floating_body(dog) -> None:
    """A pose held 0.5 m in the air: the assistance must carry the whole weight."""
    r = track(_still(dog, 1.0, lift=0.5), assist="root")
    assert r.survival == 1.0
    assert r.assist["assist_on"] is True
    assert r.metrics["assist_force_mg"] == pytest.approx(1.0, rel=0.05)
    assert np.abs(r.qpos[-1, 2] - r.reference_qpos[-1, 2]) < 0.02


def test_without_actuation_the_dog_falls(dog) -> None:
    limp = PDController(dog, 0.0, 0.0)
    r = track(_still(dog, 3.0), controller=limp)
    assert r.fell and not r.unstable
    assert 0.0 < r.survival < 1.0
    assert r.fall_time == pytest.approx(r.survival * 3.0)
    assert len(r.qpos) < len(r.reference_qpos)  # stopped at the fall
    assert r.metrics["fell"] is True
    full = track(_still(dog, 3.0), controller=PDController(dog, 0.0, 0.0), stop_on_fall=False)
    assert len(full.qpos) == len(full.reference_qpos) and full.survival == r.survival


def test_fall_detector_rules(dog) -> None:
    q = dog.key_qpos[dog.key("home").id].copy()
    det = FallDetector(dog, np.tile(q, (40, 1)), FPS, leg_length=0.61)
    d = mujoco.MjData(dog)

    def at(qpos: np.ndarray) -> mujoco.MjData:
        d.qpos[:] = qpos
        mujoco.mj_forward(dog, d)
        return d

    assert det.check(1, at(q)) is None
    low = q.copy()
    low[2] *= 0.4
    assert det.fall(1, at(low)).cause is FallCause.TRUNK_LOW
    assert det.check(1, at(low)) == det.fall(1, at(low)).text  # the same, in words
    tipped = q.copy()
    tipped[3:7] = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # rolled 90°
    assert det.fall(1, at(tipped)).cause is FallCause.TILT
    # lying low with the head on the floor: allowed for 0.2 s (6 frames), then a fall
    nose = q.copy()
    nose[dog.joint("neck_pitch").qposadr[0]] = 0.5
    nose[dog.joint("head_pitch").qposadr[0]] = 2.0
    head = dog.body("head").id
    while not any(
        dog.geom_bodyid[c.geom1] == head or dog.geom_bodyid[c.geom2] == head
        for c in at(nose).contact[: d.ncon]
    ):
        nose[2] -= 0.005  # lower the trunk until the head touches the floor
    assert nose[2] > 0.5 * q[2]  # still high: only the ground-contact rule can fire
    det.reset()
    falls = [det.fall(k, at(nose)) for k in range(1, 9)]
    assert falls[:6] == [None] * 6
    assert falls[6] is not None and falls[6].cause is FallCause.BODY_CONTACT
    assert "head" in falls[6].bodies
    # the rule's thresholds are options: a stricter tilt limit catches a smaller roll
    strict = FallDetector(dog, np.tile(q, (40, 1)), FPS, 0.61, options=FallOptions(tilt_deg=5.0))
    rolled = q.copy()
    rolled[3:7] = [np.cos(np.pi / 36), np.sin(np.pi / 36), 0.0, 0.0]  # rolled 10°
    assert det.check(1, at(rolled)) is None
    assert strict.fall(1, at(rolled)).cause is FallCause.TILT


def test_unstable_run_is_reported_not_raised(dog) -> None:
    wild = servo_model(dog).__copy__()
    wild.actuator_gainprm[:, 0] *= 1e6
    wild.actuator_biasprm[:, 1] *= 1e6
    wild.actuator_biasprm[:, 2] = 0.0
    wild.actuator_forcelimited[:] = 0
    wild.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    traj = QposTrajectory(
        np.tile(dog.key_qpos[0], (31, 1)) + np.r_[np.zeros(7), np.full(34, 0.1)],
        FPS,
        np.zeros(31),
        (),
    )
    for use_rollout in (True, False):
        r = track(traj, species="dog", model=wild, use_rollout=use_rollout)
        assert r.unstable and r.unstable_reason
        assert r.survival < 1.0 and r.metrics["fell"] is True
        json.dumps(r.report(), allow_nan=False)


# ------------------------------------------------------------------ paths agree
def test_rollout_and_python_loop_agree(walk) -> None:
    a = track(walk, use_rollout=True, stop_on_fall=False)
    b = track(walk, use_rollout=False, stop_on_fall=False)
    np.testing.assert_allclose(a.qpos, b.qpos, atol=1e-9)
    mg = 25.0 * 9.81  # contact forces agree to solver tolerance (warm starts differ)
    np.testing.assert_allclose(a.touch, b.touch, atol=1e-3 * mg)
    assert a.survival == b.survival
    assert a.work_j == pytest.approx(b.work_j, rel=1e-6)


def test_initial_velocity_noise_is_seeded_and_reaches_both_loops(walk) -> None:
    """``init_noise`` perturbs the first state from ``seed``, the same way on the rollout
    path and in the Python loop; without it the seed changes nothing."""
    base = track(walk, use_rollout=True, stop_on_fall=False)
    np.testing.assert_array_equal(
        track(walk, use_rollout=True, stop_on_fall=False, seed=7).qpos, base.qpos
    )
    runs = {
        (path, seed): track(
            walk, use_rollout=path, stop_on_fall=False, seed=seed, init_noise=0.05
        ).qpos
        for path in (True, False)
        for seed in (1, 2)
    }
    np.testing.assert_allclose(runs[True, 1], runs[False, 1], atol=1e-9)
    np.testing.assert_array_equal(
        runs[True, 1],
        track(walk, use_rollout=True, stop_on_fall=False, seed=1, init_noise=0.05).qpos,
    )
    n = min(len(runs[True, 1]), len(runs[True, 2]), len(base.qpos))
    assert np.abs(runs[True, 1][:n] - base.qpos[:n]).max() > 1e-4
    assert np.abs(runs[True, 1][:n] - runs[True, 2][:n]).max() > 1e-4
    # the free joint starts with the reference's velocity: the root's first step agrees
    np.testing.assert_allclose(runs[True, 1][1, :3], base.qpos[1, :3], atol=5e-3)
    for bad in (-1e-3, float("nan"), float("inf")):
        with pytest.raises(SimulationError, match="init_noise must be finite and >= 0"):
            track(walk, init_noise=bad)


def test_track_many_matches_track(walk, dog) -> None:
    still = _still(dog, 1.0)
    many = track_many([walk, still, walk], threads=2)
    one = [track(walk), track(still)]
    for m, o in zip(many, [one[0], one[1], one[0]], strict=True):
        np.testing.assert_allclose(m.qpos, o.qpos, atol=1e-12)
        assert m.survival == o.survival
    pd_many = track_many([still, still], controller="pd", threads=2)
    assert [r.controller for r in pd_many] == ["pd", "pd"]


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_every_named_controller_runs(controller, dog) -> None:
    r = track(_still(dog, 0.5), controller=controller)
    assert r.controller == controller
    assert not r.unstable and r.survival == 1.0
    if controller == "servo":  # no Python in the loop: mujoco.rollout
        assert "rollout" in r.controller_stats["notes"][0]
    else:
        assert r.controller_stats["calls"] > 0


@pytest.mark.slow
def test_mpc_runs_its_torque_layer_at_its_rate_with_and_without_assistance(walk) -> None:
    from habitsim.controllers import RootAssist

    free = track(walk, controller="mpc")
    held = track(walk, controller="mpc", assist=True)
    steps = walk.duration / 0.002
    # 250 Hz torque layer, assisted too: the model integrates the assist's damping
    calls = steps * TrackOptions().mpc_control_hz * 0.002
    assert free.controller_stats["calls"] == pytest.approx(calls, rel=0.05)
    assert held.controller_stats["calls"] == pytest.approx(calls, rel=0.05)
    assert not held.unstable and held.survival == 1.0
    # held explicitly the assist flipped sign every step against the mpc's own trunk
    # feedback and read 2-5 m·g
    assert held.assist["assist_force_mg"] < 0.5
    assert held.metrics["sim_mpjpe_per_leg"] <= free.metrics["sim_mpjpe_per_leg"]
    shared = species_model("dog")
    np.testing.assert_array_equal(shared.dof_damping[:6], 0.0)  # the copy was damped

    class Explicit:  # an assist-like object without damped_model: every step, as before
        def __init__(self, model):
            self.inner = RootAssist(model)

        def apply(self, model, data, ref):
            return self.inner.apply(model, data, ref)

        def report(self, data=None):
            return self.inner.report(data)

        def reset(self, model, data):
            self.inner.reset(model, data)

    other = track(walk, controller="mpc", assist=Explicit(species_model("dog")))
    assert other.controller_stats["calls"] == pytest.approx(steps, rel=0.05)


# ------------------------------------------------------------------ bad inputs
def test_bad_inputs_are_typed_errors(dog, walk) -> None:
    traj = QposTrajectory(np.tile(dog.key_qpos[0], (5, 1)), FPS, np.zeros(5), ())
    with pytest.raises(UnknownSpeciesError, match="hores"):
        track(traj, species="hores")
    with pytest.raises(UnknownSpeciesError):
        Motion("hores", FPS, walk.root_positions, walk.rotations)
    bad = QposTrajectory(traj.qpos[:, :-3], FPS, np.zeros(5), ())
    with pytest.raises(SimulationError, match="shape"):
        track(bad, species="dog")
    nan = QposTrajectory(traj.qpos.copy(), FPS, np.zeros(5), ())
    nan.qpos[3, 12] = np.nan
    with pytest.raises(SimulationError, match="NaN"):
        track(nan, species="dog")
    with pytest.raises(SimulationError, match="valid: .*balance"):
        track(walk, controller="hover")
    with pytest.raises(SimulationError, match="species"):
        track(walk, species="cat")
    with pytest.raises(SimulationError):
        track(walk, control_hz=10_000.0)
    # a model without the habitsim joints
    box = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>"
    )
    with pytest.raises(SimulationError, match="does not fit"):
        track(walk, model=box)


# ------------------------------------------------------------------ CLI
@pytest.mark.slow
def test_cli_track_writes_motion_and_report(tmp_path, walk) -> None:
    from habitsim.cli import main

    src = walk.save(tmp_path / "walk.npz")
    out, rep = tmp_path / "sim.npz", tmp_path / "r.json"
    assert main(["track", str(src), "--out", str(out), "--report", str(rep)]) == 0
    sim = load_motion(out)
    assert sim.species == "dog" and sim.contacts is not None
    report = json.loads(rep.read_text())
    assert set(SIMULATED_KEYS) <= set(report["metrics"])
    assert set(DYNAMIC_KEYS) == set(report["reference_dynamic"])
    assert set(KINEMATIC_KEYS) == set(report["simulated_kinematic"])
    assert report["frames_simulated"] == sim.num_frames
    # the default controller is mpc, which keeps the walk up unassisted; servo on request
    assert report["controller"] == "mpc" and report["metrics"]["survival"] == 1.0
    assert main(["track", str(src), "--controller", "servo", "--report", str(rep)]) == 0
    assert json.loads(rep.read_text())["controller"] == "servo"
    assert main(["track", str(src), "--assist", "root", "--report", str(rep)]) == 0
    assert json.loads(rep.read_text())["assist"]["assist_force_mg"] > 0


def test_cli_missing_video_writer_fails_before_writing(tmp_path, walk, capsys, monkeypatch) -> None:
    from habitsim import render
    from habitsim.cli import main

    # a machine without imageio-ffmpeg (it is a dependency here, so pretend it is absent)
    monkeypatch.setattr(render, "_has", lambda name: name != "imageio_ffmpeg")
    src = walk.save(tmp_path / "walk.npz")
    out = tmp_path / "sim.npz"
    assert main(["track", str(src), "--out", str(out), "--video", str(tmp_path / "v.mp4")]) == 2
    assert "imageio-ffmpeg" in capsys.readouterr().err
    assert not out.exists()


# ------------------------------------------------------------------ rendering
@pytest.mark.slow
def test_render_frames(dog) -> None:
    from habitsim import render

    if not render.render_available():
        pytest.skip("no OpenGL backend for off-screen rendering")
    q = np.tile(dog.key_qpos[0], (3, 1))
    q[:, 0] += [0.0, 0.5, 1.0]
    frames = render.render_frames(dog, q, width=160, height=120)
    assert frames.shape == (3, 120, 160, 3) and frames.dtype == np.uint8
    assert frames.std() > 5  # not a blank image
    # the tracking camera follows the dog: its image barely changes as it moves
    assert np.abs(frames[0].astype(int) - frames[2].astype(int)).mean() < 20


def test_lowest_point_matches_mujoco_distance(dog) -> None:
    """The geometric ground clearance used for the reference equals mj_geomDistance."""
    from habitsim.mjutils import lowest_z as _lowest_z

    d = mujoco.MjData(dog)
    floor = dog.geom("floor").id
    geoms = np.flatnonzero((dog.geom_contype != 0) & (dog.geom_bodyid != 0))
    rng = np.random.default_rng(0)
    for _ in range(3):
        mujoco.mj_resetDataKeyframe(dog, d, dog.key("home").id)
        d.qpos[7:] += rng.normal(0.0, 0.3, dog.nq - 7)
        quat = rng.normal(size=4)
        d.qpos[3:7] = quat / np.linalg.norm(quat)
        mujoco.mj_kinematics(dog, d)
        want = [mujoco.mj_geomDistance(dog, d, int(g), floor, 10.0, None) for g in geoms]
        got = _lowest_z(dog, geoms, d.geom_xpos[geoms], d.geom_xmat[geoms])
        np.testing.assert_allclose(got, want, atol=1e-9)


def test_sim_package_keeps_every_public_name() -> None:
    import habitsim.sim as S

    for name in S.__all__:
        assert getattr(S, name) is not None, name
    from habitsim.sim.tracking import track as track_fn

    assert S.track is track_fn and callable(S.track)
    assert S._species_model("dog", False) is S.species_model("dog")


def _pair(tmp_path):
    from habitsim.gaits import generate

    a = generate("dog", "walk", seed=0, duration_s=0.3).save(tmp_path / "a.npz")
    b = generate("cat", "walk", seed=0, duration_s=0.2).save(tmp_path / "b.npz")
    return a, b


def test_cli_beside_needs_a_video(tmp_path, capsys) -> None:
    from habitsim.cli import main

    a, b = _pair(tmp_path)
    assert main(["track", str(a), "--beside", str(b)]) == 2
    assert "--video" in capsys.readouterr().err


@pytest.mark.slow  # two tracking runs and a 1280-pixel-wide video: about 15 s
def test_cli_beside_writes_the_two_runs_side_by_side(tmp_path, capsys) -> None:
    from PIL import Image

    from habitsim import render
    from habitsim.cli import main

    if not render.render_available():
        pytest.skip("no OpenGL backend for off-screen rendering")
    a, b = _pair(tmp_path)
    video = tmp_path / "pair.gif"
    argv = ["track", str(a), "--beside", str(b), "--controller", "servo", "--video", str(video)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "track " in out and "beside: " in out and "cat" in out
    with Image.open(video) as im:
        assert im.size == (1280, 480) and im.n_frames == 9  # 0.3 s at 30 fps, the cat's held
