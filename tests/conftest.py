"""Helpers shared by several test modules (imported as ``from conftest import ...``; pytest puts
this folder on ``sys.path``): closed forms of the wall scenes and a tiny model with a fake results
file for the readers, plots and command line."""
import dataclasses
from types import SimpleNamespace

import numpy as np

from dr_masonry.model import Model
from dr_masonry.results import ResultWriter


def rocking_shear(n_base, length, thickness, height, ft=0.0):
    """Base shear (N) at which a wall ``length`` x ``thickness`` x ``height`` (m) rocks as a rigid
    body about its toe: (n_base L / 2 + ft t L^2 / 2) / H, from the moments about the toe of the
    axial force at the base ``n_base`` (N, load and self-weight) and of a bed joint whose tensile
    strength ``ft`` (Pa) holds the whole base until it lets go."""
    return (n_base * length / 2 + ft * thickness * length ** 2 / 2) / height


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
