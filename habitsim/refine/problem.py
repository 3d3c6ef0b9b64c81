"""Build the refinement NLP of one window — apart from solving it.

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

Parts: names and sizes in :mod:`~habitsim.refine.layout`, the IPOPT settings in
:mod:`~habitsim.refine.settings`, the model's facts in :mod:`~habitsim.refine.model_facts`,
the symbolic NLP in :mod:`~habitsim.refine.expressions`, and the built problem with its
parameter values and bounds in :mod:`~habitsim.refine.nlp`; this module builds it.
"""

from __future__ import annotations

import time
from typing import Any

import casadi as ca
import mujoco

from .errors import RefineInputError
from .expressions import _expressions, _Exprs, _Kin
from .layout import COST_TERMS, FEET, GLOBAL_PARAMS, GROUND_JOINTS, STAGE_A_TERMS
from .layout import LEG_PREFIXES as LEG_PREFIXES
from .model_facts import ModelInfo, model_info
from .nlp import RefinementProblem
from .settings import HESSIANS as HESSIANS
from .settings import SolverSettings

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
