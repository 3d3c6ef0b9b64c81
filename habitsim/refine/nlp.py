"""The built NLP of one window (:class:`RefinementProblem`): its layout, and a
window's parameter values and variable and constraint bounds."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from .errors import RefineInputError
from .layout import _N_EDGES, GLOBAL_PARAMS, GROUND_JOINTS
from .model_facts import ModelInfo
from .settings import SolverSettings


@dataclass
class RefinementProblem:
    """One window's NLP, built once and solved many times (see :mod:`habitsim.refine.problem`).

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
