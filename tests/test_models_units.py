"""Unit tests of the learning core's maths: shapes, quantizer, flow, features, retrieval,
configuration."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from habitsim.contacts import contacts_from_feet
from habitsim.gaits import generate
from habitsim.models.config import Config, ModelConfig, NetConfig, QuantizerConfig, preset
from habitsim.models.data import ClipSet, feature_stats
from habitsim.models.errors import ConfigError, TextEncoderError
from habitsim.models.features import (
    C_DIM,
    C_INDEX,
    FEAT_DIM,
    FEATURE_VERSION,
    Q_DIM,
    batched_fk,
    canonical_window,
    clip_arrays,
    decoded_contacts,
    features_to_motion,
    species_offsets,
    uncanonicalize,
    window_positions,
)
from habitsim.models.habit import AffineCoupling, HabitPosterior, RealNVP
from habitsim.models.kinematics import fk_torch
from habitsim.models.model import HabitVQVAE
from habitsim.models.quantizer import EMAQuantizer, code_probabilities, residual_quantize
from habitsim.models.text import morphology_vector, retrieve_neighbour
from habitsim.models.vqvae import MotionDecoder, MotionEncoder
from habitsim.motion import Motion
from habitsim.skeleton import get_skeleton

pytestmark = pytest.mark.usefixtures("torch_one_thread")


# ---------------------------------------------------------------------------- shapes


def test_encoder_decoder_shapes_and_rate():
    net = NetConfig(width=32, depth=2, dilation=3, down_t=2)
    enc = MotionEncoder(FEAT_DIM, 24, net)
    dec = MotionDecoder(24, 10, FEAT_DIM, net)
    x = torch.randn(3, FEAT_DIM, 64)
    f = enc(x)
    assert f.shape == (3, 24, 16)  # temporal rate 4
    y = dec(f, torch.randn(3, 10))
    assert y.shape == (3, FEAT_DIM, 64)
    with pytest.raises(ValueError, match="condition"):
        dec(f, None)


@pytest.mark.parametrize("levels", [1, 3])
def test_model_shapes_every_variant(levels):
    species = ["cat", "horse"]
    for variant in ("habit", "no_habit", "habit_only", "text_only", "habit_ema"):
        cfg = preset("small", variant).replace(**{"model.quantizer.levels": levels}).model
        m = HabitVQVAE(cfg, species, ["cat", "horse", "tiger"], 8)
        x = torch.randn(2, cfg.window, FEAT_DIM)
        f = m.encode(x)
        assert f.shape == (2, cfg.quantizer.code_dim, cfg.window // 4)
        q = m.quantize(f, sample=False, update=False)
        assert q.indices.shape == (2, cfg.window // 4)
        assert q.level_indices.shape == (2, cfg.window // 4, levels)
        codebooks = [k for k in m.state_dict() if k.endswith("codebook")]
        assert len(codebooks) == levels and "quantizer.codebook" in codebooks
        z = m.posterior(x, species)[0] if cfg.use_z else None
        cond = m.condition(species, z)
        assert (cond is None) == (m.cond_dim == 0)
        y = m.decode(q.quantized, cond, m.path(x))
        assert y.shape == x.shape
        if cfg.use_z:
            assert m.sample_prior("cat", 5).shape == (5, cfg.habit.z_dim)


def test_path_conditioned_decoder_follows_the_path_it_is_given():
    """A ``path_condition`` model reads the pelvis path of the source windows (per code,
    un-quantized) and its output depends on it; without a path it refuses to decode; a
    configuration without the key (older checkpoints) is a model without the input."""
    cfg = preset("small").replace(**{"model.path_condition": True}).model
    m = HabitVQVAE(cfg, ["cat", "horse"], ["cat", "horse"], 8).eval()
    clip = generate("cat", "trot", seed=0, duration_s=2.0)
    x = torch.from_numpy(canonical_window(clip_arrays(clip), 0, cfg.window)[0][None])
    p = m.path(x)
    assert p.shape == (1, 2, cfg.window // cfg.rate)
    # the mean of each code's frames of the normalised pelvis velocity (x, y)
    sl = slice(Q_DIM, Q_DIM + 2)
    v = ((x[0, :, sl] - m.feat_mean[sl]) / m.feat_std[sl]).numpy()
    want = v.reshape(-1, cfg.rate, 2).mean(axis=1).T
    np.testing.assert_allclose(p[0].numpy(), want, rtol=1e-6)
    codes = m.quantize(m.encode(x), sample=False, update=False).quantized
    cond = m.condition(["cat"], m.posterior(x, ["cat"])[0])
    with torch.no_grad():
        y1 = m.decode(codes, cond, p)
        y2 = m.decode(codes, cond, p + 1.0)
    assert (y1 - y2).abs().max() > 1e-3
    with pytest.raises(ValueError, match="path"):
        m.decode(codes, cond)
    d = preset("small").to_dict()
    d["model"].pop("path_condition")
    assert Config.from_dict(d).model.path_condition is False
    plain = HabitVQVAE(Config.from_dict(d).model, ["cat"], ["cat"], 8)
    assert not any("path" in k for k in plain.state_dict())


def test_path_heading_gives_the_heading_and_the_velocity_in_its_frame():
    """With ``path_heading`` the path's last two channels are (cos ψ, sin ψ) of the pelvis
    heading in the window's frame and its first two the velocity in the heading's frame,
    per code: a turning walk keeps moving forwards on it, a backward walk backwards, while
    the heading turns; the flag needs the path input."""
    cfg = preset("small").replace(**{"model.path_condition": True, "model.path_heading": True})
    m = HabitVQVAE(cfg.model, ["dog"], ["dog"], 8).eval()
    w = cfg.model.window
    for action, sign in (("turn_left", 1.0), ("walk_backward", -1.0)):
        clip = generate("dog", action, seed=1, duration_s=3.0)
        arrays = clip_arrays(clip)
        x = torch.from_numpy(canonical_window(arrays, 0, w)[0][None])
        p = m.path(x)[0].numpy()
        assert p.shape == (4, w // cfg.model.rate)
        yaw = arrays.yaw[:w] - arrays.yaw[0]
        want = np.stack([np.cos(yaw), np.sin(yaw)]).reshape(2, -1, cfg.model.rate).mean(-1)
        np.testing.assert_allclose(p[2:], want, atol=1e-4)
        v = x[0, :, Q_DIM : Q_DIM + 2].numpy()  # the pelvis velocity in the window's frame
        c, s_ = np.cos(yaw), np.sin(yaw)
        own = np.stack([c * v[:, 0] + s_ * v[:, 1], c * v[:, 1] - s_ * v[:, 0]], -1)
        mean, std = m.feat_mean[Q_DIM : Q_DIM + 2].numpy(), m.feat_std[Q_DIM : Q_DIM + 2].numpy()
        own = ((own - mean) / std).reshape(-1, cfg.model.rate, 2).mean(1).T
        np.testing.assert_allclose(p[:2], own, atol=1e-3)
        assert np.all(sign * (p[0] * std[0] + mean[0]) > 0)  # forwards (backwards) throughout
        turned = float(np.arctan2(p[3], p[2])[-1])
        assert turned > 0.1 if action == "turn_left" else abs(turned) < 0.05
    with pytest.raises(ConfigError, match="path_heading needs model.path_condition"):
        preset("small").replace(**{"model.path_heading": True})


def test_heading_relative_decoder_turns_its_output_with_the_source_heading():
    """With ``heading_relative`` the decoder's output is turned, frame by frame, by the
    source's heading read from the path (within 0.01 rad of the turning source's own
    pelvis heading away from the window's ends); the flag needs the heading channels."""
    from habitsim.models.model import turn_windows

    cfg = preset("small").replace(
        **{
            "model.path_condition": True,
            "model.path_heading": True,
            "model.heading_relative": True,
        }
    )
    m = HabitVQVAE(cfg.model, ["dog"], ["dog"], 8).eval()
    w, r = cfg.model.window, cfg.model.rate
    arrays = clip_arrays(generate("dog", "turn_left", seed=3, duration_s=3.0))
    x = torch.from_numpy(canonical_window(arrays, 0, w)[0][None])
    path = m.path(x)
    psi = m.path_heading_frames(path, w)[0].numpy()
    want = np.unwrap(arrays.yaw[:w] - arrays.yaw[0])
    assert want[-1] > 0.2  # the window turns
    np.testing.assert_allclose(psi[r:-r], want[r:-r], atol=0.01)
    codes = m.quantize(m.encode(x), sample=False, update=False).quantized
    cond = m.condition(["dog"], m.posterior(x, ["dog"])[0])
    with torch.no_grad():
        y = m.decode(codes, cond, path)
        raw = m.denormalize(m.decoder(codes, cond, path).transpose(1, 2))
    torch.testing.assert_close(y, turn_windows(raw, torch.from_numpy(psi)[None]))
    assert (y - raw).abs().max() > 1e-3
    with pytest.raises(ConfigError, match="heading_relative needs model.path_heading"):
        preset("small").replace(**{"model.path_condition": True, "model.heading_relative": True})


