"""Figures and numbers of docs/validation.md, "Arches and dry stone".

Usage: ``python docs/make_arch_figures.py``: runs the arch scene (n = 12, R = 1 m) at 0.97 and
1.03 times the LP's minimum thickness under self-weight and at t/R = 0.15 and 0.2 on the tilting
table, and the dry-wall scene (a block that overturns, one that slides, a stack of three, the
block on a wider coarse base); writes the mechanisms into docs/arch/ and prints the table of the
LP's (tests/limit_analysis.py) or the closed form's numbers against this code's, with run times.
About 15 s on 2 cores.
"""
import os
import sys
import tempfile
import time

from matplotlib.figure import Figure

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

import limit_analysis as la  # noqa: E402
from dr_masonry.cases import arch, dry_wall  # noqa: E402
from dr_masonry.collapse import draw_mechanism  # noqa: E402

OUT = os.path.join(HERE, "arch")
N = 12


def faces_text(idx, faces):
    return " ".join(f"{i}{'e' if f > 0 else 'i'}" for i, f in zip(idx, faces))


def arch_rows(tmp):
    rows = []
    t_min = la.minimum_thickness(1.0, N)
    cases = [("gravity", 1.03 * t_min.value, t_min, "t = 1.03 t_min"),
             ("gravity", 0.97 * t_min.value, t_min, "t = 0.97 t_min"),
             ("tilt", 0.15, la.collapse_factor(1.0, 0.15, N), "t/R = 0.15"),
             ("tilt", 0.2, la.collapse_factor(1.0, 0.2, N), "t/R = 0.2")]
    for load, t, lp, label in cases:
        params = dict(arch.PARAMS, thickness=t, load=load, out=os.path.join(tmp, "arch"))
        t0 = time.perf_counter()
        sim, a, res, found = arch.run(params)
        wall = time.perf_counter() - t0
        if res.collapsed:
            name = f"arch_{load}_{t:.4f}".replace(".", "_") + ".png"
            arch.mechanism_figure(sim.model, a, sim.dyn.U, res.motion, found[0], found[1],
                                  os.path.join(OUT, name),
                                  f"{label}: " + ("collapse under self-weight" if load == "gravity"
                                                  else f"lam = {res.factor:.4f}"),
                                  marks=(lp.hinges, lp.faces, "hinges (LP)"))
        sim.close()
        ref = f"t_min/R = {lp.value:.4f}" if load == "gravity" else f"{lp.value:.4f}"
        got = ("stands" if not res.collapsed else "collapses" if load == "gravity" else
               f"{res.factor:.4f} - {res.failed:.4f}")
        rows.append((f"arch, {load}, {label} (t/R = {t:.4f})", ref, got,
                     faces_text(lp.hinges, lp.faces), faces_text(*found[:2]) if found else "-",
                     f"{wall:.1f} s"))
    return rows


def wall_rows(tmp):
    rows = []
    cases = [(dict(width=0.2, height=0.4, mu=0.8), "block b/h = 0.5, mu = 0.8"),
             (dict(width=0.4, height=0.2, mu=0.4), "block b/h = 2, mu = 0.4"),
             (dict(width=0.3, height=0.2, courses=3, mu=0.8), "3 blocks, b/H = 0.5, mu = 0.8"),
             (dict(width=0.2, height=0.4, mu=0.8, base_overhang=0.1, base_nx=3),
              "block b/h = 0.5 on a 0.4 m base of 3 elements")]
    fig = Figure(figsize=(8, 3.2))
    axes = fig.subplots(1, len(cases))
    for ax, (kw, label) in zip(axes, cases):
        params = dict(dry_wall.PARAMS, out=os.path.join(tmp, "wall"), **kw)
        t0 = time.perf_counter()
        sim, blocks, base, res, how = dry_wall.run(params)
        wall = time.perf_counter() - t0
        H = params["courses"] * params["height"]
        draw_mechanism(ax, sim.model, [base] + blocks, sim.dyn.U, res.motion,
                       0.1 * H / abs(res.motion).max())
        ax.set_aspect("equal")
        ax.set_title(f"{how} at {res.factor:.3f}", fontsize=9)
        ax.tick_params(labelsize=7)
        sim.close()
        ref, mode = dry_wall.closed_form(params)
        rows.append((f"dry wall, {label}", f"{ref:.4f} ({mode})",
                     f"{res.factor:.4f} - {res.failed:.4f} ({how})", "", "", f"{wall:.1f} s"))
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "dry_wall_mechanisms.png"), dpi=90)
    return rows


def main():
    os.makedirs(OUT, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        rows = arch_rows(tmp) + wall_rows(tmp)
    print("| case | reference | this code (last converged - no equilibrium) | hinges, reference "
          "| hinges, this code | run time |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")


if __name__ == "__main__":
    main()
