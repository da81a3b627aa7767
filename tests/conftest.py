"""Helpers shared by several test modules (imported as ``from conftest import ...``; pytest puts
this folder on ``sys.path``): closed forms of the wall scenes and a tiny model with a fake results
file for the readers, plots and command line, figures recorded as they are saved (to read a
picture's pixels at data points), a two-brick wall for the compile tests, and
hexahedron meshes with the force kernel's elastic forces on them (test_hex8, test_corotational)."""
import dataclasses
import warnings
from types import SimpleNamespace

import numpy as np
from matplotlib.image import imread

from dr_masonry import JointLaw, Load, PlasticDamage, Simulation, SolverOptions, Stage
from dr_masonry.geometry import BrickSpec, add_wall, plane_nodes
from dr_masonry.kernels import forces, hex8
from dr_masonry.kernels.plastic_damage import NMS
from dr_masonry.loading import Gravity
from dr_masonry.model import HEX_NATURAL, Model
from dr_masonry.results import ResultWriter


def rocking_shear(n_base, length, thickness, height, ft=0.0):
    """Base shear (N) at which a wall ``length`` x ``thickness`` x ``height`` (m) rocks as a rigid
    body about its toe: (n_base L / 2 + ft t L^2 / 2) / H, from the moments about the toe of the
    axial force at the base ``n_base`` (N, load and self-weight) and of a bed joint whose tensile
    strength ``ft`` (Pa) holds the whole base until it lets go."""
    return (n_base * length / 2 + ft * thickness * length ** 2 / 2) / height


def saved_figures(monkeypatch, module):
    """Record the figures that code creating them through ``module.Figure`` (``matplotlib.figure``,
    or ``dr_masonry.viz.plots``, which imports it) saves: returns a dict, file name -> figure,
    filled as they are saved; each figure keeps the dpi it was saved at as ``saved_dpi``."""
    saved = {}

    class Recorded(module.Figure):
        def savefig(self, fname, *a, **k):
            self.saved_dpi = k.get("dpi", self.dpi)
            saved[str(fname)] = self
            return super().savefig(fname, *a, **k)
    monkeypatch.setattr(module, "Figure", Recorded)
    return saved


def pixels(png, fig, ax, xy):
    """RGB colours (n, 3) of the saved picture ``png`` of recorded figure ``fig`` at the data
    points ``xy`` (n, 2) of its axes ``ax``."""
    img = imread(png)[..., :3]
    p = ax.transData.transform(np.atleast_2d(xy)) * (fig.saved_dpi / fig.dpi)
    return img[np.round(img.shape[0] - p[:, 1]).astype(int), np.round(p[:, 0]).astype(int)]


@dataclasses.dataclass
class StubMaterial:
    """Stand-in for PlasticDamage: a dataclass with params_array()."""
    E: float = 10e9
    nu: float = 0.2

    def params_array(self):
        return np.array([self.E, self.nu])


class StubLaw:
    """A joint law that is not a dataclass (stored as repr)."""

    def __repr__(self):
        return "StubLaw(kn=1e12)"


def tiny_model(with_contacts=True):
    """Two stacked boxes 0.2 x 0.1 x 0.1 m (block 1 on top of block 0), 2 x 1 x 1 hexahedra each.

    The contact set (when asked) has one point per top-face node of block 0 against the bottom
    face of block 1.
    """
    m = Model()
    mat = StubMaterial()
    m.set_joint_law(StubLaw())
    m.add_box((0, 0, 0), (0.2, 0.1, 0.1), mat, divisions=(2, 1, 1), group="wall", fixed=True)
    m.add_box((0, 0, 0.1), (0.2, 0.1, 0.1), mat, divisions=(2, 1, 1), group="beam")
    if with_contacts:
        grid, _ = m.block_face(0, 1)
        _, quads = m.block_face(1, 0)
        slave = grid.ravel()
        nc = slave.size
        m.contacts = SimpleNamespace(
            slave=slave, master=np.repeat(quads[:1], nc, axis=0), xi=np.zeros((nc, 2)),
            area=np.full(nc, 0.02 / nc), law=np.zeros(nc, np.int64),
            blocks=np.tile([0, 1], (nc, 1)), gap0=np.zeros((nc, 3)), n=nc)
    return m


def fake_fields(m, k):
    """Frame fields of increment k: U = k * 1e-4 * node index pattern, damage growing with k."""
    nn, ne, nc = m.n_nodes, m.n_elements, m.contacts.n
    U = np.zeros((nn, 3))
    U[:, 0] = 1e-4 * k * m.nodes[:, 2] / 0.2
    return {"U": U, "dt": np.linspace(0, 0.1 * k, ne), "dc": np.zeros(ne),
            "D": np.linspace(0, 0.2 * k, nc), "opening": np.full(nc, 1e-5 * k),
            "slip": np.full(nc, 2e-5 * k)}


