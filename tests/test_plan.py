"""The plan (``ks_jax.backend.Plan``): how rows are computed is data, made at the entry points and passed down
as a static argument, never state of the process (docs/devices.md). On a CPU the accelerator's plan is taken
to exercise its logic, with the CPU's values; the physics' one CPU-only form is the platform's choice."""

from __future__ import annotations

import ast
import json
import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import export

import fit
import ks_jax
from ks_jax.backend import Plan, checked_devices, plan_for
from ks_jax.cli import main
from ks_jax.model.packing import Packing
from ks_jax.model import linalg as la
from ks_jax.solve import cases as solve_cases
from samples import assert_json_close

MODEL = Path(ks_jax.__file__).parent / "model"
CASES = Path(ks_jax.__file__).parent / "cases"


def test_a_plan_is_a_value_and_bad_plans_are_refused():
    """Equal plans are one key (hashable, compared by value, a repr without an address: a kept program's key
    holds it); a path other than the two, or a chunk that is not a positive whole number, is refused with the
    value and the rule."""
    assert Plan("cpu") == Plan() == plan_for("cpu") and hash(Plan("accelerator", 8)) == hash(Plan("accelerator", 8))
    assert len({Plan("cpu"), Plan("accelerator"), Plan("cpu", 64)}) == 3
    assert repr(Plan("accelerator")) == "Plan(path='accelerator', chunk_rows=None)"
    assert plan_for(Plan("accelerator", 8)) == Plan("accelerator", 8)
    with pytest.raises(ValueError, match="plan path = 'gpu': must be 'cpu' or 'accelerator'"):
        Plan("gpu")
    for bad in (0, -3, 2.5, True):
        with pytest.raises(ValueError, match=f"plan chunk_rows = {bad!r}: must be a positive whole number"):
            Plan("cpu", bad)


def test_the_default_plan_is_the_devices_path():
    """Without a plan, the devices the rows go to decide: the CPU's path where they are all CPUs."""
    cpus = jax.devices("cpu")
    assert plan_for(None, cpus) == Plan("cpu")
    expected = "cpu" if all(d.platform == "cpu" for d in jax.devices()) else "accelerator"
    assert plan_for() == Plan(expected)


def test_devices_that_are_not_a_list_of_jax_devices_are_refused_before_any_work():
    """The devices a fit or a sweep splits its rows over are JAX devices, at least one, each once: anything else
    is refused by the entry point with its name, the value and the rule, before a case is checked or a row
    solved (not an error from inside the mesh); a list, a tuple or an iterator of devices, or None (this
    process's), is taken as it is."""
    d = jax.devices()[0]
    case = ks_jax.load_case(CASES / "fit_seed_001.json")
    refused = [([], ValueError, r"devices = \[\]: give at least one JAX device"),
               ("cpu", TypeError, r"devices = 'cpu': give a list of JAX devices .* plan='cpu'"),
               (d, TypeError, r"devices = .*: give a list of JAX devices"),
               ([1], TypeError, r"devices holds 1: each must be a JAX device"),
               ([d, d], ValueError, r"devices = \[.*\]: each device once")]
    for bad, kind, rule in refused:
        with pytest.raises(kind, match="reconstruct_batch: " + rule):
            fit.reconstruct_batch([case], devices=bad)
        with pytest.raises(kind, match="sweep: " + rule):
            ks_jax.sweep(case, {"vehicles[0].speed": [10.0, 20.0]}, devices=bad)
    assert checked_devices([d], "x") == checked_devices((d,), "x") == checked_devices(iter([d]), "x") == (d,)
    assert checked_devices(None, "x") == tuple(jax.local_devices())
    once = fit.reconstruct_batch([case], devices=iter([d]))[0]  # an iterator is read once, and its devices used
    assert once.status == "ok" and once.estimate == fit.reconstruct_batch([case])[0].estimate


