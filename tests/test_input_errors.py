"""Bad input gets a clear error naming the parameter, id, value or file: never a traceback of an
internal error, a NaN-filled result or a silent clamp. One test per entry point: solver options,
stages and controls, load patterns, the model and simulation API, result files and checkpoints,
output folders and the scene scripts' parameters (through ``dr-masonry run``)."""
import shutil

import h5py
import numpy as np
import pytest

from dr_masonry import (BodyForce, Displacement, Force, Gravity, JointLaw, Load, Model,
                        PlasticDamage, Simulation, SolverOptions, Stage)
from dr_masonry.cli import main
from dr_masonry.loading import Combined, LoadingError, PointLoad, Pressure, cyclic_path
from dr_masonry.model import ModelError
from dr_masonry.options import FLAT, OptionsError
from dr_masonry.protocols import S5
from dr_masonry.results import ResultsError, make_folder, open_result
from conftest import write_fake_result

MAT = PlasticDamage.elastic(10e9, 0.2, 2000.0)


@pytest.mark.parametrize("field, value, msg", [
    ("tol", -1.0, r"tol=-1.0: must be a finite number in \(0, 0.1\] \(a relative residual\)"),
    ("tol", 5.0, r"tol=5.0: must be a finite number in \(0, 0.1\]"),   # was run: no equilibrium
    ("tol", "1e-4", r"tol='1e-4'"),
    ("tol", float("nan"), r"tol=nan"),
    ("max_iter", 2.5, r"max_iter=2.5: must be an integer >= 1"),   # hung in the relaxation
    ("max_iter", 0, r"max_iter=0"),
    ("stall_iter", 2.5, r"stall_iter=2.5: must be an integer >= 0"),
    ("max_cuts", True, r"max_cuts=True"),
    ("alpha", "x", r"alpha='x'"),                                   # was a Numba TypingError
    ("alpha", -1.0, r"alpha=-1.0: must be a finite number > 0"),
    ("predictor", "no", r"predictor='no': must be True or False"),  # counted as True
    ("coarse", 1, r"coarse=1: must be True, False or 'auto'"),
    ("damping", "viscus", r"damping='viscus': valid values are"),
    ("floor_tol", 1e-5, r"floor_tol=1e-05: must be a finite number 0 \(off\) or in \[tol"),
    ("floor_tol", 2.0, r"floor_tol=2.0: must be a finite number 0 \(off\) or in \[tol = 5e-05, "
                       r"0.1\]"),                                    # was run: any row accepted
    ("gap_tol", 1.0, r"gap_tol=1.0: must be a finite number in \[0, 1\) \(0: off\)"),
])
def test_solver_options_name_the_field(field, value, msg):
    with pytest.raises(OptionsError, match=msg):
        SolverOptions(**{field: value})
    with pytest.raises(OptionsError, match=r"alpha=1.0: must be a finite number in \[0, 1\)"):
        SolverOptions(damping="local", alpha=1.0)


def test_paths_of_more_increments_than_any_run_could_relax_are_refused():
    """A billion increments was killed for memory while the targets were built."""
    with pytest.raises(LoadingError, match=r"stage 's': 1,000,000,000 increments exceed"):
        Stage("s", 1e9)
    with pytest.raises(LoadingError, match=r"protocol S5 with step 1e-09 m: .* exceed"):
        S5.path(height=2.75, step=1e-9)
    with pytest.raises(LoadingError, match=r"protocol S5: 2,000,000 increments exceed"):
        S5.monotonic_path(2e6, height=2.75)
    with pytest.raises(LoadingError, match=r"cyclic protocol: .* exceed"):
        cyclic_path([1.0], cycles=2, points_per_quarter=10**6)
    assert S5.path(height=2.75, step=0.00025).size == 2192    # the scene's default path


@pytest.mark.parametrize("kw, msg", [(dict(points_per_quarter=0), "points_per_quarter=0"),
                                     (dict(points_per_quarter=2.5), "points_per_quarter=2.5"),
                                     (dict(cycles=0), "cycles=0"),      # were an empty path
                                     (dict(cycles=-1), "cycles=-1")])
def test_cyclic_path_counts_are_whole_numbers(kw, msg):
    with pytest.raises(LoadingError, match=rf"cyclic protocol: {msg} must be a whole number"):
        cyclic_path([1.0], **kw)
    assert cyclic_path([1.0], cycles=1.0, points_per_quarter=2).size == 8


