"""S4 slender wall: in-plane cyclic shear-compression of a 1.10 x 2.75 m wall (cf. paper COMP-2).

A 1.10 m long (5 bricks) x 2.75 m high (34 courses) x 0.102 m running-bond wall on a fixed
foundation block, with a stiff steel loading beam on top; same set-up, joints and output as the
S5 squat wall (``cases/squat_wall.py``, whose builder this scene reuses). Vertical
pre-compression 0.52 MPa kept constant; ``bc=double_clamped`` (beam rotation held, the reference
run) or ``bc=cantilever`` (beam rotation free, like the paper's COMP-2). Horizontal displacement
of the beam: monotonic to 2.5 % drift, or cyclic 0.05, 0.1, 0.2, 0.3, 0.5, 0.75, 1.0, 1.5, 2.0 %
drift, two cycles each (:data:`dr_masonry.protocols.S4`).

Expected behaviour (paper Figs. 13-14): a flexural (rocking) response: the bed joints open at
the base and, double clamped, also at the top; peak base shear close to the rocking capacity
(N L / 2 + tension) / H (cantilever) or twice that (double clamped), almost non-dissipative
rocking loops at small drifts and toe crushing at large ones.

Run: ``python cases/slender_wall.py [key=value ...]`` (or ``dr-masonry run slender_wall``); the
monotonic run on the default fine mesh (4 x 1 x 2 hexahedra per brick) took 10 min 54 s on one
thread beside two other runs (2026-12-07, version 0.2.0), ``mesh=coarse`` about 10 minutes.
``fast=true`` runs a 0.88 x 0.81 m coarse wall in a few increments (test suite). The full
protocols' commands and measured run times: README, "Full protocols".
"""
import sys

from dr_masonry.cases import squat_wall
from dr_masonry.cli import run_script
from dr_masonry.protocols import S4
from dr_masonry.units import MPa, mm

#: the fine mesh by default: on the coarse one (one hexahedron per brick) the double-clamped peak
#: is 10 % lower and the cantilever's 4 % above the finite-strength rocking bound
#: (docs/validation.md, "S4: what sets the peak")
PARAMS = dict(squat_wall.PARAMS, length=1.10, height=2.75, sigma=0.52 * MPa, bc="double_clamped",
              drift=S4.monotonic, increments=40, step=1.0 * mm, mesh="fine",
              out="results/slender_wall")
FAST = squat_wall.FAST
CURVE = squat_wall.CURVE
VIEWS = squat_wall.VIEWS


def build(params):
    """``(sim, stages, rig)``: the simulation, its stages and the :class:`squat_wall.Rig` (see
    :func:`squat_wall.build`)."""
    return squat_wall.build(params, S4)


def run(params):
    """Run; returns (simulation, history, push-stage mask, :class:`squat_wall.Rig`)."""
    return squat_wall.run(params, S4)


def main(argv=None):
    squat_wall.main(argv, __doc__, PARAMS, S4, "S4 slender wall", "slender_wall")


if __name__ == "__main__":
    sys.exit(run_script(main))
