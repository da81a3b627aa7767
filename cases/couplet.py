"""S1 couplet: direct tension of two stacked blocks through their mortar joint.

Two 220 x 81 x 102 mm expanded bricks, the bottom one clamped at its base, the top one pulled up
by a rigid platen (a reference point tied to its top face, all other DOFs held). The blocks stay
elastic (1.5 MPa tensile strength >> ft), so the response is the joint law integrated over the
joint. Reference (closed form, MODEL.md section 2): peak stress ft = 0.12 MPa at u0 = ft / Knn,
softening ft (1 - g_t(u)) to zero at u_k = 1 mm; dissipated energy = integral of the envelope.

Run: ``python cases/couplet.py [key=value ...]`` or ``dr-masonry run couplet``.
Fast (the default test suite runs it with a coarse mesh): about 10 s after compilation.
"""
import sys

import numpy as np

from dr_masonry import Displacement, JointLaw, Model, PlasticDamage, Simulation, Stage
from dr_masonry.cases.joint import tension_envelope
from dr_masonry.cli import run_script
from dr_masonry.params import ParameterError
from dr_masonry.scene import finish, scene_params, solver_options
from dr_masonry.units import MPa, mm

PARAMS = dict(
    u_max=1.2 * mm,        # final opening of the platen, m
    increments=120,        # load increments to u_max (energy balance error ~ 1/n^2)
    nx=4, ny=2, nz=1,      # hexahedra per block (length, thickness, height)
    tol=1e-4,              # relative residual tolerance
    damping="viscous",
    out="results/couplet",
)
L, H, T = 0.22, 0.081, 0.102
#: the response curve (dr_masonry.study): joint tensile stress (MPa) against opening (mm)
CURVE = dict(x="platen.uz", y="platen.fz", stage=None, xscale=1 / mm,
             yscale=1 / (L * T * MPa), xlabel="opening (mm)", ylabel="tensile stress (MPa)")


def build(params):
    """Model and stages of the couplet test."""
    model = Model()
    model.set_joint_law(JointLaw.reference())
    brick = PlasticDamage.reference()
    div = (params["nx"], params["ny"], params["nz"])
    bottom = model.add_box((0, 0, 0), (L, T, H), brick, div)
    top = model.add_box((0, 0, H), (L, T, H), brick, div)
    sim = Simulation(model, solver_options(params), output=params.get("h5"), config=params)
    base = model.block_nodes(bottom)
    sim.fix(base[np.isclose(model.nodes[base, 2], 0.0)])
    platen = model.block_nodes(top)
    platen = platen[np.isclose(model.nodes[platen, 2], 2 * H)]
    rp = sim.rigid_point("platen", nodes=platen)
    holds = [Displacement(target=rp, dof=d, to=0.0) for d in ("x", "y", "rx", "ry", "rz")]
    # cubic spacing: the peak (a few micrometres) is resolved as well as the long softening tail
    if not (np.isfinite(params["u_max"]) and params["u_max"] > 0):
        raise ParameterError(f"parameter u_max={params['u_max']!r}: must be an opening > 0 m")
    t = np.arange(1, params["increments"] + 1) / params["increments"]
    pull = Displacement(target=rp, dof="z", path=params["u_max"] * t ** 3, name="pull")
    stages = [Stage("tension", params["increments"], holds + [pull])]
    return sim, stages


def run(params):
    """Run the scene; returns (simulation, history)."""
    sim, stages = build(params)
    hist = sim.run(stages)
    return sim, hist


def main(argv=None):
    params = scene_params(PARAMS, None, sys.argv[1:] if argv is None else argv, __doc__,
                          "couplet")
    sim, hist = run(params)
    u = hist["platen.uz"]
    s = hist["platen.fz"] / (L * T)
    finish(sim, params["out"], x=u / mm, y=s / MPa, xlabel="opening (mm)",
           ylabel="tensile stress (MPa)", title="S1 couplet",
           reference=(u / mm, tension_envelope(JointLaw.reference(), u) / MPa, "closed form"))
    print(f"peak stress {s.max() / MPa:.4f} MPa (ft = 0.12 MPa)")
    return hist


if __name__ == "__main__":
    sys.exit(run_script(main))
