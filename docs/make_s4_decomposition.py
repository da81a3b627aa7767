"""What sets the S4 slender wall's peak: docs/validation.md, "S4: what sets the peak".

Usage: ``python docs/make_s4_decomposition.py [workers=2] [out=results/s4_decomposition]
[only=double_clamped|cantilever]``: runs the S4 scene (``cases/slender_wall.py``, monotonic) on
the coarse mesh once per model ingredient changed alone, and on the fine mesh (the scene's
default), for both boundary conditions, through
:func:`dr_masonry.study.run_study` (``workers`` processes of one thread), and prints the table of
peaks against the reference run and against two limit-analysis bounds computed here, not by the
solver:

* the rigid no-tension rocking capacity: the pier rotates about its toes, the vertical force at
  each end acts at the corner: V = (N_top + N_base) L / (2 H) double clamped,
  N_base L / (2 H) cantilever;
* the same with a finite compressive strength f_c (S3, the wallet's 6.8 MPa): the force at each
  end acts at the centre of a stress block a = N / (f_c t) long, V = sum N (L - a) / (2 H).

On the coarse mesh the double-clamped push is cut after 12 of its 40 graded increments (the same
targets up to 0.41 % drift, past its coarse-mesh peak at 0.18 %); the fine mesh peaks later
(0.52 %) and runs whole, like the cantilever. About 35 min on 2 cores (2026-12-07): the fine
double-clamped run 13 min, the coarse runs with kc_factor 30 and 100 4-14 min, the others 1-2
min.
"""
import os
import sys

from dr_masonry.cases import slender_wall
from dr_masonry.params import parse_overrides
from dr_masonry.results import open_result
from dr_masonry.study import run_study
from dr_masonry.units import MPa, kN

DEFAULTS = dict(workers=2, out="results/s4_decomposition", only="")
#: the ingredients, each changed alone: label -> overrides of the reference run
INGREDIENTS = {
    "reference": {},
    "kc_factor 30": dict(kc_factor=30.0),
    "kc_factor 100": dict(kc_factor=100.0),
    "fine mesh (the scene's default)": dict(mesh="fine"),
    "elastic bricks": dict(bricks="elastic"),
    "beam held vertically": dict(beam_z="held"),
    "beam rotations rx, rz free": dict(beam_out_of_plane="free"),
    "joint ft and u_k x 2 (PAR_A)": dict(variant="PAR_A"),
}
#: per boundary condition: the push (the double-clamped one cut past its peak, same targets)
PUSH = {"double_clamped": dict(increments=12, drift=2.5 * (12 / 40) ** 1.5),
        "cantilever": dict()}
#: masonry compressive strength, Pa (S3 wallet, docs/validation.md)
FC = 6.8 * MPa


def bounds(bc):
    """(rigid, finite-f_c) base shear bounds (N) of the S4 wall with boundary condition ``bc``,
    from its geometry and loads as the scene builds them."""
    _, _, rig = slender_wall.build(dict(slender_wall.PARAMS, bc=bc, h5=None))
    L, t, H = rig.wall.length, rig.wall.thickness, rig.wall.height
    ends = [rig.n_top + rig.weight_wall] + ([rig.n_top] if bc == "double_clamped" else [])
    rigid = sum(N * L for N in ends) / (2 * H)
    finite = sum(N * (L - N / (FC * t)) for N in ends) / (2 * H)
    return rigid, finite


def vertical_load(h5):
    """(min, max) of the beam's vertical force (N) and its largest uplift (m) over the push."""
    h = open_result(h5).history
    push = h["increment"] > slender_wall.PARAMS["pre_increments"]
    return -h["beam.fz"][push].max(), -h["beam.fz"][push].min(), h["beam.uz"][push].max()


def main(argv=None):
    params = parse_overrides(DEFAULTS, sys.argv[1:] if argv is None else argv, __doc__)
    bcs = [params["only"]] if params["only"] else list(PUSH)
    # the slow (fine-mesh) variants first, so that the workers finish together
    variants = sorted(((f"{bc} {label}", dict(dict(bc=bc, maps="", report=False, mesh="coarse",
                                                    **PUSH[bc]), **kw))
                       for bc in bcs for label, kw in INGREDIENTS.items()),
                      key=lambda v: v[1]["mesh"] != "fine")
    for _, kw in variants:      # the fine mesh's push whole
        if kw["mesh"] == "fine":
            kw.update(increments=slender_wall.PARAMS["increments"], drift=slender_wall.PARAMS["drift"])
    res = run_study("slender_wall", variants, out=params["out"], n_workers=params["workers"])
    rows = {r["label"]: r for r in res.rows}
    for bc in bcs:
        rigid, finite = bounds(bc)
        ref = rows[f"{bc} reference"]      # the coarse mesh
        print(f"\n{bc}: rigid no-tension bound {rigid / kN:.2f} kN, with f_c = "
              f"{FC / MPa:.1f} MPa {finite / kN:.2f} kN")
        print("| ingredient changed | peak (kN) | vs reference | vs rigid bound | at (mm) | "
              "N on the beam (kN) | wall time |")
        print("|---|---|---|---|---|---|---|")
        for label in INGREDIENTS:
            r = rows[f"{bc} {label}"]
            if r["status"] != "ok":
                print(f"| {label} | failed: {r['error'].splitlines()[-1]} | | | | | |")
                continue
            lo, hi, _ = vertical_load(r["h5"])
            n = f"{lo / kN:.1f}" if hi - lo < 0.05 * kN else f"{lo / kN:.1f}-{hi / kN:.1f}"
            print(f"| {label} | {r['peak']:.2f} | {100 * (r['peak'] / ref['peak'] - 1):+.1f} % | "
                  f"{100 * (r['peak'] * kN / rigid - 1):+.1f} % | {r['x_at_peak']:.2f} | {n} | "
                  f"{r['wall_s'] / 60:.1f} min |")
    print(f"\n(results in {os.path.abspath(params['out'])})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
