"""S0 joint: one contact point of the joint law, driven by prescribed gap histories.

Scene: the cohesive-frictional law of MODEL.md section 2 with the calibrated parameters of the paper
(Table 2), driven directly (no blocks, no solver) through ``drive_joint``:

* monotonic opening to 1.2 u_k, against the closed-form envelope ft (1 - g_t(u)) and its fracture
  energy;
* monotonic direct shear at sigma = 0, -0.2, -0.6, -1.0 MPa (the normal stress is held by the
  compression penalty: u = sigma / kc_pen), against the envelope fs (1 - g_s) + g_s mu <-sigma>
  (peak c + tan_phi |sigma|, residual mu |sigma|);
* the cyclic shear loops of the paper's Fig. 4 at sigma = ``cyclic_sigma``: a softening-stage
  loop (amplitude ``soft_amp``) and a friction-stage loop (amplitude ``fric_amp`` > delta_k);
* a cyclic opening path (Fig. 3): secant unloading to the origin, penalty in compression.

Reference: the closed forms of MODEL.md (printed as relative errors). Run time: about a second
(plus Numba compilation on the first run).

Usage: ``python cases/joint.py [key=value ...]``, e.g. ``shear_damage=paper out=results/joint``.
Writes joint_*.png and joint_*.csv to ``out``.
"""
import os
import sys

import numpy as np

from dr_masonry.cli import run_script
from dr_masonry.drivers_joint import drive_joint
from dr_masonry.materials.joint import JointLaw
from dr_masonry.params import ParameterError, output_path, parse_overrides
from dr_masonry.results import make_folder
from dr_masonry.units import MPa, mm

PARAMS = dict(
    out="results/joint",
    shear_damage="calibrated",  # or "paper" (eq (7) literally)
    steps=2000,                 # points per monotonic leg
    sigmas_MPa=(0.0, -0.2, -0.6, -1.0),   # normal stresses of the shear paths
    cyclic_sigma_MPa=-0.6,
    soft_amp_mm=0.3,
    fric_amp_mm=1.5,
)


def _leg(a, b, n):
    """n points from a (excluded) to b (included), gaps (n, 3)."""
    s = np.linspace(0.0, 1.0, n + 1)[1:, None]
    return np.asarray(a, float) + s * (np.asarray(b, float) - np.asarray(a, float))


def _polyline(verts, n):
    return np.vstack([_leg(a, b, n) for a, b in zip(verts[:-1], verts[1:])])


def build(params):
    """The law and the gap paths (dict name -> (n, 3) m) of the scene."""
    law = JointLaw.reference(shear_damage=params["shear_damage"])
    n = int(params["steps"])
    # monotonic paths pass exactly through the peak and the end of softening
    u = np.union1d(np.linspace(0.0, 1.2 * law.u_k, n + 1), [law.ft / law.knn, law.u_k])[1:]
    paths = {"tension": np.column_stack([u, 0 * u, 0 * u])}
    for s in (float(v) * MPa for v in params["sigmas_MPa"]):
        d = np.union1d(np.linspace(0.0, 2 * law.delta_k, n + 1), [law.fs(s) / law.kss, law.delta_k])
        paths[f"shear {s / MPa:g} MPa"] = np.column_stack([np.full(d.size, s / law.kc_pen), d, 0 * d])
    uc = float(params["cyclic_sigma_MPa"]) * MPa / law.kc_pen
    for name, amp in (("softening loop", params["soft_amp_mm"]), ("friction loop", params["fric_amp_mm"])):
        a = float(amp) * mm
        paths[name] = _polyline([(0, 0, 0), (uc, 0, 0), (uc, a, 0), (uc, -a, 0), (uc, 2 * a, 0)], n)
    paths["cyclic opening"] = _polyline(
        [(0, 0, 0), (0.1 * mm, 0, 0), (-0.5e-6, 0, 0), (0.3 * mm, 0, 0), (0, 0, 0), (0.6 * mm, 0, 0),
         (-0.5e-6, 0, 0), (1.2 * mm, 0, 0)], n)
    return law, paths


def tension_envelope(law, u):
    """Closed-form joint stress (Pa) of ``law`` at monotonic opening ``u`` (array, m): knn u up
    to the peak ft at u0 = ft / knn, then ft (1 - g_t(u)), zero from u_k on (MODEL.md section 2)."""
    u0 = law.ft / law.knn
    gt = np.clip((1 - np.exp(-law.zeta * (u - u0) / (law.u_k - u0))) / -np.expm1(-law.zeta), 0, 1)
    return np.where(u <= u0, law.knn * u, law.ft * (1 - gt))


def _envelopes(law, sigma, x):
    """Closed-form monotonic envelopes: tension at opening x, shear at slip x and stress sigma."""
    ten = tension_envelope(law, x)
    fs, mup = law.fs(sigma), law.mu * max(-sigma, 0.0)
    d0 = fs / law.kss
    gs = np.clip((1 - np.exp(-law.xi * (x - d0) / (law.delta_k - d0))) / -np.expm1(-law.xi), 0, 1)
    sh = np.where(x <= d0, law.kss * x, fs * (1 - gs) + gs * mup)
    return ten, sh


def _csv(path, header, cols):
    np.savetxt(path, np.column_stack(cols), fmt="%.10g", delimiter=",", header=header, comments="")


