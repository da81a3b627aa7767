"""Checkpoint and restart: everything a continued run needs, written into the result file at
every frame and every ``SolverOptions.checkpoint_s`` between frames, and read back by
``Simulation.resume``."""
from __future__ import annotations

import time

import numpy as np

from .. import loading as L
from ..kernels.plastic_damage import NMS
from ..results import check_stored, ends_run, open_result
from .arrays import mark_pristine

#: the nodal and reference-point arrays a checkpoint holds (``Dyn`` fields)
STATE = ("U", "V", "free", "rpU", "rpV", "rpfree")


class Checkpoints:
    """When checkpoints are written and kept (``Output.checkpoint_s``, ``keep_checkpoint_s``)."""

    def __init__(self):
        self.time = time.perf_counter()   # when one was last written
        self.kept = self.time             # when one was last kept

    def due(self, sim):
        """True when a result file is written and ``checkpoint_s`` have passed since the last
        checkpoint."""
        return (sim.writer is not None
                and time.perf_counter() - self.time >= sim.options.output.checkpoint_s)

    def write(self, sim, inside=False):
        """Store everything a continued run needs (overwritten at every frame and every
        ``checkpoint_s`` between frames); ``inside``: after a committed part of a cut
        increment (the stage position is that increment's)."""
        self.time = time.perf_counter()
        d = sim.dyn
        arrays = {k: getattr(d, k) for k in STATE}
        energy_arrays, energy_meta = sim.energy.serialise()
        arrays.update(rp_force=sim.rp_force, lam=sim.lam, **energy_arrays,
                      s_blocks=sim.mesh.s_old, s_joints=sim.cont.s_old,
                      du_prev=sim.du_prev if sim.du_prev is not None else np.zeros(0))
        if sim.sliding is not None:
            arrays.update(sim.sliding.state())
        meta = {"values": [[list(k), v] for k, v in sim.values.items()],
                "factors": sim.factors, **energy_meta, "dctl_prev": sim.dctl_prev,
                "dlam_prev": sim.dlam_prev, "opening_slope": sim.opening_slope,
                "opening_gmul": sim.opening_gmul, "split": sim.split, "quick": sim.quick,
                "pending": [[[[list(k), v] for k, v in goal.items()], depth, diss]
                            for goal, depth, diss in sim.pending],
                "history": {k: v for k, v in sim.history.items()}, "patterns": [],
                "stage": list(sim.stage_position), "inside": inside}
        for name, (pat, P, rpP) in sim.patterns.items():
            arrays[f"pattern_P/{name}"] = P
            arrays[f"pattern_rpP/{name}"] = rpP
            meta["patterns"].append(name)
        keep_s = sim.options.output.keep_checkpoint_s
        keep = keep_s > 0 and self.time - self.kept >= keep_s
        if keep:
            self.kept = self.time
        sim.writer.write_checkpoint(sim.increment, arrays, meta, keep=keep)


def _check(sim, arrays):
    """Raise a clear error unless the checkpoint ``arrays`` fit this model and are finite."""
    d = sim.dyn
    need = {k: getattr(d, k).shape for k in STATE}
    need.update(rp_force=sim.rp_force.shape, lam=sim.lam.shape, s_blocks=sim.mesh.s_old.shape,
                s_joints=sim.cont.s_old.shape, f_prev=None, du_prev=None)
    for k, shape in need.items():
        if k in arrays and shape is not None and np.shape(arrays[k]) != shape:
            raise L.LoadingError(f"checkpoint of {sim.output}: {k} has shape "
                                 f"{np.shape(arrays[k])}, this model needs {shape} (not the "
                                 "same model)")
        check_stored(sim.output, k, arrays.get(k))