# ---------------------------------------------------------------------------- quantizer


def _quantizer(k=6, d=3, decay=0.9, threshold=1.0, reset=True) -> EMAQuantizer:
    return EMAQuantizer(
        QuantizerConfig(num_codes=k, code_dim=d, ema_decay=decay, reset_threshold=threshold),
        reset=reset,
    )


def test_ema_update_matches_formula():
    q = _quantizer(reset=False, threshold=0.0)
    g = torch.Generator().manual_seed(0)
    q.codebook.copy_(torch.randn(6, 3, generator=g))
    q.code_sum.copy_(torch.randn(6, 3, generator=g))
    q.code_count.copy_(torch.rand(6, generator=g) + 0.5)
    q.initialized.fill_(True)
    f = torch.randn(10, 3, generator=g)
    idx = torch.tensor([0, 0, 1, 2, 2, 2, 3, 3, 4, 4])
    sum0, cnt0 = q.code_sum.clone(), q.code_count.clone()
    q.ema_update(f, idx)
    lam = 0.9
    exp_cnt = lam * cnt0 + (1 - lam) * torch.bincount(idx, minlength=6).float()
    exp_sum = lam * sum0 + (1 - lam) * torch.stack([f[idx == k].sum(0) for k in range(6)])
    torch.testing.assert_close(q.code_count, exp_cnt)
    torch.testing.assert_close(q.code_sum, exp_sum)
    torch.testing.assert_close(q.codebook, exp_sum / exp_cnt[:, None])