def test_postprocessing_and_material_queries_name_bad_arguments():
    from dr_masonry.materials.plastic_damage import MaterialError
    from dr_masonry.postprocess import PostprocessError, energy_per_cycle
    h = {k: np.zeros(3) for k in ("u", "D_blocks", "D_joints", "W_ext")}
    with pytest.raises(PostprocessError, match="rows selects no row"):   # was an IndexError
        energy_per_cycle(h, "u", rows=np.zeros(3, bool))
    with pytest.raises(MaterialError, match="which='shear'"):   # returned the compression energy
        PlasticDamage.reference().fracture_energy("shear")


def test_integer_options_take_integral_numbers_as_stages_do():
    o = SolverOptions(max_iter=2e5, max_cuts=np.int64(6), stall_iter=0.0)
    assert (o.increments.max_iter, o.increments.max_cuts, o.increments.stall_iter) == (200_000, 6, 0)
    assert all(type(v) is int for v in (o.increments.max_iter, o.increments.max_cuts, o.increments.stall_iter))
    assert Stage("s", 2e1).increments == 20


def test_stages_controls_and_patterns_are_checked_when_made():
    bad = [
        (lambda: Stage("s", 0), r"stage 's': increments=0 must be an integer >= 1"),
        (lambda: Stage("s", 2.5), r"increments=2.5"),                # was truncated to 2
        (lambda: Stage("s", 2, frames=0), r"frames=0"),              # ZeroDivisionError
        (lambda: Stage("s", 2, frame_at=[3]), r"frame_at=\[3\] must be a list of increments of "
                                              r"the stage, integers in 1..2"),
        (lambda: Stage("s", 2, frame_at=5), r"frame_at=5"),
        (lambda: Stage("s", 2, max_iter=0), r"max_iter=0"),          # fell back to the option
        (lambda: Stage("s", 2, tol=float("nan")), r"tol=nan"),
        (lambda: Stage("s", 2, tol=0.5), r"stage 's': tol=0.5 must be a finite number in \(0, 0.1\]"),
        (lambda: Stage("s", 2, controls=None), r"controls must be a list"),
        (lambda: Stage("s", 2, controls=["x"]), r"controls must be a list"),
        (lambda: Displacement(to="abc", target=None), r"to='abc' must be a finite number"),
        (lambda: Load(pattern=None, to=1.0), r"pattern must be one of"),
        (lambda: Gravity(g=float("nan")), r"g=nan must be a finite number"),
        (lambda: BodyForce((np.nan, 0, 0)), r"accel: value 0 of 3 is nan"),
        (lambda: BodyForce((1.0, 0)), r"must be 3 finite numbers"),
        (lambda: PointLoad(None, "x", value=np.inf), r"value=inf"),
        (lambda: Combined([(Gravity(), np.nan)]), r"\(pattern, finite weight\) pairs"),
        (lambda: Pressure(np.zeros((1, 3), int)), r"quads must be an \(m, 4\) array"),
        (lambda: PointLoad(-1, "x"), r"PointLoad 'point': target must be a RigidPoint"),
        (lambda: Displacement(to=1.0, path=[1.0], target=None), r"give to or path, not both"),
        (lambda: Displacement(path=[0.0, np.nan], target=None), r"path: value 1 of 2 is nan"),
    ]
    for make, msg in bad:
        with pytest.raises(LoadingError, match=msg):
            make()
    with pytest.raises(LoadingError, match=r"path: 'ab' is not a list of numbers"):
        Displacement(path="ab", target=None)


def _sim():
    m = Model()
    m.set_joint_law(JointLaw.dry(0.5))
    base = m.add_box((0, 0, 0), (0.2, 0.1, 0.1), MAT, (2, 1, 1), fixed=True)
    top = m.add_box((0, 0, 0.1), (0.2, 0.1, 0.1), MAT, (2, 1, 1))
    return m, Simulation(m), base, top