def load(sim, increment=None):
    """Restore ``sim`` (built, its writer open) from the last checkpoint of ``sim.output``, or
    from the one kept after ``increment`` (later rows and frames are dropped)."""
    if increment is not None:
        sim.writer.rewind(int(increment))
    inc, arrays, meta = open_result(sim.output).checkpoint()
    d = sim.dyn
    sb = arrays.get("s_blocks")
    if sb is not None and sb.ndim == 3 and sb.shape[2] == NMS - 1:
        # written before the states held MS_DL (2026-12-05): no multiplier, no first guess
        arrays["s_blocks"] = np.concatenate([sb, np.zeros(sb.shape[:2] + (1,))], axis=2)
    _check(sim, arrays)
    for k in STATE:
        getattr(d, k)[:] = arrays[k]
    sim.rp_force[:] = arrays["rp_force"]
    sim.lam[:] = arrays["lam"]
    sim.energy.restore(arrays, meta, d.U)
    sim.mesh.s_old[:] = arrays["s_blocks"]
    sim.mesh.s_new[:] = arrays["s_blocks"]
    mark_pristine(sim)
    sim.cont.s_old[:] = arrays["s_joints"]
    sim.cont.s_new[:] = arrays["s_joints"]
    if sim.sliding is not None:
        sim.sliding.restore(arrays)
    sim.du_prev = arrays["du_prev"] if arrays["du_prev"].size else None
    sim.values = {tuple(k): v for k, v in meta["values"]}
    sim.factors = dict(meta["factors"])
    sim.dctl_prev = meta["dctl_prev"]
    sim.dlam_prev = meta.get("dlam_prev", 0.0)          # older files: no opening predictor
    sim.opening_slope = meta.get("opening_slope")
    sim.opening_gmul = meta.get("opening_gmul", 1.0)    # older files: the full gain
    sim.split = meta.get("split", 0)                    # older files: no step memory
    sim.quick = meta.get("quick", 0)
    sim._checkpoint_stage = meta.get("stage")
    sim._checkpoint_inside = meta.get("inside", True)   # older files: may be
    pending = meta.get("pending")
    if pending is not None:
        sim.pending = [({tuple(k): v for k, v in goal}, depth, diss)
                       for goal, depth, diss in pending]
    else:   # older files: not stored; inside an increment, None: the rest is split anew
        sim.pending = None if sim._checkpoint_inside else []
    sim.history = {k: list(v) for k, v in meta["history"].items()}
    for name in meta["patterns"]:
        stored = L.StoredPattern(name, arrays[f"pattern_P/{name}"], arrays[f"pattern_rpP/{name}"])
        sim.patterns[name] = (stored, stored.P, stored.rpP)
    sim.increment = inc
    sim.writer.truncate(inc, len(sim.history.get("increment", ())))


def resume_position(sim, stages):
    """(stage index, increments of it done, its controls' start values) of the checkpoint.

    Checkpoints store their position; for older files it is found from the number of
    increments, checked against the prescribed paths (a run whose increments were cut cannot
    be located that way and is refused); a ramp's start follows from its value there.
    """
    from .controls import key
    pos = sim._checkpoint_stage
    if pos is not None:
        if ends_run(pos):   # a finished run: the stages given come after it
            return 0, 0, None
        k, i, starts = pos[:3]
        if k >= len(stages) or i > stages[k].increments:
            raise L.LoadingError(f"resume {sim.output}: the checkpoint is at increment {i} of "
                                 f"stage {k}, the stages given have fewer (not the same run)")
        return k, i, {tuple(kk): v for kk, v in starts}
    done = sim.increment
    for k, stage in enumerate(stages):
        if done <= stage.increments:
            break
        done -= stage.increments
    else:
        raise L.LoadingError(f"resume {sim.output}: the checkpoint is after {sim.increment} "
                             f"increments, the stages given have fewer (not the same run)")
    starts = {}
    n = stage.increments
    for ctl in stage.controls:
        kk = key(ctl)
        now = sim.values.get(kk, 0.0)
        # a ramp's value after `done` of n increments fixes its start value
        starts[kk] = (n * now - done * ctl.to) / (n - done) if (
            ctl.path is None and ctl.to is not None and 0 < done < n) else now
        if ctl.path is not None and done and not np.isclose(ctl.path[done - 1], now, rtol=1e-9,
                                                            atol=1e-15):
            raise L.LoadingError(f"resume {sim.output}: control {ctl.label} is at {now:.6g}, "
                                 f"not at the value of increment {done} of stage "
                                 f"{stage.name!r} (cut increments: the file has no stage "
                                 f"position)")
    return k, done, starts
