"""S2 triplet: shear test of three stacked blocks under constant pre-compression (EN 1052-3 style).

Three 220 x 81 x 102 mm expanded bricks stacked with two bed joints. As in the standard test,
the outer blocks are supported against the shear on their end faces (x = L), so that they carry
the shear without bending; the pre-compression acts through a rigid platen on the top block (the
bottom block rests on a roller base), and the middle block is pushed along x as a rigid body.
Output: shear stress (horizontal force / two joint areas) against the slip of the middle block.
Reference (MODEL.md section 2, paper Fig. 10): peak c + tan(phi) sigma, residual mu sigma.

Run: ``python cases/triplet.py [key=value ...]`` (``sigma`` in MPa, one run per value of
``sigmas``); the default test suite runs one coarse pre-compression in a few seconds.
"""
import sys

import numpy as np

from dr_masonry import (Displacement, Force, JointLaw, Model, PlasticDamage, Simulation,
                        Stage)
from dr_masonry.cli import run_script
from dr_masonry.geometry import plane_nodes
from dr_masonry.params import ParameterError, output_path
from dr_masonry.scene import finish, scene_params, solver_options
from dr_masonry.units import MPa, mm

PARAMS = dict(
    sigmas=(0.2, 0.6, 1.0),  # pre-compressions, MPa (> 0; comma separated on the command line)
    slip=1.5 * mm,          # final slip of the middle block, m
    increments=150,         # shear increments (quadratic spacing: fine near the peak)
    nx=4, ny=2, nz=1,       # hexahedra per block (length, thickness, height)
    tol=1e-4,
    damping="viscous",
    out="results/triplet",
)
L, H, T = 0.22, 0.081, 0.102
AREA = L * T


def build(params, sigma):
    """Model and stages for pre-compression ``sigma`` (Pa, positive = compression)."""
    model = Model()
    model.set_joint_law(JointLaw.reference())
    brick = PlasticDamage.reference()
    div = (params["nx"], params["ny"], params["nz"])
    b = [model.add_box((0, 0, k * H), (L, T, H), brick, div) for k in range(3)]
    sim = Simulation(model, solver_options(params),
                     output=params.get("h5"), config=dict(params, sigma=sigma))
    base = plane_nodes(model, 2, 0.0, blocks=[b[0]])
    sim.fix(base, "z")
    sim.fix(base[np.isclose(model.nodes[base, 0], L)], "y")
    platen = plane_nodes(model, 2, 3 * H, blocks=[b[2]])
    ends = plane_nodes(model, 0, L, blocks=[b[0], b[2]])
    sim.fix(np.setdiff1d(ends, platen), "x")
    top = sim.rigid_point("top", nodes=platen)
    push = sim.rigid_point("push", blocks=[b[1]])
    holds = [Displacement(target=top, dof=d, to=0.0) for d in ("y", "rx", "ry", "rz")]
    holds += [Displacement(target=push, dof=d, to=0.0) for d in ("x", "y", "rx", "ry", "rz")]
    pre = Stage("precompression", 5, holds + [Force(target=top, dof="z", to=-sigma * AREA)])
    t = np.arange(1, params["increments"] + 1) / params["increments"]
    shear = Stage("shear", params["increments"],
                  [Displacement(target=push, dof="x", path=params["slip"] * t ** 2, name="slip")])
    return sim, [pre, shear]


def run(params, sigma):
    """Run one pre-compression; returns (simulation, slip (m), shear stress (Pa))."""
    sim, stages = build(params, sigma)
    hist = sim.run(stages)
    shear = np.asarray(hist["increment"]) > 5
    return sim, hist["push.ux"][shear], hist["push.fx"][shear] / (2 * AREA)


def check(params):
    """Raise :class:`ParameterError` naming the first parameter the scene cannot run with."""
    output_path(params)
    if not params["sigmas"] or not all(np.isfinite(v) and v > 0 for v in params["sigmas"]):
        raise ParameterError(f"parameter sigmas={params['sigmas']!r}: at least one pre-compression,"
                             " each finite and > 0 MPa")
    if not (np.isfinite(params["slip"]) and params["slip"] > 0):
        raise ParameterError(f"parameter slip={params['slip']!r}: must be > 0 m")
    for key in ("increments", "nx", "ny", "nz"):
        if params[key] < 1:
            raise ParameterError(f"parameter {key}={params[key]!r}: must be >= 1")


def main(argv=None):
    params = scene_params(PARAMS, None, sys.argv[1:] if argv is None else argv, __doc__,
                          "triplet")
    law = JointLaw.reference()
    check(params)
    for s in [float(v) * MPa for v in params["sigmas"]]:
        out = f"{params['out']}_{s / MPa:.1f}MPa"
        sim, slip, tau = run(dict(params, h5=out + ".h5"), s)
        peak, res = law.c + law.tan_phi * s, law.mu * s
        finish(sim, out, x=slip / mm, y=tau / MPa, xlabel="slip (mm)", ylabel="shear stress (MPa)",
               title=f"S2 triplet, pre-compression {s / MPa:.1f} MPa",
               reference=([0, slip[-1] / mm], [peak / MPa, peak / MPa], "c + tan(phi) sigma"))
        print(f"sigma {s / MPa:.1f} MPa: peak {tau.max() / MPa:.4f} MPa (closed form "
              f"{peak / MPa:.4f}), final {tau[-1] / MPa:.4f} MPa (mu sigma {res / MPa:.4f})")


if __name__ == "__main__":
    sys.exit(run_script(main))