def test_model_and_simulation_ids_are_checked():
    m, sim, base, top = _sim()
    n = m.n_nodes
    for ids in ([7], [-1]):                       # -1 was silently the last block
        with pytest.raises(ModelError,
                           match=rf"block_nodes: block: id {ids[0]} is not an integer in \[0, 2\)"):
            m.block_nodes(ids)
    with pytest.raises(ModelError, match=r"block_face: face: id 9"):
        m.block_face(0, 9)
    with pytest.raises(ModelError, match=r"divisions must be three integers >= 1, got \(2.5, 1, "):
        m.add_box((1, 0, 0), (0.2, 0.1, 0.1), MAT, (2.5, 1, 1))
    with pytest.raises(ModelError, match=r"fixed must be True or False, got 'no'"):
        m.add_box((1, 0, 0), (0.2, 0.1, 0.1), MAT, fixed="no")   # a non-empty string was True
    for ids, msg in (([n], rf"id {n} is not an integer in \[0, {n}\)"), ([-1], r"id -1"),
                     ([1.7], r"id 1.7"), ([], r"no nodes given")):
        with pytest.raises(LoadingError, match=msg):
            sim.fix(ids)
    with pytest.raises(LoadingError, match=r"rigid point 'p': position: value 0 of 3 is nan"):
        sim.rigid_point("p", blocks=[top], position=(np.nan, 0, 0))
    with pytest.raises(ModelError, match=r"block_nodes: block: id 99"):
        sim.rigid_point("q", blocks=[99])
    # what the model holds but the solver cannot use: named when the simulation is made
    m2 = Model()
    m2.set_joint_law("reference")
    m2.add_box((0, 0, 0), (0.2, 0.1, 0.1), MAT)
    with pytest.raises(ModelError, match=r"default joint law must be a JointLaw, got 'reference'"):
        Simulation(m2)
    m3 = Model()
    m3.add_box((0, 0, 0), (0.2, 0.1, 0.1), JointLaw.reference())
    with pytest.raises(ModelError, match=r"block 0: material must be a PlasticDamage, got Joint"):
        Simulation(m3)
    with pytest.raises(OptionsError, match=r"options must be a SolverOptions, got str"):
        Simulation(m, options="fast")
    with pytest.raises(LoadingError, match=r"give blocks or nodes \(one of them\)"):
        sim.rigid_point("r", blocks=[top], nodes=[0])       # the blocks were ignored
    with pytest.raises(LoadingError, match=r"fix: dofs='' must be a string"):
        sim.fix([0], dofs="")
    with pytest.raises(LoadingError, match=r"stages must be a non-empty list of Stage"):
        sim.run([])                                         # was KeyError: 'increment'


def test_controls_on_one_dof_and_bad_pressure_quads_are_refused_at_run():
    m, sim, base, top = _sim()
    rp = sim.rigid_point("top", blocks=[top])
    two = Stage("s", 1, [Displacement(target=rp, dof="x", to=1e-4),
                         Force(target=rp, dof="x", to=10.0)])    # the last one used to win
    with pytest.raises(LoadingError, match=r"stage 's': controls Displacement and Force both act "
                                           r"on DOF 0 of 'top'"):
        sim.run([two])
    far = Stage("p", 1, [Load(pattern=Pressure(np.array([[0, 1, 2, 10**6]])), to=1.0)])
    with pytest.raises(LoadingError, match=r"node id 1000000 in quads, the model has 24 nodes"):
        sim.run([far])


def test_fields_changed_after_creation_are_checked_at_run():
    """Options, stages, controls and patterns are checked when made; a field changed afterwards
    (``sim.options.increments.max_iter = 2.5``) is checked again when the run starts: it had hung in the
    relaxation (2.5), raised a Numba TypingError (alpha 'x'), a KeyError (damping 'viscus'), a
    ZeroDivisionError (frames 0) or an AttributeError (a string among the controls). A field
    set by its flat name on the options (not in its group) is refused, not silently kept."""
    def run(change_options=None, change_stage=None):
        m, sim, base, top = _sim()
        rp = sim.rigid_point("top", blocks=[top])
        stage = Stage("s", 1, [Force(target=rp, dof="z", to=-10.0),
                               Load(pattern=Gravity(), to=1.0)])
        for k, v in (change_options or {}).items():
            group, field = FLAT[k]
            setattr(getattr(sim.options, group), field, v)
        if change_stage:
            change_stage(stage)
        sim.run([stage])
    for change, msg in ((dict(max_iter=2.5), r"max_iter=2.5: must be an integer"),
                        (dict(alpha="x"), r"alpha='x'"),
                        (dict(damping="viscus"), r"damping='viscus': valid values"),
                        (dict(tol=-1.0), r"tol=-1.0")):
        with pytest.raises(OptionsError, match=msg):
            run(change_options=change)
    with pytest.raises(OptionsError, match=r"set options.increments.max_iter"):
        SolverOptions().max_iter = 10
    for change, msg in ((lambda st: setattr(st, "frames", 0), r"frames=0 must be an integer"),
                        (lambda st: setattr(st.controls[0], "to", np.nan), r"to=nan"),
                        (lambda st: setattr(st.controls[1].pattern, "g", np.nan), r"g=nan"),
                        (lambda st: st.controls.append("x"), r"controls must be a list")):
        with pytest.raises(LoadingError, match=msg):
            run(change_stage=change)