def test_code_reset_revives_dead_codes():
    q = _quantizer(k=8, d=2, decay=0.5, threshold=1.0, reset=True)
    q.codebook.copy_(torch.tensor([[0.0, 0.0]] + [[100.0 + i, 100.0] for i in range(7)]))
    q.code_sum.copy_(q.codebook)
    q.code_count.fill_(1.0)
    q.initialized.fill_(True)
    g = torch.Generator().manual_seed(1)
    f = torch.randn(64, 2, generator=g) * 0.1  # all latents near code 0
    idx = q.select(f, sample=False)
    assert (idx == 0).all()
    n_reset = q.ema_update(f, idx, g)
    assert n_reset == 7
    # every revived code now sits on one of the batch's latents
    d = torch.cdist(q.codebook[1:], f).min(dim=1).values
    assert (d < 1e-6).all()
    assert (q.code_count[1:] == 1.0).all()
    # without reset the dead codes keep their stale value
    q2 = _quantizer(k=8, d=2, decay=0.5, reset=False)
    q2.codebook.copy_(torch.tensor([[0.0, 0.0]] + [[100.0 + i, 100.0] for i in range(7)]))
    q2.code_sum.copy_(q2.codebook)
    q2.code_count.fill_(1.0)
    q2.initialized.fill_(True)
    q2.ema_update(f, idx, g)
    assert torch.allclose(q2.codebook[1:, 0], torch.arange(7.0) + 100.0)