def _imported_modules(path: Path) -> set[str]:
    """Every module a file imports, relative imports resolved against ``ks_jax.model``."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = "ks_jax.model" if node.level == 1 else "ks_jax" if node.level == 2 else ""
            module = ".".join(p for p in (base, node.module or "") if p)
            names.add(module)
            names |= {f"{module}.{a.name}" for a in node.names}
    return names


def test_the_physics_knows_nothing_of_devices():
    """No module of ``ks_jax.model`` imports ``ks_jax.backend`` or asks JAX which devices or backend there are."""
    files = sorted(MODEL.glob("*.py"))
    assert len(files) > 10
    for path in files:
        imported = _imported_modules(path)
        assert not [m for m in imported if m.startswith("ks_jax.backend")], path.name
        text = path.read_text()
        for asked in ("default_backend", "jax.devices", "local_devices", "KS_JAX_PATH"):
            assert asked not in text, (path.name, asked)


def test_stored_sines_are_the_cpus_and_plain_elsewhere():
    """``materialize`` (the sines and cosines stored once) is chosen by the platform a program is lowered for:
    the same function lowered for a CPU holds the stored values' reduction, lowered for a GPU it does not; on
    the CPU the values are unchanged."""
    x = jax.ShapeDtypeStruct((16,), jnp.float64)
    program = jax.jit(la.sincos)
    cpu = export.export(program, platforms=["cpu"])(x).mlir_module()
    gpu = export.export(program, platforms=["cuda"])(x).mlir_module()
    assert "stablehlo.reduce" in cpu and "stablehlo.reduce" not in gpu
    angles = np.linspace(-7.0, 7.0, 16)
    stored = jax.jit(lambda a: la.materialize(a, 2 * a))(angles)
    np.testing.assert_array_equal(stored[0], angles)
    np.testing.assert_array_equal(stored[1], 2 * angles)
    plain = jax.jit(lambda a: la.materialize(a, everywhere=True))(angles)[0]
    np.testing.assert_array_equal(plain, angles)


@pytest.mark.slow
def test_a_solve_on_either_path_gives_the_same_numbers_from_programs_kept_apart():
    """The seed chapter's automatic-contact case solved on the CPU's path and on the accelerator's (forced on
    this device): the CPU's fences its first stage (a conditional), the accelerator's does not, and every
    number is the same. The plan is a static argument of the compiled solve, so each path has its own program
    and its own key among kept programs."""
    case = ks_jax.load_case(CASES / "auto_seed_000.json")
    on_cpu, on_accelerator = (ks_jax.solve(case, plan=p) for p in ("cpu", Plan("accelerator")))
    for a, b in zip(jax.tree_util.tree_leaves(on_cpu.result), jax.tree_util.tree_leaves(on_accelerator.result)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-13, atol=1e-13)
    assert on_cpu.status == on_accelerator.status

    def jaxpr(plan):
        solve = functools.partial(ks_jax.solve_inputs, auto_point=True, auto_normal=True, plan=plan)
        return str(jax.make_jaxpr(solve)(case.inputs))

    assert jaxpr("cpu").count("cond[") > jaxpr("accelerator").count("cond[")
    stored = solve_cases._solve.quick
    leaves, tree = jax.tree_util.tree_flatten(case.inputs)
    keys = {stored._key({"plan": plan, "auto_point": True}, tree, leaves)
            for plan in (Plan("cpu"), Plan("accelerator"))}
    assert len(keys) == 2 and None not in keys


@pytest.mark.slow
def test_the_command_line_reads_the_path_once_and_passes_it_down(monkeypatch, capsys):
    """``KS_JAX_PATH=accelerator`` is read by the command line and given to the library as a plan: the solve
    runs on the accelerator's path (here, on a CPU) with the same results as without it (to rounding: XLA fuses
    the accelerator's program differently)."""
    seen = []
    original = solve_cases.plan_for

    def recording(plan=None, devices=None):
        seen.append(plan)
        return original(plan, devices)

    monkeypatch.setattr(solve_cases, "plan_for", recording)
    case = str(CASES / "auto_seed_000.json")
    assert main(["solve", case, "--json"]) == 0
    plain = capsys.readouterr().out
    monkeypatch.setenv("KS_JAX_PATH", "accelerator")
    assert main(["solve", case, "--json"]) == 0
    assert_json_close(json.loads(capsys.readouterr().out), json.loads(plain))
    assert seen == [None, Plan("accelerator")]


def _products_without_precision(source, name):
    """Where source text multiplies arrays by ``@`` or calls matmul, dot, einsum or tensordot without a
    ``precision``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
            found.append(f"{name}:{node.lineno}: @")
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and \
                node.func.attr in ("matmul", "dot", "einsum", "tensordot") and \
                isinstance(node.func.value, ast.Name) and node.func.value.id == "jnp" and \
                "precision" not in {k.arg for k in node.keywords}:
            found.append(f"{name}:{node.lineno}: jnp.{node.func.attr}")
    return found


def test_every_product_of_arrays_asks_for_its_dtypes_full_precision():
    """An accelerator may compute a float32 matrix product in TF32 (a 10-bit mantissa) unless asked otherwise: the
    physics and the fit's solver multiply arrays only through ``linalg.mm`` or with an explicit precision."""
    files = sorted(MODEL.rglob("*.py")) + [Path(ks_jax.__file__).parents[1] / "fit" / "solvers.py"]
    assert len(files) > 15
    assert [f for path in files for f in _products_without_precision(path.read_text(), path.name)] == []
    caught = _products_without_precision("a @ b\njnp.einsum('ij,j', a, b)\njnp.dot(a, b, precision=p)", "s")
    assert caught == ["s:1: @", "s:2: jnp.einsum"]