def test_controls_and_supports_belong_to_the_simulation_and_its_set_up():
    """A control on another simulation's rigid point had silently driven this one's point of
    that index; fix() after a run was silently ignored; a closed file silently stopped the
    writing; a pattern that loads nothing free ran with no load; a non-zero displacement on a
    fixed node moved the support; a model of fixed blocks only gave NaN residuals."""
    m1, sim1, base1, top1 = _sim()
    other = sim1.rigid_point("left", blocks=[top1])
    m, sim, base, top = _sim()
    sim.rigid_point("right", blocks=[top])
    with pytest.raises(LoadingError, match=r"control Displacement: rigid point 'left' is not one "
                                           r"of this simulation's"):
        sim.run([Stage("s", 1, [Displacement(target=other, dof="z", to=-1e-7)])])
    with pytest.raises(LoadingError, match=r"PointLoad 'p': rigid point 'left' is not one"):
        sim.run([Stage("s", 1, [Load(pattern=PointLoad(other, "z", 1.0, name="p"), to=1.0)])])
    for pattern in (BodyForce((1.0, 0.0, 0.0), blocks=[base]), Pressure(m.block_face(base, 1)[1])):
        with pytest.raises(LoadingError, match=r"puts no force on any free DOF"):
            sim.run([Stage("s", 1, [Load(pattern=pattern, to=1.0)])])
    with pytest.raises(LoadingError, match=r"Combined 'combined': parts must be a non-empty"):
        Combined([])
    held = sim1.node_set("held", m1.block_nodes([base1])[:2])
    sim1.run([Stage("zero", 1, [Displacement(target=held, dof="x", to=0.0)])])  # a reaction: ok
    with pytest.raises(LoadingError, match=r"node 0 \(block 0\) is fixed in x .* would move a "
                                           r"support"):
        sim1.run([Stage("move", 1, [Displacement(target=held, dof="x", to=1e-4)])])
    for late, what in ((lambda: sim1.fix([5]), "fix"),
                       (lambda: sim1.node_set("late", [5]), "node set 'late'"),
                       (lambda: sim1.contact_reaction("r", [top1], [base1]), "contact reaction 'r'"),
                       (lambda: sim1.rigid_point("p2", nodes=[5]), "rigid point 'p2'")):
        with pytest.raises(LoadingError, match=rf"{what} must be set before the first run"):
            late()
    fixed = Model()
    fixed.add_box((0, 0, 0), (0.2, 0.1, 0.1), MAT, (2, 1, 1), fixed=True)
    with pytest.raises(ModelError, match=r"every node is fixed"):
        Simulation(fixed).run([Stage("g", 1, [Load(pattern=Gravity(), to=1.0)])])


def test_a_closed_simulation_does_not_run_on(tmp_path):
    m, sim, base, top = _sim()
    sim = Simulation(m, SolverOptions(tol=1e-6), output=str(tmp_path / "c.h5"))
    rp = sim.rigid_point("top", blocks=[top])
    stage = Stage("s", 1, [Displacement(target=rp, dof="z", to=-1e-8)])
    sim.run([stage])
    sim.close()
    with pytest.raises(ResultsError, match=r"c.h5 was closed \(Simulation.close\)"):
        sim.run([stage])


def test_result_files_missing_parts_and_damaged_checkpoints_are_named(tmp_path):
    p = tmp_path / "r.h5"
    write_fake_result(p)
    for group in ("history", "frames", "model/nodes"):
        q = tmp_path / (group.replace("/", "_") + ".h5")
        shutil.copy(p, q)
        with h5py.File(q, "a") as f:
            del f[group]
        with pytest.raises(ResultsError, match=rf"is damaged: it lacks {group}"):
            open_result(q)
        assert main(["info", str(q)]) == 2 and main(["vtk", str(q)]) == 2
    (tmp_path / "dir.h5").mkdir()
    with pytest.raises(ResultsError, match=r"is a directory"):
        open_result(tmp_path / "dir.h5")
    with pytest.raises(ResultsError, match=r"cannot create the output folder .*file\.txt"):
        (tmp_path / "file.txt").write_text("")
        make_folder(str(tmp_path / "file.txt"))
    assert main(["vtk", str(p), str(tmp_path / "vtk"), "--warp", "nan"]) == 2
    q = tmp_path / "nan.h5"              # a NaN in a frame was written to the VTK points
    shutil.copy(p, q)
    with h5py.File(q, "a") as f:
        f["frames/000002/U"][0, 0] = np.nan
    with pytest.raises(ResultsError, match=r"frame 1 field U holds non-finite values"):
        open_result(q).frame(1)
    assert main(["vtk", str(q), str(tmp_path / "vtk2")]) == 2