def test_residual_levels_quantize_what_the_previous_left():
    g = torch.Generator().manual_seed(5)
    levels = [_quantizer(k=8, d=3) for _ in range(3)]
    for n, q in enumerate(levels):
        q.codebook.copy_(torch.randn(8, 3, generator=g) * 0.3**n)
        q.initialized.fill_(True)
    f = torch.randn(2, 3, 5, generator=g, requires_grad=True)
    out = residual_quantize(levels, f, sample=False, update=False)
    # by hand: nearest code of each residual in turn
    flat = f.detach().permute(0, 2, 1).reshape(-1, 3)
    r, total, commit, idx = flat.clone(), torch.zeros_like(flat), 0.0, []
    for q in levels:
        k = torch.cdist(r, q.codebook).argmin(-1)
        e = q.codebook[k]
        commit += float(((r - e) ** 2).mean())
        total, r = total + e, r - e
        idx.append(k)
    torch.testing.assert_close(out.quantized.detach().permute(0, 2, 1).reshape(-1, 3), total)
    assert out.level_indices.shape == (2, 5, 3)
    torch.testing.assert_close(out.level_indices.reshape(-1, 3), torch.stack(idx, -1))
    assert torch.equal(out.indices, out.level_indices[..., 0])
    assert float(out.commit_loss.detach()) == pytest.approx(commit, rel=1e-5)
    # more levels never quantize worse here (each level's codes shrink with the residual)
    rq = residual_quantize
    with torch.no_grad():
        err = [
            float((rq(levels[:n], f, sample=False, update=False).quantized - f).norm())
            for n in (1, 2, 3)
        ]
    assert err[2] < err[1] < err[0]
    out.quantized.sum().backward()  # straight-through: the gradient reaches f unchanged
    torch.testing.assert_close(f.grad, torch.ones_like(f))
    one = residual_quantize(levels[:1], f, sample=False, update=False)
    assert torch.equal(one.indices, levels[0](f, sample=False, update=False).indices)


def test_soft_quantization_tends_to_nearest_code():
    g = torch.Generator().manual_seed(3)
    q = _quantizer(k=16, d=4)
    q.codebook.copy_(torch.randn(16, 4, generator=g))
    f = torch.randn(500, 4, generator=g)
    nearest = q.select(f, sample=False)
    agree = []
    for tau in (10.0, 1.0, 0.1, 1e-3, 1e-6):
        s = q.select(f, sample=True, tau=tau, generator=torch.Generator().manual_seed(0))
        agree.append(float((s == nearest).float().mean()))
    assert agree == sorted(agree)
    assert agree[-1] == 1.0 and agree[0] < 0.5
    p = code_probabilities(f, q.codebook, 1e-4)
    assert torch.equal(p.argmax(-1), nearest)


def test_sampling_follows_softmax_distribution():
    q = _quantizer(k=3, d=1)
    q.codebook.copy_(torch.tensor([[0.0], [1.0], [2.0]]))
    f = torch.zeros(20000, 1)
    s = q.select(f, sample=True, tau=1.0, generator=torch.Generator().manual_seed(0))
    freq = torch.bincount(s, minlength=3).float() / s.numel()
    expect = torch.softmax(-torch.tensor([0.0, 1.0, 4.0]), 0)
    torch.testing.assert_close(freq, expect, atol=0.015, rtol=0)


def test_straight_through_gradient():
    q = _quantizer(k=4, d=2)
    q.eval()
    q.codebook.copy_(torch.randn(4, 2))
    f = torch.randn(1, 2, 5, requires_grad=True)
    out = q(f)
    out.quantized.sum().backward()
    torch.testing.assert_close(f.grad, torch.ones_like(f))


# ---------------------------------------------------------------------------- flow


def _trained_like_flow(dim=6, layers=4, seed=0) -> RealNVP:
    torch.manual_seed(seed)
    flow = RealNVP(dim, layers, 16).double()
    for layer in flow.layers:  # non-trivial (a fresh flow is the identity)
        torch.nn.init.normal_(layer.net[-1].weight, std=0.5)
        torch.nn.init.normal_(layer.net[-1].bias, std=0.5)
    return flow


