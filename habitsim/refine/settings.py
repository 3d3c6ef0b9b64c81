"""The IPOPT settings of a refinement problem, fixed at build time
(:class:`SolverSettings`)."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import unknown_choice
from .errors import RefineInputError

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
        hessian: ``"gauss-newton"`` (default, see
            :func:`habitsim.refine.problem._gauss_newton_hessian`) or
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
