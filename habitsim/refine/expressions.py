"""The symbolic NLP of a window (CasADi MX): variables and parameters, the objective's
terms and their least-squares residuals, stage B's centroidal dynamics, and the path
constraints, as :mod:`habitsim.refine.problem` describes them."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import mujoco
import numpy as np

from ..skeleton import JOINT_NAMES
from .kinematics import SymbolicKinematics, _matmul, gibbs_to_matrix, quat_to_matrix_sx
from .layout import _N_EDGES, _TOE_IDX, GLOBAL_PARAMS, GROUND_JOINTS
from .model_facts import model_info


def _srb_momentum(inertia: np.ndarray) -> ca.Function:
    """``(R_t (9), R_t+1 (9)) → R_t · I · ω / fps``: single-rigid-body angular momentum
    between two frames (ω from R_tᵀ R_t+1, rotations row-major; multiply by fps)."""
    r0 = ca.SX.sym("r0", 9)
    r1 = ca.SX.sym("r1", 9)
    m0 = ca.reshape(r0, 3, 3).T
    m1 = ca.reshape(r1, 3, 3).T
    a = m0.T @ m1
    om = 0.5 * ca.vertcat(a[2, 1] - a[1, 2], a[0, 2] - a[2, 0], a[1, 0] - a[0, 1])
    return ca.Function("srb_momentum", [r0, r1], [m0 @ (ca.DM(inertia) @ om)])


@dataclass(frozen=True)
class _Exprs:
    X: ca.MX
    P: ca.MX
    terms: ca.MX
    lsq: ca.MX
    g: ca.MX
    blocks: dict[str, tuple[int, int]]
    residual: ca.MX | None


class _Kin:
    """The per-frame SX function and constants shared by a model's problems."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.info = model_info(model)
        kin = SymbolicKinematics(model)
        info = self.info
        nh = len(info.hinge_names)
        self.nv = 6 + nh
        joint_pts = [kin.body_point(n) for n in JOINT_NAMES]
        sole_pts = [(int(model.geom_bodyid[g]), model.geom_pos[g].copy()) for g in info.foot_geoms]
        xt = ca.SX.sym("x", self.nv)
        qr = ca.SX.sym("qref", 4)
        qpos: list = [0.0] * model.nq
        for i in range(3):
            qpos[info.free_qposadr + i] = xt[i]
        for k, adr in enumerate(info.hinge_qposadr):
            qpos[adr] = xt[6 + k]
        rot = _matmul(
            quat_to_matrix_sx([qr[i] for i in range(4)], normalize=False),
            gibbs_to_matrix([xt[3], xt[4], xt[5]]),
        )
        fk = kin.forward(qpos, free_rotation=rot)
        joints = kin.points(fk, joint_pts)
        soles = kin.points(fk, sole_pts) - ca.vertcat(0, 0, 1) @ ca.DM(info.foot_radius).T
        com = kin.com(fk)
        rot_sx = ca.vertcat(*[ca.SX(rot[i][j]) for i in range(3) for j in range(3)])
        self.frame = ca.Function(
            "frame",
            [xt, qr],
            [joints, soles, com, rot_sx],
            ["x", "qref"],
            ["joints", "sole", "com", "rot"],
        )