def test_flow_inverse_of_forward_is_identity():
    flow = _trained_like_flow()
    w = torch.randn(32, 6, dtype=torch.float64)
    z, ld_f = flow(w)
    w2, ld_i = flow.inverse(z)
    torch.testing.assert_close(w2, w, atol=1e-10, rtol=0)
    torch.testing.assert_close(ld_f, -ld_i, atol=1e-10, rtol=0)
    assert not torch.allclose(z, w)


def test_flow_logdet_equals_autograd_jacobian():
    flow = _trained_like_flow()
    for i in range(4):
        w = torch.randn(6, dtype=torch.float64, generator=torch.Generator().manual_seed(i))
        jac = torch.autograd.functional.jacobian(lambda v: flow(v[None])[0][0], w)
        expect = torch.linalg.slogdet(jac).logabsdet
        torch.testing.assert_close(flow(w[None])[1][0], expect, atol=1e-9, rtol=0)
        z = flow(w[None])[0][0]
        jac_i = torch.autograd.functional.jacobian(lambda v: flow.inverse(v[None])[0][0], z)
        torch.testing.assert_close(
            flow.inverse(z[None])[1][0], torch.linalg.slogdet(jac_i).logabsdet, atol=1e-9, rtol=0
        )


def test_flow_log_prob_is_a_density():
    # 1-D marginal check in 2-D: the density integrates to ≈ 1 on a grid
    flow = _trained_like_flow(dim=2, layers=2, seed=1)
    xs = torch.linspace(-12, 12, 801, dtype=torch.float64)
    gx, gy = torch.meshgrid(xs, xs, indexing="ij")
    z = torch.stack([gx.reshape(-1), gy.reshape(-1)], dim=-1)
    with torch.no_grad():
        p = flow.log_prob(z).exp()
    cell = float((xs[1] - xs[0]) ** 2)
    assert abs(float(p.sum()) * cell - 1.0) < 0.02


def test_coupling_starts_as_identity():
    layer = AffineCoupling(4, 8, torch.tensor([1, 0, 1, 0], dtype=torch.bool))
    w = torch.randn(3, 4)
    z, ld = layer(w)
    torch.testing.assert_close(z, w)
    torch.testing.assert_close(ld, torch.zeros(3))


def test_posterior_handles_any_length():
    cfg = preset("small").model.habit
    post = HabitPosterior(FEAT_DIM, cfg)
    for t in (5, 32, 33):
        mu, ls = post(torch.randn(2, t, FEAT_DIM))
        assert mu.shape == ls.shape == (2, cfg.z_dim)


# ---------------------------------------------------------------------------- features


def test_features_round_trip_reproduces_the_motion():
    m = generate("dog", "turn_left", seed=4, duration_s=2.5)
    arr = clip_arrays(m)
    n = arr.num_frames
    f, valid, yaw0 = canonical_window(arr, 0, n)
    assert valid.all() and f.shape == (n, FEAT_DIM)
    back = uncanonicalize(f, yaw0)
    rebuilt = features_to_motion(back, "dog", m.fps, m.root_positions[0, :2])
    err = np.linalg.norm(rebuilt.global_positions() - m.global_positions(), axis=-1).max()
    assert err < 1e-4  # float32 features, integrated root


def test_window_is_heading_canonical_and_padded():
    m = generate("horse", "walk", seed=2, duration_s=2.0)
    arr = clip_arrays(m)
    f, valid, yaw0 = canonical_window(arr, arr.num_frames - 10, 32)
    assert valid.sum() == 10 and not valid[10:].any()
    from habitsim.models.features import heading_yaw

    assert abs(heading_yaw(f[0, :4].astype(np.float64))) < 1e-5
    assert np.allclose(f[10:], f[9])  # edge padding