def write_fake_result(path, n_rows=5, frames=(0, 2, 4)):
    """A results file of the tiny model: history rows disp = 1e-4 i m, force = 1e3 * sin(i) N."""
    m = tiny_model()
    cfg = {"case": "tiny", "params": {"drift": 0.01, "mesh": [2, 1, 1]}}
    with ResultWriter(path, m, cfg) as w:
        for i in range(n_rows):
            w.append_history({"increment": i, "disp": 1e-4 * i, "force": 1e3 * np.sin(i)})
            if i in frames:
                w.write_frame(i, fake_fields(m, i), attrs={"control": 1e-4 * i})
    return m, cfg


def tiny_wall():
    """Simulation of a two-brick wall clamped at its base (test_precompile and its subprocesses)."""
    model = Model()
    model.set_joint_law(JointLaw.reference())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # length snapped to half bricks
        add_wall(model, (0, 0, 0), 0.44, 0.243, PlasticDamage.reference(),
                 brick=BrickSpec(nx_along=2, ny_thick=1, nz_height=1))
    sim = Simulation(model, SolverOptions(progress=False))
    sim.fix(plane_nodes(model, 2, 0.0), "xyz")
    return sim


def gravity():
    """One increment of self-weight."""
    return [Stage("gravity", 1, [Load(pattern=Gravity(), to=1.0)])]


def elastic_params(E, nu):
    """Material parameter row of an elastic block material (E Pa, nu), 2000 kg/m^3."""
    return PlasticDamage.elastic(E, nu, 2000.0).params_array()


def box_mesh(n, size=(1.0, 1.0, 1.0)):
    """Structured mesh of [0, size] with n = (nx, ny, nz) hexahedra, VTK corner order."""
    nx, ny, nz = n
    g = [np.linspace(0.0, s, k + 1) for s, k in zip(size, n)]
    Z, Y, Xg = np.meshgrid(g[2], g[1], g[0], indexing="ij")
    X = np.stack([Xg.ravel(), Y.ravel(), Z.ravel()], axis=1)
    I, J, K = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz),
                                              indexing="ij"))

    def nid(i, j, k):
        return i + (nx + 1) * (j + (ny + 1) * k)
    conn = np.stack([nid(I, J, K), nid(I + 1, J, K), nid(I + 1, J + 1, K), nid(I, J + 1, K),
                     nid(I, J, K + 1), nid(I + 1, J, K + 1), nid(I + 1, J + 1, K + 1),
                     nid(I, J + 1, K + 1)], axis=1)
    return X, conn.astype(np.int64)


def distorted_element(rng, amp=0.15):
    """Corners (8, 3) m of a 1 x 0.8 x 1.2 m box with every corner moved by up to ``amp``."""
    return 0.5 * (HEX_NATURAL + 1.0) * [1.0, 0.8, 1.2] + rng.uniform(-amp, amp, (8, 3))


def update_flags(ne):
    """``pristine`` and ``dirty`` of ``hex_forces`` for the full state update everywhere."""
    return np.zeros(ne, np.uint8), np.zeros(ne, np.uint8)


def run_forces(U, X, conn, E, nu, elem_mat=None, params=None, corot=False):
    """Element forces, energies and nodal forces of an elastic mesh (``corot``: every element on
    the corotational path of a run, else at its Gauss points)."""
    ne = conn.shape[0]
    dN, geo, wdet, h = hex8.hex_geometry_shared(X, conn)
    if params is None:
        params = elastic_params(E, nu)[None, :]
        elem_mat = np.zeros(ne, dtype=np.int64)
    tables = (hex8.corot_tables(X, conn, dN, geo, wdet, elem_mat, params, np.arange(ne))
              if corot else None)
    s_old = np.zeros((ne, 8, NMS))
    s_new = np.zeros((ne, 8, NMS))
    f_elem = np.full((ne, 8, 3), np.nan)
    energy = np.full(ne, np.nan)
    forces.hex_forces(np.ascontiguousarray(U, dtype=float), conn, np.arange(ne), dN, geo, wdet, h,
                    elem_mat, params, s_old, s_new, *update_flags(ne), f_elem, energy, corot=tables)
    f_node = np.zeros_like(X)
    np.add.at(f_node, conn.ravel(), f_elem.reshape(-1, 3))
    return f_elem, energy, f_node