def run(params, out):
    """Drive every path, write PNG and CSV files to ``out``; returns a dict of key numbers."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    make_folder(out)
    law, paths = build(params)
    res = {k: drive_joint(law, p) for k, p in paths.items()}
    summary = {}

    # monotonic opening
    u = paths["tension"][:, 0]
    r = res["tension"]
    env, _ = _envelopes(law, 0.0, u)
    summary["tension_peak"] = r.traction[:, 0].max()
    summary["tension_energy"] = r.dissipated[-1]
    _csv(os.path.join(out, "joint_tension.csv"), "u_m,sigma_Pa,envelope_Pa,damage,dissipated_J_m2",
         [u, r.traction[:, 0], env, r.damage, r.dissipated])
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(u / mm, r.traction[:, 0] / MPa, label="kernel")
    ax.plot(u / mm, env / MPa, "--", label="ft (1 - g_t)")
    ax.set(xlabel="opening u [mm]", ylabel="sigma [MPa]", title="S0 monotonic opening")
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "joint_tension.png"), dpi=120)
    plt.close(fig)

    # monotonic direct shear
    fig, ax = plt.subplots(figsize=(5, 3.5))
    rows = []
    for k in (k for k in paths if k.startswith("shear")):
        p, r = paths[k], res[k]
        sigma = r.traction[-1, 0]
        _, env = _envelopes(law, sigma, p[:, 1])
        rows.append(np.column_stack([np.full(len(p), sigma), p[:, 1], r.traction[:, 1], env, r.damage]))
        summary[f"{k} peak/fs"] = r.traction[:, 1].max() / law.fs(sigma)
        line, = ax.plot(p[:, 1] / mm, r.traction[:, 1] / MPa, label=f"sigma = {sigma / MPa:.1f} MPa")
        ax.plot(p[:, 1] / mm, env / MPa, "--", color=line.get_color(), lw=0.8)
    _csv(os.path.join(out, "joint_shear.csv"), "sigma_Pa,slip_m,tau_Pa,envelope_Pa,damage", [np.vstack(rows)])
    ax.set(xlabel="slip d [mm]", ylabel="tau [MPa]", title=f"S0 direct shear ({law.shear_damage})")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "joint_shear.png"), dpi=120)
    plt.close(fig)

    # cyclic paths (Fig. 4 and Fig. 3)
    fig, axs = plt.subplots(1, 2, figsize=(9, 3.5))
    rows = []
    for k in ("softening loop", "friction loop"):
        p, r = paths[k], res[k]
        rows.append(np.column_stack([np.full(len(p), k == "friction loop"), p[:, 1], r.traction[:, 1],
                                     r.damage, r.dissipated]))
        axs[0].plot(p[:, 1] / mm, r.traction[:, 1] / MPa, label=k)
    _csv(os.path.join(out, "joint_cyclic_shear.csv"), "friction_stage,slip_m,tau_Pa,damage,dissipated_J_m2",
         [np.vstack(rows)])
    axs[0].set(xlabel="slip d [mm]", ylabel="tau [MPa]",
               title=f"Fig. 4 loops, sigma = {params['cyclic_sigma_MPa']} MPa")
    axs[0].legend(fontsize=7)
    p, r = paths["cyclic opening"], res["cyclic opening"]
    _csv(os.path.join(out, "joint_cyclic_opening.csv"), "u_m,sigma_Pa,damage,dissipated_J_m2",
         [p[:, 0], r.traction[:, 0], r.damage, r.dissipated])
    axs[1].plot(p[:, 0] / mm, r.traction[:, 0] / MPa)
    axs[1].set(xlabel="opening u [mm]", ylabel="sigma [MPa]", title="Fig. 3 cyclic opening",
               ylim=(-0.05, 1.1 * law.ft / MPa))
    fig.tight_layout()
    fig.savefig(os.path.join(out, "joint_cyclic.png"), dpi=120)
    plt.close(fig)
    return summary


def check(params):
    """Raise :class:`ParameterError` naming the first parameter with a value the scene cannot
    drive (``steps`` an integer >= 2, amplitudes > 0, stresses finite and <= 0)."""
    output_path(params)
    if params["shear_damage"] not in ("calibrated", "paper"):
        raise ParameterError(f"parameter shear_damage={params['shear_damage']!r}: valid values "
                             "are 'calibrated', 'paper'")
    if params["steps"] < 2:
        raise ParameterError(f"parameter steps={params['steps']!r}: must be >= 2 points per leg")
    for key in ("soft_amp_mm", "fric_amp_mm"):
        if not (np.isfinite(params[key]) and params[key] > 0):
            raise ParameterError(f"parameter {key}={params[key]!r}: must be a slip > 0 mm")
    sig = (*params["sigmas_MPa"], params["cyclic_sigma_MPa"])
    if not params["sigmas_MPa"] or not all(np.isfinite(v) and v <= 0 for v in sig):
        raise ParameterError(f"parameters sigmas_MPa={params['sigmas_MPa']!r}, cyclic_sigma_MPa="
                             f"{params['cyclic_sigma_MPa']!r}: at least one stress, each finite "
                             "and <= 0 (compression)")


def main(argv=None):
    params = parse_overrides(PARAMS, argv, __doc__)
    check(params)
    law = JointLaw.reference(shear_damage=params["shear_damage"])
    summary = run(params, params["out"])
    u0 = law.ft / law.knn
    gt_int = (law.u_k - u0) * (1 - (1 + np.expm1(-law.zeta) / law.zeta) / -np.expm1(-law.zeta))
    gf = 0.5 * law.ft * u0 + law.ft * gt_int
    print(f"tension peak {summary['tension_peak'] / MPa:.6f} MPa (ft {law.ft / MPa} MPa)")
    print(f"tension energy {summary['tension_energy']:.4f} J/m^2 (closed form {gf:.4f}, "
          f"rel. err {summary['tension_energy'] / gf - 1:.2e})")
    for k, v in summary.items():
        if k.endswith("peak/fs"):
            print(f"{k} = {v:.6f}")
    print(f"wrote PNG and CSV files to {params['out']}")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