def test_window_positions_match_skeleton_fk():
    ms = [generate(s, "walk", seed=1, duration_s=1.5) for s in ("cat", "elephant")]
    arrs = [clip_arrays(m) for m in ms]
    x = torch.from_numpy(np.stack([canonical_window(a, 0, 32)[0] for a in arrs])).double()
    pos = window_positions(x, [m.species for m in ms], 30.0)
    for i, (m, a) in enumerate(zip(ms, arrs, strict=True)):
        ref = m.global_positions()[:32] - np.r_[m.root_positions[0, :2], 0.0]
        c, s = math.cos(-a.yaw[0]), math.sin(-a.yaw[0])
        rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        np.testing.assert_allclose(pos[i].numpy(), ref @ rot.T, atol=2e-4)


def test_root_path_does_not_depend_on_the_decoded_pelvis_yaw():
    # Velocities live in the window's frame: a wrong pelvis yaw turns the body, not its path.
    m = generate("horse", "turn_left", seed=3, duration_s=2.0)
    arr = clip_arrays(m)
    x = torch.from_numpy(canonical_window(arr, 0, 48)[0]).double()[None]
    bent = x.clone()
    half = torch.tensor(0.15, dtype=torch.float64)  # a 0.3 rad yaw error on every pelvis
    yaw = torch.stack([torch.cos(half), 0 * half, 0 * half, torch.sin(half)])
    from habitsim.models.kinematics import torch_quat_mul

    bent[0, :, :4] = torch_quat_mul(yaw.expand(48, 4), x[0, :, :4])
    a = window_positions(x, ["horse"], 30.0)[0, :, 0]
    b = window_positions(bent, ["horse"], 30.0)[0, :, 0]
    torch.testing.assert_close(a, b)


def test_mirrored_training_clips_pair_with_mirrored_partners(tmp_path):
    from habitsim.dataset import build_dataset
    from habitsim.models.data import load_clip_set

    build_dataset(
        tmp_path, clips_per_species=6, seed=3, species=["cat", "dog"], workers=1, progress=False
    )
    plain = load_clip_set(tmp_path, "train")
    both = load_clip_set(tmp_path, "train", mirror=True)
    assert len(both.clips) == 2 * len(plain.clips)
    for i, j in enumerate(range(0, len(both.clips), 2)):
        a, r = both.clips[j], both.clips[j + 1]
        assert a.species == r.species == plain.clips[i].species
        assert both.pair_keys[j + 1] == f"{both.pair_keys[j]}~mirror"
        # reflected root path, same height
        np.testing.assert_allclose(r.root[:, 1], -a.root[:, 1], atol=1e-9)
        np.testing.assert_allclose(r.height, a.height, atol=1e-12)
    for i, part in enumerate(both.partners()):
        assert all((both.pair_keys[k] or "").endswith("~mirror") == (i % 2 == 1) for k in part)


def test_batched_fk_matches_fk_torch():
    ms = [
        generate(s, "trot" if s != "bear" else "walk", seed=1, duration_s=1.0)
        for s in ("cat", "bear", "horse")
    ]
    q = torch.tensor(np.stack([m.rotations[:20] for m in ms]))
    r = torch.tensor(np.stack([m.root_positions[:20] for m in ms]))
    a = batched_fk(r, q, species_offsets([m.species for m in ms], torch.float64))
    b = torch.stack([fk_torch(get_skeleton(m.species), r[i], q[i]) for i, m in enumerate(ms)])
    torch.testing.assert_close(a, b)


# ---------------------------------------------------------------------------- retrieval


def test_retrieval_on_hand_made_embeddings():
    emb = {
        "cat": np.array([0.0, 0.0]),
        "dog": np.array([1.0, 0.0]),
        "horse": np.array([5.0, 5.0]),
        "tiger": np.array([0.2, 0.1]),
        "wolf": np.array([0.8, 0.0]),
    }
    r = retrieve_neighbour("tiger", ["cat", "dog", "horse"], emb)
    assert r.neighbour == "cat"
    assert r.text_distance == pytest.approx(math.hypot(0.2, 0.1))
    assert [n for n, *_ in r.ranking] == ["cat", "dog", "horse"]
    assert "cat" in r.explain() and "tiger" in r.explain()
    assert retrieve_neighbour("wolf", ["cat", "dog", "horse"], emb).neighbour == "dog"
    # morphology can overturn a close text match: tiger (200 kg) is far from a cat (4.5 kg)
    morph = {k: morphology_vector(k) for k in emb}
    r2 = retrieve_neighbour(
        "tiger", ["cat", "dog", "horse"], emb, morphology_weight=1.0, morphology=morph
    )
    assert r2.neighbour == "dog"
    assert r2.score == pytest.approx(r2.text_distance + r2.morphology_distance)
    with pytest.raises(TextEncoderError, match="no text embedding"):
        retrieve_neighbour("zebra", ["cat"], emb)
    with pytest.raises(TextEncoderError):
        retrieve_neighbour("cat", ["cat"], emb)