@pytest.mark.filterwarnings("ignore:increment 2:RuntimeWarning")   # two large push steps
def test_scene_parameters_and_resume_are_checked(tmp_path, capsys):
    """Through ``dr-masonry run``: exit status 2 and one line naming the parameter."""
    out = str(tmp_path / "w")
    cases = [
        (["run", "couplet", "tol=-1"], "SolverOptions.tol=-1.0"),        # was a traceback
        (["run", "squat_wall", "fast=true", "height=0"], "parameter height=0.0"),  # was 1 course
        (["run", "squat_wall", "fast=true", "out="], "parameter out=''"),
        (["run", "squat_wall", "fast=true", f"out={tmp_path}/"], "must name the results' path"),
        (["run", "couplet", "out="], "parameter out=''"),
        (["run", "squat_wall", "fast=true", "drift=nan"], "drift='nan': cannot convert to float"),
        (["run", "triplet", "sigmas=-0.2"], "parameter sigmas=(-0.2,)"),  # tension: ran away
        (["run", "triplet", "sigmas="], "at least one pre-compression"),
        (["run", "joint", "steps=0"], "parameter steps=0"),               # wrote empty CSVs
        (["run", "joint", "sigmas_MPa=abc"], "parameter sigmas_MPa='abc'"),
        (["run", "squat_wall", "fast=true", f"out={tmp_path}/f.txt/w"], "cannot create"),
        # a parameter of the other protocol was ignored: a monotonic run for a cyclic one
        (["run", "squat_wall", "fast=true", "protocol=cyclic", "increments=100"],
         "parameter increments=100 shapes the monotonic path only; this run is protocol=cyclic"),
        (["run", "terraced_house", "step=-0.001"],
         "parameter step=-0.001 shapes the cyclic path only; this run is protocol=monotonic"),
        (["run", "squat_wall", "fast=true", "drift=0"], "monotonic target must be a finite "
                                                         "nonzero value"),   # ran a null push
    ]
    (tmp_path / "f.txt").write_text("")
    for argv, msg in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert msg in err and "Traceback" not in err, (argv, err)
    # a complete run is not run again by resume=true
    args = ["run", "squat_wall", "fast=true", "increments=2", "pre_increments=1", f"out={out}"]
    assert main(args) == 0
    rows = open_result(out + ".h5").history["increment"].size
    assert main(args + ["resume=true"]) == 2
    assert "is complete (3 rows" in capsys.readouterr().err
    assert open_result(out + ".h5").history["increment"].size == rows == 3


@pytest.mark.parametrize("damage, msg", [
    (lambda g: g.__delitem__("U"), r"checkpoint of .* is damaged: it lacks U"),
    (lambda g: g["s_joints"].__setitem__((0, 0), np.nan), r"s_joints holds 1 non-finite values"),
    (lambda g: g["contacts/master"].__setitem__((0, 0), 10**6),
     r"contacts/master: indices outside \[0, 24\)"),
    (lambda g: g.attrs.__delitem__("meta"), r"its attribute meta is missing"),
])
def test_a_damaged_checkpoint_is_named_on_resume(tmp_path, damage, msg):
    """A NaN in the checkpoint used to stop the continued run as an 'unstable time step', a
    missing array as a KeyError and an out-of-range contact as a numpy error."""
    path = str(tmp_path / "run.h5")

    def setup(output):
        m, _, base, top = _sim()
        return Simulation(m, SolverOptions(tol=1e-6), output=output)
    stages = [Stage("gravity", 2, [Load(pattern=Gravity(), to=1.0)])]
    sim = setup(path)
    sim.run(stages)
    sim.close()
    with h5py.File(path, "a") as f:
        damage(f["checkpoint"])
    with pytest.raises(ResultsError, match=msg):
        setup(path).resume(path)


