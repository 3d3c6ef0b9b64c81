"""Build the refinement NLP of one window — apart from solving it (STYLE.md habit 4).

:func:`build_refinement_problem` returns a :class:`RefinementProblem`: the IPOPT solver
(a casadi ``nlpsol`` built with ``expand=True``, i.e. a pure SX graph with exact
Hessians), the variable / parameter / constraint layout, and the helpers that turn a
window of input data into parameter values, bounds and an initial guess. Nothing in the
built problem depends on the clip: targets, weights, leg length, mass, frame rate,
friction and contact labels are all *values* (parameters, or bounds), so one build per
(model, window length, stage, solver options) serves every window of every clip of that
species; :mod:`habitsim.refine.solve` caches it.

Per frame t the variables are (in this order)

=========  ====  ===============================================================
block      size  meaning
=========  ====  ===============================================================
``root``   3     pelvis (free-joint) position [m]
``rot``    3     Gibbs vector g of a correction of the input's root orientation:
                 R_t = R̂_t · C(g_t) (:func:`~.kinematics.gibbs_to_matrix`) [-]
``hinge``  n     the model's hinge angles in qpos order [rad], bounds = joint ranges
``force``  16    stage B only: friction-pyramid edge weights β ≥ 0 of the 4 feet,
                 in units of m·g (forced to 0 by bounds when the foot is in swing)
``com``    3     stage B only: the centre of mass c [m], tied to the FK's CoM by the
                 ``com`` rows (an auxiliary variable: it keeps c̈ a linear function of
                 3 variables per frame instead of a nonlinear one of 3 × 40, which
                 makes stage B's Hessian, factorisation and build cheaper; README)
=========  ====  ===============================================================

Why a Gibbs-vector correction of the input orientation rather than a quaternion with a
norm constraint: it needs no extra equality constraint, is rational (cheap, exact
Hessians), has no singularity below a 180° correction (corrections are small), and the
input's heading can wind up any number of turns without wrapping problems.

Objective (all terms dimensionless, each averaged so the weights mean the same for any
window length and species):

* ``track``   = w_track · mean over frames and habitsim joints of ‖p − p̂‖² / L²;
* ``smooth``  = w_smooth · mean over interior frames of the pelvis' squared second
  differences (position, and rotation-matrix entries × L/√2) · fps⁴ / g², i.e. trunk
  accelerations in units of g. Hinge jitter is removed *before* the solve by the
  contact-aware second-difference pre-filter of :mod:`habitsim.refine.solve`;
* ``jerk``    = w_jerk · mean over frames of the pelvis' squared third differences
  (position, rotation-matrix entries × L/√2) · fps³ in units of g·√(g/L);
* ``hinge_jerk`` = w_hinge_jerk · mean over frames and hinges of the squared third
  differences of the hinge angles × L/2 (a displacement at half a leg length), same unit.
  Planting feet the input lets slide and lifting swing feet over the contact height bend
  the input's paths, and inputs far outside the joint ranges are clipped; without these
  two terms the bends came out as kinks (README). Both are linear or nearly so; a jerk of
  the 30 joint positions themselves made every KKT factorisation slower and IPOPT's
  Gauss-Newton iterations stall. The hinge term couples 4 frames;
* ``regularisation`` = w_reg · mean of (θ − θ̂)² over frames and hinges
  + w_root · mean ‖g‖² (stay near the input angles and root orientation);
* stage B ``residual`` = w_residual · mean over interior frames of
  ‖r_F‖²/(m·g)² + ‖r_τ‖²/(m·g·L)², the 6-D root residual wrench of the centroidal
  dynamics (below); ``force`` = w_force · mean ‖β‖² (makes the contact forces unique).

The residual wrench is the slack of the centroidal equations, eliminated (the optimum of
``min ‖r‖² s.t. r = h(x)`` is ``min ‖h(x)‖²``)::

    r_F = m·(c̈ − g⃗) − Σ_f F_f                        (c: the CoM variables)
    r_τ = dL/dt − Σ_f (p_f − c) × F_f,   L = R_t · I_c · ω_t   (single rigid body)

with c̈ and dL/dt by central differences, ω from R_tᵀR_{t+1}, I_c the model's composite
inertia about the CoM in the pelvis frame at the home keyframe, p_f the lowest point of
the foot sphere, F_f = m·g · Σ_e β_e (μ·d_e + ẑ) with d_e = ±x̂, ±ŷ (a linear friction
pyramid: quadratic cones are much slower in IPOPT, see the README).

Constraints (rows of g, in this order):

* ``sole``  (4 per frame): height of the lowest point of each foot sphere
  (geom centre z − radius) ≥ 0, = 0 when the foot is in contact (optionally at least
  a given swing floor in swing; bounds, see :meth:`RefinementProblem.bounds`);
* ``ground`` (per frame, every habitsim joint except the toes): height ≥ 0 (the toe
  sites lie on the foot spheres, so the sole rows cover them);
* ``clearance`` (4 per frame): height of each toe site — the point docs/metrics.md's
  ``skate_mm`` and ``penetration_mm`` measure — at least the swing clearance profile
  of :mod:`habitsim.refine.solve` in swing (free in stance and where no profile is
  given);
* ``pin``   (8 per frame pair t, t+1): horizontal toe-site displacement = 0 when the
  foot is in contact in both frames, and in the pairs the swing profile pins (a swing
  foot below the metric's contact height rises vertically); free otherwise. Pinning the
  toe (a material point on the sphere's surface) while the sphere's lowest point stays
  on the floor lets the foot roll on its sphere the way a pad does, with no sliding of
  the toe;
* ``com``   (stage B, 3 per frame): c − CoM(FK) = 0, the CoM from the model's body
  masses and inertial frames.

Contact labels only change bounds (``lbg``/``ubg``), frames taken over from a previous
window only change variable bounds (``lbx = ubx``): neither triggers a rebuild.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import mujoco
import numpy as np

from ..errors import unknown_choice
from ..mjutils import free_joints, home_qpos
from ..skeleton import JOINT_NAMES
from .errors import RefineError, RefineInputError
from .kinematics import SymbolicKinematics, _matmul, gibbs_to_matrix, quat_to_matrix_sx

__all__ = [
    "FEET",
    "GROUND_JOINTS",
    "GLOBAL_PARAMS",
    "COST_TERMS",
    "STAGE_A_TERMS",
    "SolverSettings",
    "RefinementProblem",
    "ModelInfo",
    "model_info",
    "build_refinement_problem",
    "clip_evaluator",
]

#: Feet in habitsim order; their geoms are ``<leg>_foot`` spheres, toes ``<leg>_toe`` sites.
FEET = ("lf", "rf", "lh", "rh")
#: Names of the global (per-window) parameters, in order.
GLOBAL_PARAMS = (
    "leg_length",
    "fps",
    "gravity",
    "mu",
    "w_track",
    "w_smooth",
    "w_jerk",
    "w_hinge_jerk",
    "w_reg",
    "w_root",
    "w_residual",
    "w_force",
)
#: Cost term names (stage A has the first five, stage B all seven).
COST_TERMS = (
    "track",
    "smooth",
    "jerk",
    "hinge_jerk",
    "regularisation",
    "residual",
    "force",
)
#: Number of cost terms of stage A (the first ones of :data:`COST_TERMS`).
STAGE_A_TERMS = 5
_TOES = tuple(f"{leg}_toe" for leg in FEET)
#: Name prefixes of the legs' hinges (the pre-filter treats them contact-aware).
LEG_PREFIXES = tuple(f"{leg}_" for leg in FEET)
_TOE_IDX = tuple(JOINT_NAMES.index(n) for n in _TOES)
#: Habitsim joints held at or above the floor by the ``ground`` rows (the toes are on
#: the foot spheres, held by the ``sole`` rows).
GROUND_JOINTS = tuple(i for i, n in enumerate(JOINT_NAMES) if n not in _TOES)
_N_EDGES = 4
#: Hessians of :class:`SolverSettings`.
HESSIANS = ("gauss-newton", "exact")


@dataclass(frozen=True)
class SolverSettings:
    """IPOPT settings fixed at build time (part of the cache key).

    Attributes:
        max_iter: iteration limit per window.
        tol: IPOPT's (scaled) optimality tolerance.
        constr_viol_tol: absolute constraint tolerance [m] (stance drift, penetration).
        acceptable: accept IPOPT's "Solved To Acceptable Level" as success.
        mu_init: initial barrier parameter (small values suit warm starts).
        hessian: ``"gauss-newton"`` (default, see :func:`_gauss_newton_hessian`) or
            ``"exact"`` (CasADi's exact Hessian of the Lagrangian).
        obj_scaling: IPOPT's ``obj_scaling_factor``. The cost terms are means of
            squared, normalised errors, so a variable's curvature is ~1e-4; unscaled, the
            barrier term then dominates for variables resting at a bound (a joint at its
            limit) and pushes them a radian away whenever the barrier parameter grows —
            IPOPT wandered for 40+ iterations on near-optimal starts. × 100 fixes it.
        jerk: build the pelvis and hinge jerk rows. Third differences couple every
            variable to the three frames either side, which widens the KKT matrix's band:
            with them built (even at weight 0) a stage-A iteration costs about 3× as
            much, so they are built only for solves whose jerk weights are non-zero
            (:attr:`habitsim.refine.RefineOptions.settings`).
    """

    max_iter: int = 200
    tol: float = 1e-5
    constr_viol_tol: float = 1e-5
    acceptable: bool = True
    mu_init: float = 1e-3
    hessian: str = "gauss-newton"
    obj_scaling: float = 100.0
    jerk: bool = False

    def __post_init__(self) -> None:
        if self.hessian not in HESSIANS:
            raise RefineInputError(unknown_choice("hessian", self.hessian, HESSIANS))

    def ipopt(self) -> dict:
        return {
            "print_level": 0,
            "sb": "yes",
            "max_iter": int(self.max_iter),
            "tol": float(self.tol),
            "constr_viol_tol": float(self.constr_viol_tol),
            "acceptable_tol": 1e-4,
            "acceptable_constr_viol_tol": float(self.constr_viol_tol),
            "acceptable_iter": 10 if self.acceptable else 0,
            "mu_init": float(self.mu_init),
            "mu_strategy": "adaptive",
            # the adaptive barrier's monotone safeguard re-raised μ on warm starts and
            # spent 3–6 iterations recovering; without it stage A needs 22 % fewer
            "adaptive_mu_globalization": "never-monotone-mode",
            "obj_scaling_factor": float(self.obj_scaling),
            "hessian_approximation": "exact",  # exact = use our hess_lag (see hessian)
            "linear_solver": "mumps",
            "fixed_variable_treatment": "make_parameter",
            "bound_push": 1e-8,
            "bound_frac": 1e-8,
        }


@dataclass(frozen=True)
class ModelInfo:
    """What the refinement reads from a habitsim species model (numbers, no symbols).

    Attributes:
        free_qposadr: qpos address of the pelvis free joint.
        hinge_qposadr: (n,) qpos addresses of the hinge joints, in qpos order.
        hinge_names: their joint names.
        lower, upper: (n,) joint ranges [rad] (±inf where a joint is unlimited).
        foot_geoms: (4,) geom ids of the foot spheres; foot_radius (4,) [m].
        mass: total mass [kg]; gravity: |g| [m/s²].
        inertia: (3, 3) composite inertia about the CoM in the pelvis frame at home [kg m²].
        friction: sliding friction of foot against floor (the larger, as MuJoCo combines).
    """

    free_qposadr: int
    hinge_qposadr: np.ndarray
    hinge_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    foot_geoms: np.ndarray
    foot_radius: np.ndarray
    mass: float
    gravity: float
    inertia: np.ndarray
    friction: float


def model_info(model: mujoco.MjModel) -> ModelInfo:
    """Read a habitsim species model's refinement facts.

    Raises:
        RefineError: no single free joint, a non-hinge joint, or a missing foot sphere.
    """
    free = free_joints(model)
    if len(free) != 1:
        raise RefineError(f"the model needs exactly one free joint (the pelvis), found {len(free)}")
    hinges = [j for j in range(model.njnt) if j != free[0]]
    bad = [
        model.joint(j).name
        for j in hinges
        if int(model.jnt_type[j]) != int(mujoco.mjtJoint.mjJNT_HINGE)
    ]
    if bad:
        raise RefineError(f"the refinement handles hinge joints only; not hinges: {', '.join(bad)}")
    hinges.sort(key=lambda j: int(model.jnt_qposadr[j]))
    lim = model.jnt_limited[hinges].astype(bool)
    rng = model.jnt_range[hinges]
    lower = np.where(lim, rng[:, 0], -np.inf)
    upper = np.where(lim, rng[:, 1], np.inf)
    feet = []
    for leg in FEET:
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{leg}_foot")
        if g < 0 or int(model.geom_type[g]) != int(mujoco.mjtGeom.mjGEOM_SPHERE):
            raise RefineError(f"the model has no foot sphere geom '{leg}_foot'")
        feet.append(g)
    feet_a = np.array(feet)
    ground = np.flatnonzero(model.geom_bodyid == 0)
    floor_mu = float(model.geom_friction[ground, 0].max()) if len(ground) else 1.0
    mu = max(float(model.geom_friction[feet_a, 0].max()), floor_mu)
    # composite inertia about the CoM, pelvis frame, at the home keyframe (or qpos0)
    d = mujoco.MjData(model)
    d.qpos[:] = home_qpos(model)
    mujoco.mj_kinematics(model, d)
    mujoco.mj_comPos(model, d)
    root = int(model.jnt_bodyid[free[0]])
    masses = model.body_mass[1:]
    mass = float(masses.sum())
    com = (masses[:, None] * d.xipos[1:]).sum(axis=0) / mass
    inertia = np.zeros((3, 3))
    for b in range(1, model.nbody):
        rb = d.ximat[b].reshape(3, 3)
        ib = rb @ np.diag(model.body_inertia[b]) @ rb.T
        r = d.xipos[b] - com
        inertia += ib + model.body_mass[b] * (r @ r * np.eye(3) - np.outer(r, r))
    rr = d.xmat[root].reshape(3, 3)
    inertia = rr.T @ inertia @ rr
    return ModelInfo(
        free_qposadr=int(model.jnt_qposadr[free[0]]),
        hinge_qposadr=np.array([int(model.jnt_qposadr[j]) for j in hinges]),
        hinge_names=tuple(model.joint(j).name for j in hinges),
        lower=lower,
        upper=upper,
        foot_geoms=feet_a,
        foot_radius=model.geom_size[feet_a, 0].copy(),
        mass=mass,
        gravity=float(np.linalg.norm(model.opt.gravity)),
        inertia=inertia,
        friction=mu,
    )


@dataclass
class RefinementProblem:
    """One window's NLP, built once and solved many times (see the module docstring).

    Attributes:
        n_frames: window length W.
        dynamics: stage B (centroidal dynamics) if True.
        info: the model facts.
        settings: the IPOPT settings.
        solver: ``nlpsol`` (inputs x0, p, lbx, ubx, lbg, ubg, ...); None for an
            evaluation-only problem (:func:`clip_evaluator`).
        evaluator: Function ``(x, p) → (terms (7,), g (n_g,), residual (6, W))``: the cost
            terms in :data:`COST_TERMS` order (their sum is the objective; the stage-B
            terms are 0 in stage A), the constraint rows, and the root residual wrench
            per frame as [F/(m·g); τ/(m·g·L)] (0 at the first and last frame and in
            stage A).
        frame: Function ``(x_t, qref_t) → (joints (3, 30), sole (3, 4), com (3,), rot (9,))``
            of one frame (rot: the pelvis rotation, row-major).
        nx: variables per frame; nv: variables per frame without the forces.
        build_time_s: wall time of the build [s].
        ng_blocks: constraint block name → (start, stop) rows.
    """

    n_frames: int
    dynamics: bool
    info: ModelInfo
    settings: SolverSettings
    solver: ca.Function | None
    evaluator: ca.Function
    frame: ca.Function
    nx: int
    nv: int
    build_time_s: float
    ng_blocks: dict[str, tuple[int, int]] = field(default_factory=dict)
    #: the model a cached problem was built on, kept alive (its id is part of the cache key)
    _model_ref: Any = field(default=None, repr=False, compare=False)

    # ---------------------------------------------------------------- layout helpers
    @property
    def n_hinge(self) -> int:
        return len(self.info.hinge_names)

    @property
    def n_x(self) -> int:
        """Total number of variables."""
        return self.nx * self.n_frames

    @property
    def n_g(self) -> int:
        """Total number of constraint rows."""
        return max(stop for _, stop in self.ng_blocks.values())

    def unpack(self, x: np.ndarray) -> np.ndarray:
        """(W, nx) per-frame variables of a flat solution vector."""
        return np.asarray(x, dtype=np.float64).reshape(self.n_frames, self.nx)

    def pack(self, xw: np.ndarray) -> np.ndarray:
        """Flat vector of (W, nx) per-frame variables."""
        return np.asarray(xw, dtype=np.float64).reshape(-1)

    # ---------------------------------------------------------------- values
    def parameters(
        self,
        targets: np.ndarray,
        qref: np.ndarray,
        hinge_ref: np.ndarray,
        glob: dict[str, float],
    ) -> np.ndarray:
        """The parameter vector of a window.

        Args:
            targets: (W, 30, 3) habitsim joint positions to track [m].
            qref: (W, 4) input pelvis orientations, unit quaternions wxyz.
            hinge_ref: (W, n) input hinge angles [rad].
            glob: every name of :data:`GLOBAL_PARAMS` → value.
        """
        w = self.n_frames
        missing = [k for k in GLOBAL_PARAMS if k not in glob]
        if missing:
            raise RefineInputError(f"missing global parameters {missing}")
        per = np.concatenate(
            [
                np.asarray(targets, float).reshape(w, -1),
                np.asarray(qref, float).reshape(w, 4),
                np.asarray(hinge_ref, float).reshape(w, self.n_hinge),
            ],
            axis=1,
        )
        return np.concatenate([[float(glob[k]) for k in GLOBAL_PARAMS], per.reshape(-1)])

    def bounds(
        self,
        contacts: np.ndarray,
        fixed: np.ndarray | None = None,
        fixed_values: np.ndarray | None = None,
        swing_floor: np.ndarray | None = None,
        clearance: np.ndarray | None = None,
        pins: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Variable and constraint bounds of a window.

        Args:
            contacts: (W, 4) bool feet in contact (LF, RF, LH, RH).
            fixed: (W,) bool frames whose variables are fixed to ``fixed_values``
                (frames already committed by the previous window).
            fixed_values: (W, nx) values for the fixed frames.
            swing_floor: optional (W, 4) lowest allowed sole height [m] of feet in swing
                (default 0: on or above the floor).
            clearance: optional (W, 4) lowest allowed toe height [m] of feet in swing
                (NaN or −inf: none; default none).
            pins: optional (W-1, 4) bool frame pairs whose horizontal toe displacement is
                held at 0 (default: the foot in contact in both frames; given pins are
                added to those).

        Returns:
            lbx, ubx, lbg, ubg.
        """
        w, info = self.n_frames, self.info
        c = np.asarray(contacts, dtype=bool)
        if c.shape != (w, 4):
            raise RefineInputError(f"contacts must have shape ({w}, 4), got {c.shape}")
        lbx = np.full((w, self.nx), -np.inf)
        ubx = np.full((w, self.nx), np.inf)
        lbx[:, 6 : self.nv] = info.lower
        ubx[:, 6 : self.nv] = info.upper
        lbx[:, 3:6] = -2.0  # Gibbs vector: corrections below ~127°
        ubx[:, 3:6] = 2.0
        if self.dynamics:
            nb = 4 * _N_EDGES
            lbx[:, self.nv : self.nv + nb] = 0.0
            ubx[:, self.nv : self.nv + nb] = np.repeat(np.where(c, np.inf, 0.0), _N_EDGES, axis=1)
        if fixed is not None and np.any(fixed):
            fv = (
                self.unpack(np.asarray(fixed_values).reshape(-1))
                if fixed_values is not None
                else None
            )
            if fv is None:
                raise RefineInputError("fixed frames need fixed_values")
            lbx[fixed] = fv[fixed]
            ubx[fixed] = fv[fixed]
        lbg = np.zeros(self.n_g)
        ubg = np.zeros(self.n_g)
        a, b = self.ng_blocks["sole"]
        ubg[a:b] = np.where(c, 0.0, np.inf).reshape(-1)
        if swing_floor is not None:
            lbg[a:b] = np.where(c, 0.0, np.maximum(np.asarray(swing_floor, float), 0.0)).reshape(-1)
        a, b = self.ng_blocks["ground"]
        ubg[a:b] = np.inf
        a, b = self.ng_blocks["clearance"]
        ubg[a:b] = np.inf
        if clearance is None:
            lbg[a:b] = -np.inf
        else:
            cl = np.asarray(clearance, float)
            if cl.shape != (w, 4):
                raise RefineInputError(f"clearance must have shape ({w}, 4), got {cl.shape}")
            lbg[a:b] = np.where(c | ~np.isfinite(cl), -np.inf, cl).reshape(-1)
        a, b = self.ng_blocks["pin"]
        both = c[1:] & c[:-1]  # (W-1, 4)
        if pins is not None:
            pn = np.asarray(pins, bool)
            if pn.shape != (w - 1, 4):
                raise RefineInputError(f"pins must have shape ({w - 1}, 4), got {pn.shape}")
            both = both | pn
        free = np.repeat(~both, 2, axis=1)  # x and y rows per foot
        lbg[a:b] = np.where(free, -np.inf, 0.0).reshape(-1)
        ubg[a:b] = np.where(free, np.inf, 0.0).reshape(-1)
        if fixed is not None and np.any(fixed):
            # rows of fixed frames only are constants (zero Jacobian rows make the KKT
            # matrix singular): the previous window has satisfied them, drop them
            fx = np.asarray(fixed, bool)
            per_frame = {"sole": 4, "ground": len(GROUND_JOINTS), "clearance": 4, "com": 3}
            for name, k in per_frame.items():
                if name in self.ng_blocks:
                    a, b = self.ng_blocks[name]
                    rows = np.repeat(fx, k)
                    lbg[a:b][rows], ubg[a:b][rows] = -np.inf, np.inf
            a, b = self.ng_blocks["pin"]
            rows = np.repeat(fx[1:] & fx[:-1], 8)
            lbg[a:b][rows], ubg[a:b][rows] = -np.inf, np.inf
        return lbx.reshape(-1), ubx.reshape(-1), lbg, ubg


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


def _gauss_newton_hessian(e: _Exprs) -> ca.Function:
    """IPOPT's ``hess_lag`` as Gauss-Newton: 2·λ_f·JᵀJ of the least-squares residuals
    (the objective is exactly their sum of squares), plus the exact curvature of the
    ``clearance`` rows and — stage B — of the ``com`` rows.

    Why: the exact Hessian of the FK-based tracking term is indefinite away from the
    solution, and IPOPT then refactorises the KKT matrix several times per iteration to
    correct its inertia; JᵀJ is positive semi-definite. On 100-frame artefact clips it
    halves stage A's time (8–9 iterations per window instead of 11–19) for the same
    optimum. The curvature of the sole/ground/pin rows is left out (including it stalls
    IPOPT); that of the CoM tie is kept, without it stage B sometimes needs 5× the
    iterations; so is that of the swing-clearance rows: without it, clips whose swing
    feet must be lifted (a sunk foot) ran into the Gauss-Newton iteration cap and fell
    back to the exact Hessian (41–43 iterations instead of 8–20).
    """
    x = ca.vec(e.X)
    xs = ca.SX.sym("x", x.shape[0])
    ps = ca.SX.sym("p", e.P.shape[0])
    lf = ca.SX.sym("lam_f")
    lg = ca.SX.sym("lam_g", e.g.shape[0])
    jr = ca.jacobian(ca.Function("lsq", [x, e.P], [e.lsq]).expand()(xs, ps), xs)
    hess = 2 * lf * (jr.T @ jr)
    for name in ("clearance", "com"):
        if name not in e.blocks:
            continue
        a, b = e.blocks[name]
        g_rows = ca.Function("g_" + name, [x, e.P], [e.g[a:b]]).expand()(xs, ps)
        hess = hess + ca.hessian(ca.dot(lg[a:b], g_rows), xs)[0]
    return ca.Function(
        "nlp_hess_l",
        [xs, ps, lf, lg],
        [ca.triu(hess)],
        ["x", "p", "lam_f", "lam_g"],
        ["triu_hess_gamma_x_x"],
    )


def build_refinement_problem(
    model: mujoco.MjModel,
    n_frames: int,
    dynamics: bool = False,
    settings: SolverSettings | None = None,
) -> RefinementProblem:
    """Build the NLP of an ``n_frames`` window (classic order: variables, objective,
    dynamics, path constraints, then the solver). No solve happens here.

    Args:
        model: a habitsim species model (pelvis free joint, hinges, ``<leg>_foot``
            spheres, ``<leg>_toe`` sites, bodies/sites named like the habitsim joints).
        n_frames: window length W ≥ 3.
        dynamics: add stage B's contact forces and centroidal dynamics.
        settings: IPOPT settings (default :class:`SolverSettings`).

    Raises:
        RefineInputError: ``n_frames`` < 3.
        RefineError: the model does not have the habitsim structure.
    """
    t0 = time.perf_counter()
    if int(n_frames) < 3:
        raise RefineInputError(f"a refinement window needs at least 3 frames, got {n_frames}")
    w = int(n_frames)
    settings = settings or SolverSettings()
    kin = _Kin(model)
    e = _expressions(kin, w, dynamics, jerk_rows=settings.jerk)
    x = ca.vec(e.X)
    nlp = {"x": x, "p": e.P, "f": ca.sum1(e.terms), "g": e.g}
    opts: dict[str, Any] = {
        "expand": True,
        "print_time": False,
        "error_on_fail": False,
        "ipopt": settings.ipopt(),
    }
    if settings.hessian == "gauss-newton":
        opts["hess_lag"] = _gauss_newton_hessian(e)
    solver = ca.nlpsol("refine", "ipopt", nlp, opts)
    return RefinementProblem(
        n_frames=w,
        dynamics=dynamics,
        info=kin.info,
        settings=settings,
        solver=solver,
        evaluator=_evaluator(kin, e),
        frame=kin.frame,
        nx=e.X.shape[0],
        nv=kin.nv,
        build_time_s=time.perf_counter() - t0,
        ng_blocks=e.blocks,
    )


def _evaluator(kin: _Kin, e: _Exprs) -> ca.Function:
    res = e.residual if e.residual is not None else ca.MX.zeros(6, e.X.shape[1])
    return ca.Function(
        "evaluate", [ca.vec(e.X), e.P], [e.terms, e.g, res], ["x", "p"], ["terms", "g", "residual"]
    )


def clip_evaluator(model: mujoco.MjModel, n_frames: int, dynamics: bool) -> RefinementProblem:
    """A :class:`RefinementProblem` of any length without a solver (``solver`` None):
    its ``evaluator`` gives the cost terms, constraint rows and residual of a whole clip,
    with exactly the expressions the windows are solved with (used by the report)."""
    if int(n_frames) < 3:
        raise RefineInputError(f"a refinement needs at least 3 frames, got {n_frames}")
    kin = _Kin(model)
    e = _expressions(kin, int(n_frames), dynamics)
    return RefinementProblem(
        n_frames=int(n_frames),
        dynamics=dynamics,
        info=kin.info,
        settings=SolverSettings(),
        solver=None,
        evaluator=_evaluator(kin, e),
        frame=kin.frame,
        nx=e.X.shape[0],
        nv=kin.nv,
        build_time_s=0.0,
        ng_blocks=e.blocks,
    )
