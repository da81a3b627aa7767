"""What every scene does after its run: close the result, write the curve (PNG + CSV) and VTK."""
import os

import numpy as np


def finish(sim, out, x, y, xlabel, ylabel, title, reference=None, vtk=True):
    """Write ``out.png`` (curve, optional reference (x, y, label)), ``out.csv`` and ``out_vtk/``.

    ``sim`` is closed first so that the HDF5 result is complete. Returns the written paths.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sim.close()
    os.makedirs(os.path.dirname(out) or ".", exist_ok=True)
    fig, ax = plt.subplots(figsize=(6, 4))
    if reference is not None:
        ax.plot(reference[0], reference[1], "k--", lw=1, label=reference[2])
    ax.plot(x, y, "o-", ms=2, label="dr_masonry")
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out + ".png", dpi=120)
    plt.close(fig)
    hist = sim.history
    keys = list(hist)
    np.savetxt(out + ".csv", np.column_stack([hist[k] for k in keys]), delimiter=",",
               header=",".join(keys), comments="")
    paths = [out + ".png", out + ".csv"]
    if vtk and sim.output is not None:
        from .viz.vtk_series import export_vtk
        paths.append(export_vtk(sim.output, out + "_vtk"))
    return paths