def test_model_and_simulation_arguments_of_the_wrong_kind_are_named():
    """Plain Python errors before (could not convert string to float, IndexError, TypeError,
    AttributeError, a 7 PiB MemoryError): each names the argument and the value now."""
    from dr_masonry.geometry import BrickSpec, GeometryError, plane_nodes
    m = Model()
    for call, msg in ((lambda: m.add_box((0, 0, 0), "abc", MAT), r"block 0: box size must be "
                                                                 r"numbers in m, got 'abc'"),
                      (lambda: m.add_box((0, 0), (1, 1, 1), MAT), r"box origin must have shape"),
                      (lambda: m.add_block("abc", MAT), r"block 0: corners must be numbers"),
                      (lambda: m.add_box((0, 0, 0), (1, 1, 1), MAT, (10 ** 5,) * 3),
                       r"make 1,000,000,000,000,000 hexahedra, more than MAX_BLOCK_ELEMENTS"),
                      (lambda: m.block("0"), r"block '0' does not exist"),
                      (lambda: m.check_overlaps("x"), r"tol='x' must be a finite length")):
        with pytest.raises(ModelError, match=msg):
            call()
    m, sim, base, top = _sim()
    for call, msg in ((lambda: plane_nodes(m, 2.0, 0.0), r"axis must be 0, 1 or 2, got 2.0"),
                      (lambda: plane_nodes(m, 2, "top"), r"value must be a finite coordinate"),
                      (lambda: BrickSpec(nx_along=None), r"nx_along must be an integer >= 1"),
                      (lambda: BrickSpec(nz_height=float("nan")), r"nz_height must be an integer")):
        with pytest.raises(GeometryError, match=msg):
            call()
    with pytest.raises(ModelError, match=r"Simulation: model must be a Model, got None"):
        Simulation(None)
    with pytest.raises(OptionsError, match=r"config must be a dict"):
        Simulation(m, config=[1, 2])
    with pytest.raises(ResultsError, match=r"output must be a file path or None, got 5"):
        Simulation(m, output=5)
    for name in (None, 5, ""):
        with pytest.raises(LoadingError, match=r"must be non-empty strings"):
            sim.node_set(name, [5])
    with pytest.raises(LoadingError, match=r"contact reaction 'c': blocks: id 7 is not an "
                                           r"integer in \[0, 2\)"):   # was "no joint between"
        sim.contact_reaction("c", [7], [0])
    with pytest.raises(LoadingError, match=r"contact reaction 'c': support: id 'wall'"):
        sim.contact_reaction("c", [1], "wall")
    with pytest.raises(LoadingError, match=r"fix: id None is not an integer"):   # AttributeError
        sim.fix(None)
    for path in (None, 5):
        with pytest.raises(ResultsError, match=r"a results file must be given as a path"):
            open_result(path)
    sim.monitors.append("print")                       # a TypeError once the run started
    with pytest.raises(OptionsError, match=r"monitors: 'print' is not a function"):
        sim.run([Stage("s", 1, [Load(pattern=Gravity(), to=1.0)])])


def test_resume_of_a_file_of_another_model_of_the_same_sizes_is_refused(tmp_path):
    """Only the node, element and contact counts were compared: a longer block, another
    material or joint law resumed the other model's state with a few energy-balance warnings."""
    path = str(tmp_path / "base.h5")

    def build(length=0.2, mat=MAT, law=JointLaw.dry(0.5)):
        m = Model()
        m.set_joint_law(law)
        m.add_box((0, 0, 0), (length, 0.1, 0.1), mat, (2, 1, 1), fixed=True)
        top = m.add_box((0, 0, 0.1), (length, 0.1, 0.1), mat, (2, 1, 1))
        sim = Simulation(m, SolverOptions(tol=1e-6))
        rp = sim.rigid_point("top", blocks=[top])
        return sim, [Stage("s", 2, [Displacement(target=rp, dof="z", to=-1e-8)])]
    sim, stages = build()
    sim.output = path
    sim.run([Stage("s", 1, stages[0].controls)])
    sim.close()
    for change, msg in ((dict(length=0.4), r"node 2 lies 0.2 m from where it was"),
                        (dict(mat=PlasticDamage.elastic(20e9, 0.2, 2000.0)),
                         r"material 0 differs in E 10000000000.0 -> 20000000000.0"),
                        (dict(law=JointLaw.dry(0.6)), r"joint law 0 differs in .*mu 0.5 -> 0.6")):
        other, stages = build(**change)
        with pytest.raises(ResultsError, match=msg + r" \(not the model the file was run with\)"):
            other.resume(path)
    same, stages = build()
    same.resume(path)
    assert same.run(stages)["top.uz"][-1] == pytest.approx(-1e-8)