# ---------------------------------------------------------------------------- config


def test_config_round_trip_and_errors():
    cfg = preset("default")
    assert Config.from_dict(cfg.to_dict()) == cfg
    assert cfg.model.quantizer.num_codes == 512 and cfg.model.quantizer.code_dim == 512
    assert cfg.train.alpha == 0.5 and cfg.train.beta == 0.02
    d = cfg.to_dict()
    d["model"]["net"]["widht"] = 3
    with pytest.raises(ConfigError, match="widht"):
        Config.from_dict(d)
    with pytest.raises(ConfigError, match="unknown variant"):
        preset("default", "best")
    with pytest.raises(ConfigError, match="valid: default, small"):
        preset("huge")
    with pytest.raises(ConfigError, match="multiple"):
        ModelConfig(window=30).validate()
    with pytest.raises(ConfigError, match="expected int"):
        Config.from_dict({"train": {"steps": "10"}})
    assert cfg.replace(**{"train.steps": 7}).train.steps == 7


def test_windows_carry_the_clips_stance_labels():
    m = generate("dog", "trot", seed=4, duration_s=2.0)
    assert FEATURE_VERSION == 3 and FEAT_DIM == C_INDEX + C_DIM
    c = clip_arrays(m)
    np.testing.assert_array_equal(c.contacts.astype(bool), m.contacts)
    f, valid, _ = canonical_window(c, 5, 32)
    assert valid.all()
    np.testing.assert_array_equal(decoded_contacts(f), m.contacts[5:37])
    # a clip without labels gets the ones detected on its own toes
    bare = Motion(m.species, m.fps, m.root_positions, m.rotations)
    det = contacts_from_feet(bare.foot_positions(), m.fps, m.species_info.leg_length)
    np.testing.assert_array_equal(clip_arrays(bare).contacts.astype(bool), det)


def test_feature_stats_leave_the_contact_logits_unscaled():
    clips = [clip_arrays(generate(s, "walk", seed=1, duration_s=1.5)) for s in ("cat", "horse")]
    mean, std = feature_stats(ClipSet(clips, [None, None], ["walk", "walk"], 30.0), 16)
    assert mean.shape == (FEAT_DIM,)
    np.testing.assert_array_equal(mean[C_INDEX:], 0.0)
    np.testing.assert_array_equal(std[C_INDEX:], 1.0)
    assert np.all(std[:C_INDEX] >= 1e-2) and np.any(mean[:Q_DIM] != 0.0)


def test_quantizer_dropout_keeps_only_the_first_levels():
    torch.manual_seed(0)
    cfg = QuantizerConfig(num_codes=8, code_dim=4, levels=3)
    levels = [EMAQuantizer(cfg, reset=False) for _ in range(3)]
    for q in levels:
        q.eval()
        with torch.no_grad():
            q.codebook.copy_(torch.randn(8, 4))
            q.initialized.fill_(True)
    f = torch.randn(2, 4, 5)
    full = residual_quantize(levels, f, sample=False, update=False)
    part = residual_quantize(levels, f, sample=False, update=False, n_levels=torch.tensor([1, 3]))
    first = levels[0](f, sample=False, update=False).quantized
    torch.testing.assert_close(part.quantized[0], first[0])
    torch.testing.assert_close(part.quantized[1], full.quantized[1])
    assert not torch.allclose(part.quantized[0], full.quantized[0])
    torch.testing.assert_close(part.level_indices, full.level_indices)  # every level still ran