def _expressions(kin: _Kin, w: int, dynamics: bool, jerk_rows: bool = True) -> _Exprs:
    """Objective terms, constraints and residual of a ``w``-frame trajectory (MX).

    ``jerk_rows`` False leaves out the jerk terms' rows (their entries of the terms stay, at
    0), see :attr:`SolverSettings.jerk`."""
    info = kin.info
    nh, nv, nj = len(info.hinge_names), kin.nv, len(JOINT_NAMES)
    nx = nv + (4 * _N_EDGES + 3 if dynamics else 0)
    # ------------------------------------------------------------ variables, parameters
    X = ca.MX.sym("X", nx, w)
    npf = 3 * nj + 4 + nh
    ngl = len(GLOBAL_PARAMS)
    P = ca.MX.sym("P", ngl + npf * w)
    gp = {k: P[i] for i, k in enumerate(GLOBAL_PARAMS)}
    Pf = ca.reshape(P[ngl:], npf, w)
    tgt = Pf[: 3 * nj, :]  # (90, W): per frame the joints' x, y, z
    qref = Pf[3 * nj : 3 * nj + 4, :]
    href = Pf[3 * nj + 4 :, :]
    J, S, C, R = kin.frame.map(w)(X[:nv, :], qref)  # (3, 30W), (3, 4W), (3, W), (9, W)
    Jf = ca.reshape(J, 3 * nj, w)

    # ------------------------------------------------------------ objective
    L, fps, grav = gp["leg_length"], gp["fps"], gp["gravity"]
    track = gp["w_track"] * ca.sumsqr(Jf - tgt) / (L**2 * w * nj)

    # smoothness of the trunk: second differences of the pelvis position and rotation
    # matrix (its entries × L/√2 ≈ a displacement at one leg length), as accelerations
    # in units of g. The hinges are not in this term: the solver's contact-aware
    # pre-filter removes their jitter, and coupling 34 hinges across frames would
    # double the cost of every KKT factorisation.
    def d2(a: ca.MX) -> ca.MX:
        return a[:, 2:] - 2 * a[:, 1:-1] + a[:, :-2]

    acc = ca.vertcat(d2(X[:3, :]), d2(R) * (L / np.sqrt(2.0))) * fps**2 / grav
    smooth = gp["w_smooth"] * ca.sumsqr(acc) / (w - 2)
    # jerk of the pelvis (position, rotation entries × L/√2) in units of g·√(g/L)
    if w >= 4 and jerk_rows:
        trunk = ca.vertcat(X[:3, :], R * (L / np.sqrt(2.0)))
        t_jerk = (trunk[:, 3:] - 3 * trunk[:, 2:-1] + 3 * trunk[:, 1:-2] - trunk[:, :-3]) * (
            fps**3 * ca.sqrt(L) / grav**1.5
        )
        jerk = gp["w_jerk"] * ca.sumsqr(t_jerk) / (w - 3)
        jerk_lsq = [ca.sqrt(gp["w_jerk"] / (w - 3)) * ca.vec(t_jerk)]
    else:
        jerk, jerk_lsq = ca.MX(0), []
    # jerk of the hinges, as displacements at half a leg length, same unit: linear, so
    # its Gauss-Newton Hessian is exact and a constant band over 4 frames
    if w >= 4 and jerk_rows:
        hx = X[6:nv, :] * (L / 2.0)
        h_jerk = (hx[:, 3:] - 3 * hx[:, 2:-1] + 3 * hx[:, 1:-2] - hx[:, :-3]) * (
            fps**3 * ca.sqrt(L) / grav**1.5
        )
        hinge = gp["w_hinge_jerk"] * ca.sumsqr(h_jerk) / ((w - 3) * nh)
        hinge_lsq = [ca.sqrt(gp["w_hinge_jerk"] / ((w - 3) * nh)) * ca.vec(h_jerk)]
    else:
        hinge, hinge_lsq = ca.MX(0), []
    reg = (
        gp["w_reg"] * ca.sumsqr(X[6:nv, :] - href) / (w * nh)
        + gp["w_root"] * ca.sumsqr(X[3:6, :]) / w
    )
    lsq = [
        ca.sqrt(gp["w_track"] / (L**2 * w * nj)) * ca.vec(Jf - tgt),
        ca.sqrt(gp["w_smooth"] / (w - 2)) * ca.vec(acc),
        *jerk_lsq,
        *hinge_lsq,
        ca.sqrt(gp["w_reg"] / (w * nh)) * ca.vec(X[6:nv, :] - href),
        ca.sqrt(gp["w_root"] / w) * ca.vec(X[3:6, :]),
    ]
    extra = [ca.MX(0), ca.MX(0)]
    residual = None

    # ------------------------------------------------------------ dynamics (stage B)
    if dynamics:
        mu = gp["mu"]
        nb = 4 * _N_EDGES
        beta = X[nv : nv + nb, :]  # (16, W) edge weights [m·g], foot-major
        com = X[nv + nb :, :]  # (3, W) CoM variables, tied to the FK's CoM by the com rows
        ez = ca.DM([0, 0, 1])
        edges = [
            ca.vertcat(mu, 0, 1),
            ca.vertcat(-mu, 0, 1),
            ca.vertcat(0, mu, 1),
            ca.vertcat(0, -mu, 1),
        ]
        forces = []  # per foot (3, W) [m·g]
        for f in range(4):
            ff = edges[0] @ beta[f * _N_EDGES, :]
            for e in range(1, _N_EDGES):
                ff = ff + edges[e] @ beta[f * _N_EDGES + e, :]
            forces.append(ff)
        ftot = forces[0] + forces[1] + forces[2] + forces[3]
        r_f = d2(com) * fps**2 / grav + ez @ ca.DM.ones(1, w - 2) - ftot[:, 1:-1]
        mom = _srb_momentum(info.inertia).map(w - 1)(R[:, :-1], R[:, 1:]) * fps  # L at t + ½
        ldot = (mom[:, 1:] - mom[:, :-1]) * fps
        torque: ca.MX | float = 0
        for f in range(4):
            lever_f = (S[:, f::4] - com)[:, 1:-1] / L
            torque = torque + ca.cross(lever_f, forces[f][:, 1:-1])
        r_t = ldot / (info.mass * grav * L) - torque
        extra = [
            gp["w_residual"] * (ca.sumsqr(r_f) + ca.sumsqr(r_t)) / (w - 2),
            gp["w_force"] * ca.sumsqr(beta) / w,
        ]
        lsq += [
            ca.sqrt(gp["w_residual"] / (w - 2)) * ca.vec(ca.vertcat(r_f, r_t)),
            ca.sqrt(gp["w_force"] / w) * ca.vec(beta),
        ]
        z = ca.MX.zeros(3, 1)
        residual = ca.vertcat(ca.horzcat(z, r_f, z), ca.horzcat(z, r_t, z))
        com_rows = [("com", ca.vec(com - C))]
    else:
        com_rows = []
    terms = ca.vertcat(track, smooth, jerk, hinge, reg, *extra)

    # ------------------------------------------------------------ path constraints
    sole_z = ca.reshape(S[2, :], 4, w)
    gz = ca.reshape(J[2, :], nj, w)[list(GROUND_JOINTS), :]
    toes = ca.vertcat(*[ca.vertcat(Jf[3 * i, :], Jf[3 * i + 1, :]) for i in _TOE_IDX])  # (8, W)
    toe_z = ca.vertcat(*[Jf[3 * i + 2, :] for i in _TOE_IDX])  # (4, W)
    blocks_e = [
        ("sole", ca.vec(sole_z)),
        ("ground", ca.vec(gz)),
        ("clearance", ca.vec(toe_z)),
        ("pin", ca.vec(toes[:, 1:] - toes[:, :-1])),
    ] + com_rows
    blocks, start = {}, 0
    for name, expr in blocks_e:
        blocks[name] = (start, start + expr.shape[0])
        start += expr.shape[0]
    return _Exprs(
        X, P, terms, ca.vertcat(*lsq), ca.vertcat(*[e for _, e in blocks_e]), blocks, residual
    )
