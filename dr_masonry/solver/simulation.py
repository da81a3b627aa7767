"""The user-facing simulation: a model with supports, reference points and options
(:class:`Simulation`), its ``run`` and ``resume``.

The work is done by the modules beside this one: ``arrays`` (building the arrays and masses),
``controls`` (controls to load vectors), ``increments`` (the increment loop with cutting),
``relaxing`` (one increment relaxed by the compiled loop), ``certificate`` (convergence and
equilibrium checks, diagnoses), ``energy`` (the energy account and audit), ``rows`` (the
committed row), ``observers`` (progress bar, row writer) and ``checkpoint`` (restart).
"""
from __future__ import annotations

import os

import numpy as np

from .. import loading as L
from ..interrupts import terminate_as_interrupt
from ..model import Model, ModelError, id_array
from ..options import OptionsError, SolverOptions
from ..precompile import ensure_compiled
from ..results import ResultsError, ResultWriter, make_folder, open_result, require_kept
from ..results import state_fields
from . import checkpoint, controls
from .arrays import SolverError, build_arrays, check_materials, reaction_rows
from .energy import EnergyAccount
from .increments import run_stage
from .observers import Idle, ProgressBar, RowWriter


class Simulation:
    """A model with supports, reference points and options, ready to run stages.

    Parameters
    ----------
    model : Model
        the block assembly; contacts are detected here if the model has none yet.
    options : SolverOptions
    output : str or None
        HDF5 result path (None keeps results in memory only).
    config : dict
        the scene's input parameters, stored in the result file.

    Attributes
    ----------
    history : dict of str -> list of float, the committed rows (``docs/file_format.md``).
    monitors : list of callables ``monitor(sim, out, done)``, called after every compiled call of
        the relaxation (at most ``relaxing.CALL_ITERATIONS`` iterations): ``out`` the attempt's
        ``kernels.relaxation.Exit`` so far (``out.residual``, ``out.status``, ...), ``done`` its
        iterations (row ``sim.increment + 1``). For diagnostics (``benchmarks/
        slow_increment.py``); an exception raised by a monitor stops the run, rows so far kept.
    observers : list of objects with ``row(sim, row)``, called with every committed row (the
        result file's row writer is one).
    """

    def __init__(self, model, options=None, output=None, config=None):
        from ..contact_search import detect_contacts
        if not isinstance(model, Model):
            raise ModelError(f"Simulation: model must be a Model, got {model!r}")
        if not (output is None or isinstance(output, (str, os.PathLike))):
            raise ResultsError(f"Simulation: output must be a file path or None, got {output!r}")
        if not (config is None or isinstance(config, dict)):
            raise OptionsError(f"Simulation: config must be a dict of the input parameters, got "
                               f"{config!r}")
        self.model = model
        self.options = options or SolverOptions()
        self.output = output if output is None else os.fspath(output)
        self.config = dict(config or {})
        if not isinstance(self.options, SolverOptions):
            raise OptionsError(f"Simulation: options must be a SolverOptions, got "
                               f"{type(self.options).__name__}")
        if model.n_blocks == 0:
            raise ModelError("Simulation: the model has no blocks")
        check_materials(model)
        if model.contacts is None:
            detect_contacts(model)
        self.rigid_points = []
        self.node_sets = {}
        self.contact_reactions = {}
        self._reaction_blocks = {}   # name -> (blocks, support), to re-select rows after sliding
        self._fixed = np.zeros((model.n_nodes, 3), dtype=bool)
        fixed_blocks = np.nonzero(model.block_fixed)[0]
        self._fixed[model.block_nodes(fixed_blocks)] = True
        self._built = False
        self.writer = None   # the results file's writer, opened by build
        self._closed = False   # close() was called: no more rows can be written
        self.coarse = None
        self._resuming = False
        self._checkpoint_stage = None
        self._checkpoint_inside = False   # the checkpoint resumed from is inside a cut increment
        self._resume_increment = None
        self.checkpoints = checkpoint.Checkpoints()
        # after each increment: (stage, its increments done, the controls' start values as
        # [[key, value]], stages of the run call, increments of the stage); stored in checkpoints
        self.stage_position = None
        self._warned = set()
        self.history = {}
        self.increment = 0
        # iterations and relaxation seconds of attempts cut in two since the last committed row
        self._cut_work = [0, 0.0]
        self.monitors = []
        self.observers = []
        self.progress = Idle()

    # ------------------------------------------------------------------ set-up API
    def node_set(self, name, nodes):
        """Register a named node set (int array of node ids)."""
        self._before_run(f"node set {name!r}")
        self._check_name(name)
        nodes = self._nodes(f"node set {name!r}", nodes)
        ns = L.NodeSet(name, nodes)
        self.node_sets[name] = ns
        return ns

    def contact_reaction(self, name, blocks, support):
        """Record the force (N, global axes) that the blocks ``support`` exert through their joints
        on the blocks ``blocks`` (history ``<name>.fx/fy/fz``; the sign of a node-set reaction:
        a wall standing on a foundation gives a positive ``fz``).

        Splits the reaction of one support (a foundation under several walls) by wall, exactly:
        the joint forces are summed per contact, whatever the meshes of the two sides.
        """
        self._before_run(f"contact reaction {name!r}")
        self._check_name(name)
        nb = self.model.n_blocks
        pair = (id_array(f"contact reaction {name!r}: blocks", blocks, nb, L.LoadingError),
                id_array(f"contact reaction {name!r}: support", support, nb, L.LoadingError))
        on_slave, on_master = reaction_rows(self.model.contacts.blocks, *pair)
        if not (on_slave.size or on_master.size):
            raise L.LoadingError(f"contact reaction {name!r}: no joint between the two block sets")
        self.contact_reactions[name] = (on_slave, on_master)
        self._reaction_blocks[name] = pair

    def _before_run(self, what):
        """LoadingError: ``what`` changes the arrays that the first run built."""
        if self._built:
            raise L.LoadingError(f"{what} must be set before the first run (its arrays are built "
                                 f"then)")

    def _check_name(self, name):
        if not (isinstance(name, str) and name):   # history columns are "<name>.ux" ...
            raise L.LoadingError(f"names of node sets, rigid points and contact reactions must "
                                 f"be non-empty strings, got {name!r}")
        if name in self.contact_reactions:
            raise L.LoadingError(f"a contact reaction named {name!r} exists already")
        if name in self.node_sets or any(rp.name == name for rp in self.rigid_points):
            raise L.LoadingError(f"a node set or rigid point named {name!r} exists already; names "
                                 f"identify controls in the history and on restart")

    def fix(self, nodes, dofs="xyz"):
        """Clamp DOFs (any of 'x', 'y', 'z') of the given nodes (supports, symmetry planes)."""
        self._before_run("fix")
        nodes = self._nodes("fix", nodes)
        if not (isinstance(dofs, str) and dofs):
            raise L.LoadingError(f"fix: dofs={dofs!r} must be a string of 'x', 'y', 'z'")
        for d in dofs:
            self._fixed[nodes, L.dof_index(d, rotations=False)] = True

    def _nodes(self, what, nodes):
        """``nodes`` as sorted unique node ids; LoadingError naming ``what`` when the set is
        empty (e.g. a ``plane_nodes`` that found no node) or an id is not a node."""
        nodes = np.unique(id_array(what, nodes, self.model.n_nodes, L.LoadingError))
        if nodes.size == 0:
            raise L.LoadingError(f"{what}: no nodes given (an empty node set)")
        return nodes

    def rigid_point(self, name, blocks=None, nodes=None, position=None):
        """Tie the nodes of ``blocks`` (or ``nodes``) rigidly to a reference point with 6 DOFs.

        ``position`` defaults to the centroid of the nodes. Returns the :class:`RigidPoint`.
        """
        self._before_run(f"rigid point {name!r}")
        self._check_name(name)
        if (nodes is None) == (blocks is None):
            raise L.LoadingError(f"rigid point {name!r}: give blocks or nodes (one of them)")
        if nodes is None:
            nodes = self.model.block_nodes(blocks)
        nodes = self._nodes(f"rigid point {name!r}", nodes)
        for rp in self.rigid_points:
            if np.intersect1d(rp.nodes, nodes).size:
                raise L.LoadingError(f"rigid point {name!r} shares nodes with {rp.name!r}")
        pos = (self.model.nodes[nodes].mean(axis=0) if position is None
               else L.finite_vector(f"rigid point {name!r}: position", position, 3))
        rp = L.RigidPoint(name, nodes, pos, len(self.rigid_points))
        self.rigid_points.append(rp)
        return rp

    # ------------------------------------------------------------------ arrays
    def build(self):
        """Build the arrays (done by the first :meth:`run`; call it to inspect them first)."""
        self.options.check()
        build_arrays(self)
        n, nr = self.model.n_nodes, len(self.rigid_points)
        self.lam = np.zeros(1)
        self.rp_force = np.zeros((nr, 6))  # Force-control values on reference-point DOFs
        self.values = {}       # control key -> current value
        self.factors = {}      # pattern name -> current factor (load-controlled)
        self.patterns = {}     # pattern name -> (pattern, P (n,3), rpP (nr,6))
        self.presc = {}        # (node set name, dof) -> (nodes, dof)
        self.energy = EnergyAccount(n)
        self.du_prev = None
        self.dctl_prev = 0.0
        self.opening_slope = None   # opening control: reaction N per unit factor (secant)
        self.opening_gmul = 1.0     # opening control with a rate: the multiple of its gain
        self.dlam_prev = 0.0        # opening control: the last increment's change of factor
        self.split = 0              # step memory: halvings the next increment starts with
        self.quick = 0              # step memory: quick parts in a row at that split
        self.pending = []           # parts of the increment in progress left to run
        self.writer = None
        if self.output is not None:
            make_folder(os.path.dirname(os.path.abspath(self.output)))
            cfg = dict(self.config, solver=self.options.as_dict())
            self.writer = ResultWriter(self.output, self.model, cfg,
                                       mode="a" if self._resuming else "w")
            self.observers.append(RowWriter(self.writer))
        self._built = True
        if self._resuming:
            checkpoint.load(self, self._resume_increment)

    def pattern_forces(self, pat):
        """(P (n_nodes, 3) N, rpP (n_rp, 6)) of a load pattern per unit factor, cached by name."""
        return controls.pattern_forces(self, pat)

    # ------------------------------------------------------------------ running
    def run(self, stages):
        """Run the stages; returns the history (dict of arrays). Raises SolverError on failure,
        KeyboardInterrupt on Ctrl-C and :class:`~dr_masonry.interrupts.Terminated` (one) on SIGTERM,
        with the results file complete up to the last row written.

        After :meth:`resume`, ``stages`` must be the original run's stages: those finished before
        the checkpoint are skipped and the stage in progress continues where it stopped.
        """
        if not (isinstance(stages, (list, tuple)) and stages
                and all(isinstance(s, L.Stage) for s in stages)):
            raise L.LoadingError(f"Simulation.run: stages must be a non-empty list of Stage, got "
                                 f"{stages!r}")
        self.options.check()   # fields changed since the options were made
        for mon in self.monitors:
            if not callable(mon):
                raise OptionsError(f"Simulation.monitors: {mon!r} is not a function "
                                   f"monitor(sim, out, done)")
        for stage in stages:
            L.check_stage(stage)
        if self._closed:
            raise ResultsError(f"Simulation.run: the results file {self.output} was closed "
                               f"(Simulation.close); continue a stored run with a new Simulation "
                               f"and resume")
        if not self._built:
            self.build()
        for stage in stages:  # register every prescribed node set so history columns stay fixed
            controls.check_controls(self, stage)
            for ctl in stage.controls:
                sets = ([ctl.target] if isinstance(ctl, (L.Displacement, L.Indirect))
                        and isinstance(ctl.target, L.NodeSet) else
                        [ctl.a, ctl.b] if isinstance(ctl, L.Opening) else [])
                for side in sets:   # (an Opening: the two sides' mean displacements)
                    k = L.dof_index(ctl.dof, rotations=False)
                    self.presc[(side.name, k)] = (side.nodes, k)
        k0, i0, starts = (checkpoint.resume_position(self, stages) if self._resuming
                          else (0, 0, None))
        self._resuming = False
        total = sum(s.increments for s in stages[k0:]) - i0
        self.progress = ProgressBar(total, self.options.output.progress)
        self.observers.append(self.progress)
        try:
            with terminate_as_interrupt():   # SIGTERM stops the run as Ctrl-C does
                ensure_compiled(self.mesh, self.cont, self.dyn)
                for k, stage in enumerate(stages[k0:], start=k0):
                    run_stage(self, stage, (k, len(stages)),
                              *((i0, starts) if k == k0 else (0, None)))
        finally:
            self.progress.close()
            self.observers.remove(self.progress)
            self.progress = Idle()
            if self.writer is not None:
                self.writer.flush()
        return {k: np.asarray(v) for k, v in self.history.items()}

    def close(self):
        """Close the result file (a run after this is refused: its rows would not be written)."""
        if self.writer is not None:
            self.writer.close()
            self.observers = [o for o in self.observers if not isinstance(o, RowWriter)]
            self.writer = None
            self._closed = True

    def fail(self, msg):
        """Stop the run with :class:`SolverError` ``msg``, the rows so far flushed to the file."""
        if self.writer is not None:
            self.writer.flush()
        raise SolverError(msg)

    def fields(self):
        """Current field values for a frame: U, dt, dc per element, D/opening/slip per contact."""
        d, mesh, cont = self.dyn, self.mesh, self.cont
        f = state_fields(d.U, mesh.s_old, cont.s_old)
        if cont.slave.size:
            on = cont.area > 0.0   # a point off the surface carries no traction
            f.update(opening=cont.gaps[:, 0].copy(),
                     slip=np.hypot(cont.gaps[:, 1], cont.gaps[:, 2]),
                     sigma=np.where(on, cont.trac[:, 0], 0.0),
                     tau=np.where(on, np.hypot(cont.trac[:, 1], cont.trac[:, 2]), 0.0))
        return f

    def write_frame(self):
        """Write a field frame of the current state and a checkpoint (with a result file)."""
        if self.writer is not None:
            sl = self.sliding
            self.writer.write_frame(self.increment, self.fields(), {"stage": self.stage_name},
                                    contacts=sl.contact_set() if sl is not None and sl.changed
                                    else None)
            self.checkpoints.write(self)

    # ------------------------------------------------------------------ restart
    def resume(self, path, increment=None):
        """Continue the run stored in ``path`` from its last checkpoint (the last frame), or
        from the checkpoint it kept after ``increment`` (``Result.kept_checkpoints``; the kept
        ones after it are dropped with the rows and frames).

        The simulation must be set up as the original one (same model, supports and reference
        points, e.g. from the scene's ``build``); later rows and frames of the file are dropped and
        the next :meth:`run` appends to it. If the stored run stopped before its end, ``run``
        must get the same stages and continues the one in progress; after a finished run, the
        stages given run after it from the restored state (controls keep their values, patterns
        their factors).
        """
        if self._built:
            raise L.LoadingError("resume() must be called before the first run")
        if increment is not None:   # checked before the file is opened for writing
            require_kept(path, open_result(path).kept_checkpoints, increment)
        self.output = path
        self._resuming = True
        self._resume_increment = increment
        self.build()
