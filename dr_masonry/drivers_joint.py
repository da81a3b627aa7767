"""Single-point driver of the joint law: prescribed gap histories through the solver's kernel."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kernels import joint_law as jk
from .materials.joint import JointLaw, JointLawError


@dataclass(frozen=True)
class JointResponse:
    """Response of one contact point along a gap path (n points).

    Attributes
    ----------
    gap : (n, 3) float64, m
        the prescribed [u, d1, d2].
    traction : (n, 3) float64, Pa
        [sigma, tau1, tau2].
    damage : (n,) float64
        D after each point.
    dissipated : (n,) float64, J/m^2
        cumulative dissipated energy.
    state : (n, NJS) float64
        committed history after each point (indices ``JS_*`` of ``dr_masonry.kernels.joint_law``).
    """
    gap: np.ndarray
    traction: np.ndarray
    damage: np.ndarray
    dissipated: np.ndarray
    state: np.ndarray


def drive_joint(law, path, state=None):
    """Drive one contact point of ``law`` along ``path``, committing after every point.

    Parameters
    ----------
    law : JointLaw
    path : (n, 3) array_like, m
        total gaps [u, d1, d2] (u > 0 opening); the path starts at gap 0.
    state : (NJS,) array_like or None
        history at the start (e.g. the last row of an earlier response's ``state``): finite,
        damage in [0, 1], largest opening and slip >= 0; None: the virgin state
        ``law.initial_state()``.

    Returns
    -------
    JointResponse
    """
    if not isinstance(law, JointLaw):
        raise JointLawError(f"drive_joint: law must be a JointLaw, got {law!r}")
    path = np.asarray(path, dtype=np.float64)
    if path.ndim != 2 or path.shape[1] != 3:
        raise JointLawError(f"drive_joint: path must have shape (n, 3) [u, d1, d2], got {path.shape}")
    bad = ~np.all(np.isfinite(path), axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise JointLawError(f"drive_joint: path point {i} is not finite: {path[i].tolist()}")
    try:
        s0 = law.initial_state() if state is None else np.array(state, dtype=np.float64)
    except (TypeError, ValueError):
        s0 = None
    if s0 is None or s0.shape != (jk.NJS,) or not np.all(np.isfinite(s0)):
        raise JointLawError(f"drive_joint: state must be {jk.NJS} finite numbers, got {state!r}")
    for i, name, hi in ((jk.JS_D, "damage D", 1.0), (jk.JS_UMAX, "largest opening u_max", None),
                        (jk.JS_DMAX, "largest slip delta_max", None)):
        if not (s0[i] >= 0.0 and (hi is None or s0[i] <= hi)):
            raise JointLawError(f"drive_joint: state[{i}] ({name}) = {s0[i]} must be "
                                + ("in [0, 1]" if hi else ">= 0"))
    path = np.ascontiguousarray(path)
    t = np.empty((path.shape[0], 3))
    states = np.empty((path.shape[0], jk.NJS))
    jk.joint_path(law.params_array(), path, s0, t, states)
    return JointResponse(path, t, states[:, jk.JS_D].copy(), states[:, jk.JS_DISS].copy(), states)