@pytest.mark.slow
def test_a_solve_lowered_for_a_gpu_asks_every_product_for_full_precision():
    """The solves of a case with automatic contact, a later exchange and motion to rest (tbone_spin_out.json) and
    of an articulated one (docs/examples/semi_trailer_side_impact.json), lowered for a GPU from this machine:
    every dot_general of their programs carries the highest precision."""
    examples = Path(ks_jax.__file__).parents[1] / "docs" / "examples"
    for path in (CASES / "tbone_spin_out.json", examples / "semi_trailer_side_impact.json"):
        case = ks_jax.load_case(path)
        case = case[0] if isinstance(case, list) else case
        rows = jax.tree_util.tree_map(lambda x: jnp.asarray(x)[None], case.inputs)
        program = jax.jit(functools.partial(solve_cases._solve_rows, auto_point=case.auto_point,
                                            auto_normal=case.auto_normal, smoothing=0.0, pole=case.pole,
                                            motion=case.motion, between=case.between, plan=Plan("accelerator")))
        text = export.export(program, platforms=["cuda"])(rows).mlir_module()
        dots = [line for line in text.splitlines() if "stablehlo.dot_general" in line]
        assert dots, path.name
        assert all("precision = [HIGHEST, HIGHEST]" in line for line in dots), (path.name, dots[:3])


def test_packing_the_watched_motions_state_gives_back_every_leaf_as_it_was():
    """``model.packing.Packing`` (the accelerator's path) puts a tree's leaves side by side, one flat array per dtype,
    and takes them back: every leaf's values (inf and NaN among them), shape and dtype as they were, whatever the
    order of the dtypes among the leaves; on the CPU's path the tree is carried as it is, the same object."""
    tree = {"a": jnp.arange(6.0).reshape(2, 3), "b": jnp.array([1, -2], jnp.int32), "c": jnp.array(True),
            "d": (jnp.array([jnp.inf, jnp.nan, -0.0]), None, jnp.zeros((0, 2))), "e": jnp.array(7, jnp.int32),
            "f": jnp.array([[False, True]])}
    packing = Packing(tree, True)
    packed = packing.pack(tree)
    assert [(x.dtype.name, x.shape) for x in packed] == [("bool", (3,)), ("float64", (9,)), ("int32", (3,))]
    back = packing.unpack(packed)
    assert jax.tree_util.tree_structure(back) == jax.tree_util.tree_structure(tree)
    for x, y in zip(jax.tree_util.tree_leaves(tree), jax.tree_util.tree_leaves(back)):
        assert x.dtype == y.dtype and x.shape == y.shape
        np.testing.assert_array_equal(x, y)
    assert np.signbit(back["d"][0][2])  # -0.0 kept
    plain = Packing(tree, False)
    assert plain.pack(tree) is tree and plain.unpack(tree) is tree and plain.fenced(tree) is tree


def _largest_loop(jaxpr) -> int:
    """The most values any while loop of ``jaxpr`` (nested ones included) carries."""
    most = 0
    for eqn in jaxpr.eqns:
        if eqn.primitive.name == "while":
            most = max(most, len(eqn.params["body_jaxpr"].jaxpr.outvars))
        for value in eqn.params.values():
            for sub in value if isinstance(value, (tuple, list)) else (value,):
                sub = getattr(sub, "jaxpr", sub)  # a closed jaxpr's own
                if hasattr(sub, "eqns"):
                    most = max(most, _largest_loop(sub))
    return most


@pytest.mark.slow
def test_a_watched_motion_on_the_accelerators_path_carries_its_state_packed_to_the_same_fit():
    """``fit_rest_positions.json`` (two speeds from the rest positions, through the watched motion after the first
    exchange) fitted on the CPU's path and on the accelerator's (forced on this device): the accelerator's watched
    motion carries its state packed, a few flat arrays where the CPU's carries the loop's own dozens, and the
    estimates, their standard deviations (from forward-mode derivatives through the loop) and the fitted rest
    positions are the same to rounding (the two programs are fused differently)."""
    case = ks_jax.load_case(CASES / "fit_rest_positions.json")
    case = case[0] if isinstance(case, list) else case
    on_cpu, on_accelerator = (fit.reconstruct(case, plan=p) for p in ("cpu", Plan("accelerator")))
    assert on_cpu.status == on_accelerator.status == "ok"
    for field in ("estimate", "std", "fitted"):
        a, b = getattr(on_cpu, field), getattr(on_accelerator, field)
        assert a.keys() == b.keys()
        np.testing.assert_allclose([b[k] for k in a], list(a.values()), rtol=1e-7, err_msg=field)

    def carried(plan):
        solve = functools.partial(ks_jax.solve_inputs, auto_point=case.auto_point, auto_normal=case.auto_normal,
                                  pole=case.pole, motion=case.motion, between=case.between, plan=plan)
        return _largest_loop(jax.make_jaxpr(solve)(case.inputs).jaxpr)

    cpu, accelerator = carried("cpu"), carried("accelerator")
    assert cpu > 30 and accelerator < 8, (cpu, accelerator)
