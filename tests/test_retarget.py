"""Animal motion on a robot: ``habitsim.retarget`` and ``habitsim retarget`` on the Go1, ANYmal C
and the Go2."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

from habitsim.cli import main
from habitsim.controllers import ControllerError, make_controller
from habitsim.gaits import generate
from habitsim.retarget import (
    RetargetError,
    RetargetOptions,
    _knee_joints,
    find_robot_feet,
    leg_extension,
    leg_ik,
    load_robot,
    load_robot_clip,
    retarget,
    robot_legs,
    track_clip,
)

#: The defaults of the knobs the tests compare against.
DEFAULTS = RetargetOptions()
GO1 = Path(__file__).parent / "robots" / "unitree_go1" / "scene.xml"
FEET = ["FL", "FR", "RL", "RR"]


@pytest.fixture(scope="module")
def go1() -> mujoco.MjModel:
    return load_robot(GO1)


@pytest.fixture(scope="module")
def walk():
    return generate("dog", "walk", seed=7, duration_s=3.0)


@pytest.fixture(scope="module")
def clip(go1, walk):
    return retarget(walk, go1, FEET)


def _feet_world(model, qpos, names):
    d = mujoco.MjData(model)
    out = np.empty((len(qpos), len(names), 3))
    for k, q in enumerate(qpos):
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        out[k] = [d.site_xpos[model.site(n).id] for n in names]
    return out


@pytest.mark.slow
def test_dog_walk_on_go1_reference(go1, walk, clip):
    rl = robot_legs(go1, FEET)
    assert clip.qpos.shape == (walk.num_frames, go1.nq) and clip.fps == walk.fps
    assert np.array_equal(clip.contacts, walk.contacts) and clip.feet == tuple(FEET)
    assert clip.metadata["ik_residual_max_m"] < 1e-4
    k = clip.metadata["scale"]
    assert k == pytest.approx(rl.leg_length / walk.species_info.leg_length)
    # trunk path kept, scaled: the same displacement times k, standing at the robot's height
    src = walk.root_positions
    assert np.allclose(
        clip.qpos[-1, :2] - clip.qpos[0, :2], k * (src[-1, :2] - src[0, :2]), atol=1e-9
    )
    assert abs(clip.qpos[:, 2].mean() - rl.height) < 1e-9
    # stance feet stand still on the ground; swing feet leave it
    feet = _feet_world(go1, clip.qpos, FEET)
    for i in range(4):
        st = clip.contacts[:, i]
        prev = np.concatenate([[False], st[:-1]])
        still = st & prev
        step = np.linalg.norm(np.diff(feet[:, i], axis=0), axis=1)[still[1:]]
        assert step.max() < 1e-4
        assert np.allclose(feet[st, i, 2], rl.radius[i], atol=1e-4)
        assert feet[~st, i, 2].max() > rl.radius[i] + 0.01
    # every leg joint within its range
    jm = rl.legs.jmap
    q = clip.qpos[:, jm.qpos_adr]
    rng = go1.jnt_range[jm.joint_ids]
    assert np.all(q >= rng[:, 0] - 1e-12) and np.all(q <= rng[:, 1] + 1e-12)


def test_joint_limits_bind_and_hold(go1, walk):
    """A robot whose knees barely bend: the IK keeps them in range (and says so)."""
    stiff = copy.copy(go1)
    knees = [stiff.joint(f"{leg}_calf_joint").id for leg in FEET]
    stiff.jnt_range[knees] = (-1.85, -1.75)
    out = retarget(walk, stiff, FEET)
    adr = stiff.jnt_qposadr[knees]
    assert out.qpos[:, adr].min() >= -1.85 - 1e-12 and out.qpos[:, adr].max() <= -1.75 + 1e-12
    assert out.metadata["joints_at_limit_share"] > 0.0
    assert out.metadata["ik_residual_max_m"] > 1e-3  # the feet cannot all be reached


@pytest.mark.slow
def test_retargeted_walk_tracks_under_mpc(go1, clip):
    res = track_clip(clip, go1, controller="mpc")
    assert not res.failed and res.survival == 1.0
    assert res.assist["assist_force_mg"] == 0.0
    assert res.metrics["sim_mpjpe_mm"] < 20.0 and res.metrics["contact_f1"] > 0.7


def test_save_load_roundtrip(clip, tmp_path):
    path = clip.save(tmp_path / "q.npz")
    back = load_robot_clip(path)
    assert np.array_equal(back.qpos, clip.qpos) and np.array_equal(back.contacts, clip.contacts)
    assert back.feet == clip.feet and back.fps == clip.fps
    assert back.metadata["scale"] == pytest.approx(clip.metadata["scale"])
    assert [p.name for p in tmp_path.iterdir()] == ["q.npz"]  # no temporary left behind


def test_bad_input_is_typed(go1, walk, tmp_path):
    valid = "head, imu, FR, FL, RR, RL, trunk, FR_hip"  # sites, geoms, bodies; no floor
    with pytest.raises(RetargetError, match=rf"unknown foot name\(s\) 'FL_foot'; .*: {valid}"):
        retarget(walk, go1, ["FL_foot", "FR", "RL", "RR"])
    with pytest.raises(RetargetError, match="4 feet"):
        retarget(walk, go1, ["FL", "FR", "RL"])
    fixed = tmp_path / "fixed.xml"
    xml = GO1.with_name("go1.xml").read_text().replace("<freejoint/>", "")
    fixed.write_text(re.sub(r"<keyframe>.*</keyframe>", "", xml, flags=re.S))
    with pytest.raises(RetargetError, match="no free joint"):
        retarget(walk, load_robot(fixed), FEET)
    with pytest.raises(RetargetError, match="does not exist"):
        load_robot(tmp_path / "none.xml")
    walk.save(tmp_path / "motion.npz")
    with pytest.raises(RetargetError, match="not a robot clip"):
        load_robot_clip(tmp_path / "motion.npz")


@pytest.mark.slow
def test_cli_retarget_and_track(walk, tmp_path, capsys):
    src, out = walk.save(tmp_path / "walk.npz"), tmp_path / "go1_walk.npz"
    code = main(
        [
            "retarget",
            str(src),
            "--robot",
            str(GO1),
            "--feet",
            "FL,FR,RL,RR",
            "--out",
            str(out),
            "--track",
            "--report",
            str(tmp_path / "r.json"),
            "--json",
        ]
    )
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["track"]["survival"] == 1.0 and summary["track"]["controller"] == "mpc"
    assert load_robot_clip(out).qpos.shape[0] == walk.num_frames
    assert json.loads((tmp_path / "r.json").read_text())["metrics"]["survival"] == 1.0
    # bad input: exit 2 with the valid names, nothing written
    bad = tmp_path / "bad.npz"
    assert (
        main(
            ["retarget", str(src), "--robot", str(GO1), "--feet", "FL,FR,RL,toe", "--out", str(bad)]
        )
        == 2
    )
    assert "unknown foot name(s) 'toe'" in capsys.readouterr().err and not bad.exists()
    assert (
        main(
            [
                "retarget",
                str(src),
                "--robot",
                str(GO1.with_name("go1.xml")),
                "--feet",
                "FL,FR,RL,RR",
                "--out",
                str(bad),
                "--track",
            ]
        )
        == 2
    )
    assert "no floor" in capsys.readouterr().err


# ------------------------------------------------------------------ a robot unlike the Go1
ANYMAL = Path(__file__).parent / "robots" / "anybotics_anymal_c" / "scene.xml"
ANYMAL_FEET = ["LF_SHANK", "RF_SHANK", "LH_SHANK", "RH_SHANK"]


@pytest.fixture(scope="module")
def anymal() -> mujoco.MjModel:
    return load_robot(ANYMAL)


def test_feet_named_by_their_body_are_the_foot_spheres(anymal, go1):
    """ANYmal's foot spheres have no name: the shank bodies name the feet, and the foot
    point is the shank's sphere at the sole, not the shank's origin at the knee."""
    from habitsim.mjutils import resolve_feet, resolve_points

    pts = resolve_feet(anymal, ANYMAL_FEET)
    for name, (kind, i) in zip(ANYMAL_FEET, pts, strict=True):
        assert kind == "geom" and anymal.geom_type[i] == mujoco.mjtGeom.mjGEOM_SPHERE
        assert anymal.body(int(anymal.geom_bodyid[i])).name == name
    # a body without a colliding sphere keeps its origin; sites and geoms are unchanged
    trunk = mujoco.mj_name2id(go1, mujoco.mjtObj.mjOBJ_BODY, "trunk")
    assert resolve_feet(go1, ["trunk", "FL"]) == resolve_points(go1, ["trunk", "FL"])
    assert resolve_feet(go1, ["trunk"])[0] == ("body", trunk)


def test_a_robot_without_home_keyframe_stands_crouched(anymal, go1):
    """qpos0 of ANYmal C stands on straight legs (a singular pose); the standing pose is
    that stance crouched, feet where they were and on the ground, knees bent."""
    assert anymal.nkey == 0
    rl = robot_legs(anymal, ANYMAL_FEET)
    assert "crouched" in rl.home_source
    assert np.all(leg_extension(rl, anymal.qpos0) > DEFAULTS.straight_reach)
    assert np.all(leg_extension(rl) < DEFAULTS.straight_reach - 0.05)
    d = mujoco.MjData(anymal)
    for q in (anymal.qpos0, rl.home):
        d.qpos[:] = q
        mujoco.mj_kinematics(anymal, d)
        if q is anymal.qpos0:
            straight = np.array(rl.legs.positions(d)).copy()
            h0 = float(d.xpos[rl.legs.trunk, 2])
    bent = np.array(rl.legs.positions(d))
    np.testing.assert_allclose(bent, straight, atol=1e-4)  # feet kept where they stood
    assert float(d.xpos[rl.legs.trunk, 2]) < h0 - 0.5 * (1 - DEFAULTS.crouch_height) * rl.height
    # the Go1 keeps its own keyframe
    assert robot_legs(go1, FEET).home_source == "keyframe 'home'"


def test_straight_legs_that_cannot_bend_are_a_typed_error(tmp_path):
    """A keyframe-less robot whose knees cannot bend cannot crouch: the error says to add
    a home keyframe."""
    xml = ANYMAL.with_name("anymal_c.xml").read_text()
    knee = r'(name="(LF|RF|LH|RH)_KFE" axis="-?1 0 0") range="[^"]*"'
    stiff = re.sub(knee, r'\1 range="-0.001 0.001"', xml)
    assert stiff.count('range="-0.001 0.001"') == 4
    (tmp_path / "anymal_c.xml").write_text(stiff)
    (tmp_path / "scene.xml").write_text(ANYMAL.read_text())
    with pytest.raises(RetargetError, match="no 'home' keyframe.*straight legs.*add a"):
        robot_legs(load_robot(tmp_path / "scene.xml"), ANYMAL_FEET)


@pytest.mark.slow
def test_dog_walk_on_anymal_tracks_under_mpc(anymal, walk):
    clip = retarget(walk, anymal, ANYMAL_FEET)
    assert clip.metadata["ik_residual_max_m"] < 1e-4
    assert "crouched" in clip.metadata["robot_home"]
    res = track_clip(clip, anymal, controller="mpc")
    assert not res.failed and res.survival == 1.0
    assert res.assist["assist_force_mg"] == 0.0
    assert res.metrics["contact_f1"] > 0.7


def test_a_named_keyframe_is_the_standing_pose(walk, tmp_path, capsys):
    """Menagerie's anymal_c_mjx.xml stands on a keyframe named "standing": --home names
    it; a name the robot does not have is an error listing its keyframes."""
    standing = (
        "0 0 0.56 1 0 0 0 0 0.5236 -0.7854 0 0.5236 -0.7854 0 -0.5236 0.7854 0 -0.5236 0.7854"
    )
    xml = ANYMAL.with_name("anymal_c.xml").read_text()
    xml = xml.replace(
        "</mujoco>", f'  <keyframe><key name="standing" qpos="{standing}"/></keyframe>\n</mujoco>'
    )
    (tmp_path / "anymal_c.xml").write_text(xml)
    (tmp_path / "scene.xml").write_text(ANYMAL.read_text())
    robot = load_robot(tmp_path / "scene.xml")
    rl = robot_legs(robot, ANYMAL_FEET, home="standing")
    assert rl.home_source == "keyframe 'standing'"
    np.testing.assert_allclose(rl.home, robot.key_qpos[0])
    assert "crouched" in robot_legs(robot, ANYMAL_FEET).home_source  # no keyframe "home"
    with pytest.raises(RetargetError, match="no keyframe 'stand'; its keyframes: standing"):
        robot_legs(robot, ANYMAL_FEET, home="stand")
    walk.save(tmp_path / "walk.npz")
    out = tmp_path / "q.npz"
    argv = ["retarget", str(tmp_path / "walk.npz"), "--robot", str(tmp_path / "scene.xml")]
    argv += ["--feet", ",".join(ANYMAL_FEET), "--out", str(out), "--home", "standing", "--json"]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["robot_home"] == "keyframe 'standing'"
    assert summary["ik_residual_max_m"] < 1e-4
    bad = [*argv[:-4], str(tmp_path / "bad.npz"), "--home", "stand"]
    assert main(bad) == 2 and not (tmp_path / "bad.npz").exists()
    assert "no keyframe 'stand'" in capsys.readouterr().err


def test_cli_retargets_motion_capture_imported_with_from(walk, tmp_path, capsys):
    """A .bvh source is imported onto --from's skeleton first (stance and planting as
    `habitsim data import-bvh`); without --from, or with another suffix, nothing runs."""
    from habitsim.bvh import write_bvh

    bvh = write_bvh(walk, tmp_path / "walk.bvh")
    out = tmp_path / "q.npz"
    base = ["retarget", str(bvh), "--robot", str(GO1), "--feet", ",".join(FEET)]
    assert main([*base, "--from", "dog", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    clip = load_robot_clip(out)
    assert len(clip.qpos) == walk.num_frames and summary["ik_residual_max_m"] < 1e-4
    # the import found the walk's own footfalls: the clip's labels are the walk's
    agree = (clip.contacts == walk.contacts).mean()
    assert agree > 0.95
    assert main([*base, "--out", str(tmp_path / "no.npz")]) == 2
    assert "a .bvh source needs --from SPECIES" in capsys.readouterr().err
    other = tmp_path / "walk.fbx"
    other.write_text("x")
    assert main(["retarget", str(other), *base[2:], "--out", str(tmp_path / "no.npz")]) == 2
    assert "(.bvh, .glb, .gltf)" in capsys.readouterr().err
    assert not (tmp_path / "no.npz").exists()


GO2 = Path(__file__).parent / "robots" / "unitree_go2" / "scene.xml"


@pytest.fixture(scope="module")
def go2() -> mujoco.MjModel:
    return load_robot(GO2)


def test_vendored_go2_is_menagerie_with_torque_motors(go2):
    assert "Unitree Robotics" in (GO2.parent / "LICENSE").read_text()
    assert go2.nmesh == 0 and not any(go2.geom_type == mujoco.mjtGeom.mjGEOM_MESH)
    assert go2.nu == 12 and go2.nkey == 1 and go2.key(0).name == "home"
    assert abs(mujoco.mj_getTotalmass(go2) - 15.21) < 0.05  # menagerie's inertials
    # torque motors (no bias, unit gain), unlike the Go1's and ANYmal's position servos
    assert np.all(go2.actuator_biastype == mujoco.mjtBias.mjBIAS_NONE)
    assert np.all(go2.actuator_gainprm[:, 0] == 1.0)
    limit = {go2.actuator(a).name: go2.actuator_ctrlrange[a, 1] for a in range(go2.nu)}
    assert limit["FL_calf"] == pytest.approx(45.43) and limit["FL_thigh"] == pytest.approx(23.7)
    for f in FEET:  # the feet are geoms only (no sites of those names)
        assert go2.geom(f).type[0] == mujoco.mjtGeom.mjGEOM_SPHERE
        assert mujoco.mj_name2id(go2, mujoco.mjtObj.mjOBJ_SITE, f) == -1


@pytest.mark.slow
def test_dog_trot_on_go2_tracks_under_mpc(go2):
    """A robot that ships torque motors and geom-only feet: a 3 s dog trot (flight
    phases included) retargeted onto it runs whole under ``mpc``, unassisted."""
    trot = generate("dog", "trot", seed=7, duration_s=3.0)
    clip = retarget(trot, go2, FEET)
    assert clip.metadata["ik_residual_max_m"] < 1e-4
    res = track_clip(clip, go2, controller="mpc")
    assert not res.failed and res.survival == 1.0
    assert res.assist["assist_force_mg"] == 0.0
    assert res.metrics["sim_mpjpe_mm"] < 60.0 and res.metrics["contact_f1"] > 0.7


def _unlimited_anymal(tmp_path) -> mujoco.MjModel:
    """ANYmal C with every joint range removed (as Menagerie's ANYmal B ships its legs)."""
    (tmp_path / "scene.xml").write_text(ANYMAL.read_text())
    xml = ANYMAL.with_name("anymal_c.xml").read_text()
    (tmp_path / "anymal_c.xml").write_text(re.sub(r' range="[^"]*"', "", xml))
    return load_robot(tmp_path / "scene.xml")


def test_leg_ik_bounds_keep_knees_bent_their_own_way(anymal, tmp_path):
    """Joints without ranges (or ±3π, ANYmal C's hip and knee flexion) get the IK's own
    bounds: half a turn about standing, and each knee on the side it bends to when
    standing, up to the straight leg."""
    free = _unlimited_anymal(tmp_path)
    assert not free.jnt_limited.any()
    for model in (anymal, free):
        rl = robot_legs(model, ANYMAL_FEET)
        d = mujoco.MjData(model)
        d.qpos[:] = rl.home
        mujoco.mj_kinematics(model, d)
        for i, (_, knee) in enumerate(_knee_joints(rl, d)):
            lo, hi, home = rl.lo[i], rl.hi[i], rl.home[rl.qadr[i]]
            assert np.all(np.isfinite(lo)) and np.all(hi - lo <= 2 * DEFAULTS.hinge_span + 1e-9)
            assert np.all((lo <= home) & (home <= hi))
            k = int(np.flatnonzero(rl.qadr[i] == model.jnt_qposadr[knee])[0])
            # one bound of the knee is its straight angle: the leg is straightest there
            ends = [lo[k], hi[k]]
            ext = [leg_extension(rl, _with(rl.home, model.jnt_qposadr[knee], v))[i] for v in ends]
            assert max(ext) > 0.995, (i, ext)
        # a foot target two leg lengths below the hip: the leg straightens, nothing spins
        q = rl.home.copy()
        targets = np.array(rl.legs.positions(d)) - [0.0, 0.0, 2.0 * rl.leg_length]
        q2, res = leg_ik(rl, q, targets, iterations=200)
        assert np.all(res > 0.5 * rl.leg_length)  # out of reach, reported
        for i in range(len(ANYMAL_FEET)):
            v = q2[rl.qadr[i]]
            assert np.all((rl.lo[i] - 1e-9 <= v) & (v <= rl.hi[i] + 1e-9))
        assert np.all(leg_extension(rl, q2) > 0.98)


def test_options_reach_the_legs_and_the_ik(anymal, go1):
    """The knobs come from RetargetOptions: a narrower hinge span narrows the IK's
    bounds, a lower crouch lowers the standing pose, a smaller IK step moves a joint
    less per iteration; bad knobs are typed errors."""
    narrow = RetargetOptions(hinge_span=0.5)
    wide, rn = robot_legs(go1, FEET), robot_legs(go1, FEET, options=narrow)
    for i in range(4):
        home = rn.home[rn.qadr[i]]
        assert np.all(rn.hi[i] - rn.lo[i] <= 2 * 0.5 + 1e-9) and np.all(rn.lo[i] <= home)
        assert np.all(rn.hi[i] - rn.lo[i] <= wide.hi[i] - wide.lo[i] + 1e-12)
    rl = robot_legs(anymal, ANYMAL_FEET)
    low = robot_legs(anymal, ANYMAL_FEET, options=RetargetOptions(crouch_height=0.75))
    assert "75%" in low.home_source and low.height < rl.height
    g = robot_legs(go1, FEET)
    far = g.nominal + np.array([0.0, 0.0, -1.0])  # out of reach: every step is capped
    q1, _ = leg_ik(g, g.home, far, iterations=1, options=RetargetOptions(max_ik_step=0.01))
    assert np.abs(q1 - g.home).max() <= 0.01 + 1e-12
    for bad in ({"straight_reach": 1.5}, {"max_ik_step": 0.0}, {"lower_passes": -1}):
        with pytest.raises(RetargetError):
            RetargetOptions(**bad)


def _with(q, adr, v):
    out = q.copy()
    out[adr] = v
    return out


@pytest.mark.slow
def test_dog_trot_on_unlimited_legs_stays_continuous(anymal, tmp_path):
    """A 3 s dog trot asks ANYmal C's legs for more reach than they have: the retarget
    straightens them (IK residual reported) instead of folding a knee backward (before
    the bounds: a joint 2.6 rad from standing, and on ANYmal B 47.7 rad in one frame)."""
    trot = generate("dog", "trot", seed=7, duration_s=3.0)
    for model in (anymal, _unlimited_anymal(tmp_path)):
        clip = retarget(trot, model, ANYMAL_FEET)
        rl = robot_legs(model, ANYMAL_FEET)
        legs = np.concatenate(rl.qadr)
        assert np.abs(np.diff(clip.qpos[:, legs], axis=0)).max() < 0.8
        assert np.abs(clip.qpos[:, legs] - rl.home[legs]).max() < 0.5 * np.pi


def _anonymous_go1(tmp_path, qpos: str | None = None) -> mujoco.MjModel:
    """The Go1 with its foot geoms and sites unnamed (as Menagerie's A1 ships its feet),
    optionally standing on another home pose."""
    xml = GO1.with_name("go1.xml").read_text()
    xml = re.sub(r'<geom name="(FL|FR|RL|RR)" class="foot"/>', '<geom class="foot"/>', xml)
    xml = re.sub(r'\s*<site name="(FL|FR|RL|RR)"[^>]*/>', "", xml)
    if qpos is not None:
        xml = re.sub(r'(<key name="home" qpos=")[^"]*"', rf'\g<1>{qpos}"', xml)
    tmp_path.mkdir(parents=True, exist_ok=True)
    (tmp_path / "go1.xml").write_text(xml)
    (tmp_path / "scene.xml").write_text(GO1.read_text())
    return load_robot(tmp_path / "scene.xml")


def test_feet_are_found_when_nobody_names_them(go1, go2, anymal, tmp_path):
    """By the usual names first, else the four legs standing on the ground, ordered LF,
    RF, LH, RH from where they stand; an unnamed foot sphere is named by its body."""
    assert find_robot_feet(go1) == tuple(FEET) == find_robot_feet(go2)
    assert find_robot_feet(anymal) == tuple(ANYMAL_FEET)
    anon = _anonymous_go1(tmp_path / "a")
    feet = find_robot_feet(anon)
    assert feet == ("FL_calf", "FR_calf", "RL_calf", "RR_calf")
    # the bodies resolve to the same foot spheres as the Go1's named geoms
    a, b = robot_legs(anon, feet), robot_legs(go1, FEET)
    assert np.allclose(a.nominal, b.nominal) and a.leg_length == pytest.approx(b.leg_length)
    # the controllers find them the same way when no feet are given
    assert make_controller("balance", anon).legs.feet == feet
    # one knee folded up at the standing pose: three legs on the ground, a typed error
    lifted = "0 0 0.27 1 0 0 0 0 0.9 -1.8 0 0.9 -2.7 0 0.9 -1.8 0 0.9 -1.8"
    three = _anonymous_go1(tmp_path / "b", lifted)
    with pytest.raises(RetargetError, match=r"3 leg\(s\) stand on the ground.*--feet"):
        find_robot_feet(three)
    with pytest.raises(ControllerError, match=r"3 leg\(s\) stand.*pass feet="):
        make_controller("balance", three)


def test_cli_finds_the_feet_without_feet(walk, tmp_path, capsys):
    npz = walk.save(tmp_path / "walk.npz")
    _anonymous_go1(tmp_path / "r")
    out = tmp_path / "q.npz"
    assert (
        main(
            ["retarget", str(npz), "--robot", str(tmp_path / "r" / "scene.xml"), "--out", str(out)]
        )
        == 0
    )
    assert "feet (found, LF, RF, LH, RH): FL_calf, FR_calf, RL_calf, RR_calf" in (
        capsys.readouterr().out
    )
    clip = load_robot_clip(out)
    assert clip.feet == ("FL_calf", "FR_calf", "RL_calf", "RR_calf")
    assert clip.metadata["feet_found"] is True and clip.metadata["ik_residual_max_m"] < 1e-4


@pytest.mark.slow
def test_trunk_is_lowered_where_stance_legs_would_be_straight(anymal, go1, walk):
    """The dog trot's stance legs, scaled to ANYmal C, would stand straighter than
    ``straight_reach`` (singular for the IK and the stance forces): the trunk is lowered
    there, smoothly, until every stance leg is bent at least that much; the Go1's walk
    needs no lowering."""
    trot = generate("dog", "trot", seed=7, duration_s=3.0)
    clip = retarget(trot, anymal, ANYMAL_FEET)
    rl = robot_legs(anymal, ANYMAL_FEET)
    assert clip.metadata["trunk_lowered_max_m"] > 0.002 * rl.leg_length
    for k in np.flatnonzero(clip.contacts.any(axis=1)):
        ext = leg_extension(rl, clip.qpos[k])[clip.contacts[k]]
        assert ext.max() <= DEFAULTS.straight_reach + 0.002, (k, ext)
    assert retarget(walk, go1, FEET).metadata["trunk_lowered_max_m"] == 0.0


# ------------------------------------------------------------------ the standing pose
GO1_HOME = "0 0 0.27 1 0 0 0 0 0.9 -1.8 0 0.9 -1.8 0 0.9 -1.8 0 0.9 -1.8"
#: How far the folded Go1 variant's calves are turned at qpos0 [rad].
FOLD = 2.6


def _go1_without_key(folder: Path) -> Path:
    """The vendored Go1 with its keyframe removed (scene.xml in ``folder``)."""
    xml = GO1.with_name("go1.xml").read_text()
    bare = re.sub(r"<keyframe>.*?</keyframe>", "", xml, flags=re.S)
    assert bare != xml
    (folder / "go1.xml").write_text(bare)
    (folder / "scene.xml").write_text(GO1.read_text())
    return folder / "scene.xml"


def _keys_file(path: Path, qpos: str, name: str = "home") -> Path:
    path.write_text(f'<mujoco><keyframe><key name="{name}" qpos="{qpos}"/></keyframe></mujoco>')
    return path


def _folded_go1(scene: Path) -> Path:
    """The Go1 whose qpos0 is folded (each calf body turned by FOLD, the knee range with
    it), as a robot whose default pose is no standing pose: its scene, one file."""
    spec = mujoco.MjSpec.from_file(str(scene))
    quat = np.zeros(4)
    mujoco.mju_axisAngle2Quat(quat, np.array([0.0, 1.0, 0.0]), -FOLD)
    for leg in FEET:
        spec.body(f"{leg}_calf").quat = quat
        joint = spec.joint(f"{leg}_calf_joint")
        joint.range = np.asarray(joint.range) + FOLD
    spec.compile()
    out = scene.with_name("folded_scene.xml")
    out.write_text(spec.to_xml())
    return out


def test_a_keyframe_from_another_file_is_the_standing_pose(go1, walk, tmp_path, capsys):
    """The Go1 with its home keyframe removed, the keyframe given in a second file: the
    robot stands on it (options and CLI); a file without a key of the robot's size is a
    typed error."""
    from habitsim.retarget import standing_keyframe

    scene = _go1_without_key(tmp_path)
    keys = _keys_file(tmp_path / "keys.xml", GO1_HOME)
    robot = load_robot(scene)
    assert robot.nkey == 0
    rl = robot_legs(robot, FEET, options=RetargetOptions(keyframe_from=keys))
    np.testing.assert_array_equal(rl.home, go1.key("home").qpos)
    assert rl.home_source == "keyframe 'home' of keys.xml"
    named = _keys_file(tmp_path / "named.xml", GO1_HOME, name="stand")
    opts = RetargetOptions(keyframe="stand", keyframe_from=named)
    np.testing.assert_array_equal(standing_keyframe(robot, options=opts)[0], rl.home)
    with pytest.raises(RetargetError):  # no key "walk" there
        standing_keyframe(robot, options=RetargetOptions(keyframe="walk", keyframe_from=named))
    short = _keys_file(tmp_path / "short.xml", "0 0 0.27 1 0 0 0")
    with pytest.raises(RetargetError):  # a key of another model's size
        robot_legs(robot, FEET, options=RetargetOptions(keyframe_from=short))
    walk.save(tmp_path / "walk.npz")
    out = tmp_path / "q.npz"
    argv = ["retarget", str(tmp_path / "walk.npz"), "--robot", str(scene), "--out", str(out)]
    assert main([*argv, "--keyframe-from", str(keys), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["robot_home"] == "keyframe 'home' of keys.xml"
    assert summary["robot_stand"]["problems"] == []
    bad = [*argv[:-1], str(tmp_path / "bad.npz"), "--keyframe-from", str(short)]
    assert main(bad) == 2 and not (tmp_path / "bad.npz").exists()


def test_a_folded_default_pose_is_refused_and_a_keyframe_file_fixes_it(walk, tmp_path, capsys):
    """A robot without a keyframe whose qpos0 is folded (trunk a few cm up) is refused
    with a StandingPoseError, not stood on; the same robot with its home keyframe from a
    second file stands at the Go1's scale. A folded keyframe is warned about."""
    from habitsim.retarget import StandingPoseError, StandingPoseWarning, stand_check

    folded_scene = _folded_go1(_go1_without_key(tmp_path))
    robot = load_robot(folded_scene)
    with pytest.raises(StandingPoseError):
        robot_legs(robot, FEET)
    home = np.fromstring(GO1_HOME, sep=" ")
    home[9::3] += FOLD  # the knee angles of the turned calves
    keys = _keys_file(tmp_path / "scene_mjx.xml", " ".join(map(str, home)))
    rl = robot_legs(robot, FEET, options=RetargetOptions(keyframe_from=keys))
    check = stand_check(rl)
    assert check["problems"] == [] and check["height_over_leg"] > 0.5
    clip = retarget(walk, rl)
    assert 0.3 < clip.metadata["scale"] < 1.0  # not the folded pose's few percent
    folded = _keys_file(tmp_path / "folded.xml", " ".join(map(str, robot.qpos0)))
    with pytest.warns(StandingPoseWarning):
        robot_legs(robot, FEET, options=RetargetOptions(keyframe_from=folded))
    # the CLI refuses it too, and names the file beside the robot that holds a keyframe
    walk.save(tmp_path / "walk.npz")
    out = tmp_path / "q.npz"
    argv = ["retarget", str(tmp_path / "walk.npz"), "--robot", str(folded_scene), "--out"]
    argv.append(str(out))
    assert main([*argv, "--feet", "FL,FR,RL,RR"]) == 2 and not out.exists()
    assert "scene_mjx.xml (home)" in capsys.readouterr().err
    assert main([*argv, "--feet", "FL,FR,RL,RR", "--keyframe-from", str(keys)]) == 0
    assert out.exists()


# ------------------------------------------------------------ robots by Menagerie name
def test_a_menagerie_name_without_the_package_is_a_typed_error(monkeypatch, tmp_path, capsys):
    """``--robot unitree_go2`` goes through mujoco-menagerie: not installed, or failing
    to give the model (offline), is a RobotSourceError (exit 2); a package that gives a
    model is used. The network is never touched: the module is replaced."""
    import sys
    import types

    from habitsim.retarget import RobotSourceError

    monkeypatch.setitem(sys.modules, "mujoco_menagerie", None)  # import fails
    with pytest.raises(RobotSourceError):
        load_robot("unitree_go2")
    walk_path = tmp_path / "walk.npz"
    generate("dog", "walk", seed=7, duration_s=0.5).save(walk_path)
    out = tmp_path / "q.npz"
    argv = ["retarget", str(walk_path), "--robot", "unitree_go2", "--out", str(out)]
    assert main(argv) == 2 and not out.exists()
    assert "pip install mujoco-menagerie" in capsys.readouterr().err

    offline = types.ModuleType("mujoco_menagerie")

    def fail(name: str) -> mujoco.MjModel:
        raise OSError("no network")

    offline.load = fail  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "mujoco_menagerie", offline)
    with pytest.raises(RobotSourceError):
        load_robot("unitree_go2")
    seen = []
    online = types.ModuleType("mujoco_menagerie")
    online.load = lambda name: seen.append(name) or load_robot(GO1)  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "mujoco_menagerie", online)
    assert load_robot("unitree_go1").nq == 19 and seen == ["unitree_go1"]
    with pytest.raises(RetargetError):  # a path that does not exist is no name
        load_robot(tmp_path / "missing.xml")


def test_vendored_a1_is_menagerie_through_the_vendor_helper(walk):
    """The A1 vendored by `habitsim models vendor`: one file without meshes, its feet found
    by their bodies, standing on its home keyframe (no folded pose), retargeted cleanly."""
    from habitsim.retarget import stand_check

    scene = Path(__file__).parent / "robots" / "unitree_a1" / "scene.xml"
    assert "made by `habitsim models vendor`" in scene.read_text().splitlines()[0]
    a1 = load_robot(scene)
    assert not np.any(a1.geom_type == mujoco.mjtGeom.mjGEOM_MESH) and a1.nmesh == 0
    feet = find_robot_feet(a1)
    assert feet == ("FL_calf", "FR_calf", "RL_calf", "RR_calf")
    rl = robot_legs(a1, feet)
    assert rl.home_source == "keyframe 'home'" and stand_check(rl)["problems"] == []
    clip = retarget(walk, rl)
    assert clip.metadata["ik_residual_max_m"] < 1e-3
