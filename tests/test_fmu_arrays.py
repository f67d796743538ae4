"""FMI 3.0 array variables (``<Dimension>``): exposed as their elements ``u[1]``, ``A[2,3]``.

The fixture ``tests/fixtures/fmu/matvec3`` (C against the FMI 3.0 API) computes
``y = k A u`` (``u``, ``y``: Float64[3] in mm, ``A``: a 3 x 3 parameter, row-major)
and ``z[i] = w[1] + ... + w[i]`` (``w``, ``z``: Float64[n], ``n`` a structural
parameter with start 4) from the inputs held at the start of each step, and
counts in ``sets_u`` the ``fmi3SetFloat64`` calls that wrote ``u``. It refuses
(fmi3Error) every get/set call whose ``nValues`` is not the sum of the sizes of
the value references it names, so a run that succeeds exchanged each array in
one call with all its elements. ``sgn`` (Int32[3], the sign of ``y``) is an array
of another type, which the compiled loop reads after every step (the values the
components hold afterwards are compared with the Python loop's). Expected
numbers are the matrix products written out by hand below.
"""
from __future__ import annotations

import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from orchestrator import Probe, System
from orchestrator.errors import SystemDescriptionError
from orchestrator.fmu import FMUComponent, FMUError, check_fmu
from orchestrator.fmu.isolated import IsolatedFMUComponent
from orchestrator.ssp import build_system, read_ssd, system_to_ssp

sys.path.insert(0, str(Path(__file__).resolve().parent / "fixtures" / "fmu"))
import cfmu  # noqa: E402

from tests.test_fmu_units import _compile, scale_xml  # noqa: E402
from tests.test_master_fast_fmu import _both  # noqa: E402
from tests.test_master_fast_fmu import fast_runs  # noqa: E402,F401 (fixture)

pytestmark = pytest.mark.skipif(cfmu.compiler() is None, reason="no C compiler")

XML = (cfmu.HERE / "matvec3" / "modelDescription.xml").read_text()
#: a's matrix (set whole), b's: identity with A[1,1] = 2 (set by element) and k = 0.5
A_A = [[1.0, 2.0, 0.0], [0.0, 1.0, 3.0], [0.5, 0.0, 1.0]]


@pytest.fixture(scope="module")
def matvec3(tmp_path_factory) -> Path:
    return cfmu.build_c_fmu(cfmu.HERE / "matvec3", tmp_path_factory.mktemp("matvec3"), stubs=True)


def _zip(path: Path, xml: str) -> Path:
    """An archive with ``xml`` and a placeholder binary (never loaded: variables are bound first)."""
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("modelDescription.xml", xml)
        zf.writestr("binaries/x86_64-linux/MatVec3.so", "x")
    return path


# ----------------------------------------------------------------------------- one instance
def test_elements_are_scalars_with_structured_names_units_and_start_values(matvec3):
    c = FMUComponent(matvec3, "m")
    try:
        assert c.names("input") == ["u[1]", "u[2]", "u[3]", "w[1]", "w[2]", "w[3]", "w[4]"]  # n = 4 (its start)
        assert c.names("output") == ["y[1]", "y[2]", "y[3]", "z[1]", "z[2]", "z[3]", "z[4]", "sets_u",
                                     "sgn[1]", "sgn[2]", "sgn[3]"]
        assert c.variable("sgn[2]").type == "Integer"
        assert c.names("parameter") == [f"A[{i},{j}]" for i in (1, 2, 3) for j in (1, 2, 3)] + ["k"]
        assert {c.variable(n).unit for n in ("u[1]", "u[3]", "y[2]")} == {"mm"}
        assert c.variable("w[4]").unit == "N" and c.variable("A[2,3]").unit is None
        np.testing.assert_array_equal(c.get("u"), [1.0, 2.0, 3.0])    # start="1 2 3"
        np.testing.assert_array_equal(c.get("A"), np.eye(3))          # start="1 0 0 0 1 0 0 0 1", row-major
        np.testing.assert_array_equal(c.get("w"), [0.0] * 4)          # start="0": one value for every element
        c.set("A", [[0, 1, 0], [0, 0, 1], [1, 0, 0]])                 # whole array
        c.set("A[3,1]", 4.0)                                          # one element
        c.set("k", 2.0)
        c.setup(0.0)
        # y = k A u with u = (1, 2, 3): 2 * (2, 3, 4 * 1)
        np.testing.assert_array_equal(c.get("y"), [4.0, 6.0, 8.0])
        c.set("u", [1.0, 0.5, 0.25])
        c.set("w", [1.0, 2.0, 3.0, 4.0])
        c.do_step(0.0, 1e-3)
        np.testing.assert_array_equal(c.get("y"), [1.0, 0.5, 8.0])
        np.testing.assert_array_equal(c.get("z"), [1.0, 3.0, 6.0, 10.0])
        assert c.get("sets_u")[0] == 2.0  # setup and the step: one call each, with all three values
        c.set("u", [-1.0, 0.0, 0.25])
        c.do_step(1e-3, 1e-3)
        np.testing.assert_array_equal(c.get("y"), [0.0, 0.5, -8.0])
        np.testing.assert_array_equal(c.get("sgn"), [0, 1, -1])  # Int32[3], read in one fmi3GetInt32
    finally:
        c.close()


def test_bad_element_names_are_errors_naming_the_array_and_its_shape(matvec3, tmp_path):
    c = FMUComponent(matvec3, "m")
    try:
        with pytest.raises(FMUError, match=r"no variable 'u\[4\]' \('u' is an array of shape 3 \(elements u\[1\] "
                                           r"\.\. u\[3\]\): 'u\[4\]' is outside it\)"):
            c.set("u[4]", 1.0)
        with pytest.raises(FMUError, match=r"'A' is an array of shape 3x3 \(elements A\[1,1\] \.\. A\[3,3\]\): "
                                           r"'A\[2\]' has 1 index\(es\), expected 2"):
            c.variable("A[2]")
        with pytest.raises(FMUError, match=r"'A' is an array of shape 3x3; got a value of shape \(2, 2\)"):
            c.set("A", np.eye(2))
        system = System("s")
        system.add(c)
        with pytest.raises(SystemDescriptionError, match=r"m.y\[0\]: .*no variable 'y\[0\]' \('y' is an array of "
                                                         r"shape 3"):
            system.connect("m.y[0]", "m.u[1]")
    finally:
        c.close()
    with pytest.raises(FMUError, match=r"mapping 'pos' -> 'y\[7\]': the FMU has no variable 'y\[7\]' \('y' is an "
                                       r"array of shape 3 \(elements y\[1\] \.\. y\[3\]\): 'y\[7\]' is outside it\)"):
        FMUComponent(matvec3, "m", mapping={"pos": "y[7]"})
    dotted = _zip(tmp_path / "dotted.fmu", XML.replace('name="u"', 'name="in.u"'))  # not an identifier
    with pytest.raises(FMUError, match=r"array 'in\.u': elements \['in\.u\[1\]', 'in\.u\[3\]'\] have no name the "
                                       r"twin can address, and the array is exchanged whole; map the array"):
        FMUComponent(dotted, mapping={"p": "in.u[2]"})
    with pytest.raises(FMUError, match=r"start has 2 values; expected 9 \(its shape\) or 1"):
        FMUComponent(_zip(tmp_path / "bad.fmu", XML.replace('start="1 0 0 0 1 0 0 0 1"', 'start="1 0"')))


def test_mapping_renames_an_element_or_a_whole_array(matvec3):
    c = FMUComponent(matvec3, "m", mapping={"pos": "y[2]", "cmd": "u"}, parameters={"A": 2 * np.eye(3)})
    try:
        assert c.names("output")[:3] == ["y[1]", "pos", "y[3]"]
        assert c.names("input")[:3] == ["cmd[1]", "cmd[2]", "cmd[3]"]
        c.setup(0.0)
        assert (c.get("y[1]")[0], c.get("pos")[0], c.get("y[3]")[0]) == (2.0, 4.0, 6.0)
    finally:
        c.close()


def test_a_structural_parameter_that_the_fmu_reports_otherwise_is_refused(matvec3):
    """The fixture's instance named "resized..." reports n = 5 after instantiation; its start is 4."""
    with pytest.raises(FMUError, match=r"resized: array 'w': the FMU reports its dimension\(s\) n = 5 \(expected 4\) "
                                       r"after instantiation"):
        FMUComponent(matvec3, "resized")


def test_a_tunable_structural_parameter_is_refused(tmp_path):
    xml = XML.replace('causality="structuralParameter" variability="fixed"',
                      'causality="structuralParameter" variability="tunable"')
    with pytest.raises(FMUError, match=r"array 'w': its dimension is the tunable structural parameter 'n', which may "
                                       r"change in reconfiguration mode"):
        FMUComponent(_zip(tmp_path / "tunable.fmu", xml))


# ----------------------------------------------------------------------------- in a system, on both loops
def _expected(steps: int) -> dict[str, np.ndarray]:
    """The ring of :func:`_ring` by hand, Gauss-Seidel (a, then b), mm.

    a: u = (1, 2, s) with s = b.y[2] (b not yet initialised at a's set-up: s = 0);
       y = A_A u = (1 + 4, 2 + 3 s, 0.5 + s)
    b: u = (a.y[3], a.y[2], a.y[1]) (the elements crossed), A = diag(2, 1, 1), k = 0.5;
       y = 0.5 (2 (0.5 + s), 2 + 3 s, 5) = (0.5 + s, 1 + 1.5 s, 2.5)
    so s_{k+1} = 1 + 1.5 s_k from s_0 = 0.
    """
    s = [0.0]
    for _ in range(steps):
        s.append(1.0 + 1.5 * s[-1])
    s = np.array(s)
    return {"a_y2": 2.0 + 3.0 * s, "b_y1": 0.5 + s, "b_y2": 1.0 + 1.5 * s, "b_y3": np.full(steps + 1, 2.5)}


def _ring(fmu: Path, kind=FMUComponent) -> System:
    system = System("ring")
    system.add(kind(fmu, "a", parameters={"A": A_A}))
    system.add(kind(fmu, "b", parameters={"A[1,1]": 2.0, "k": 0.5}))
    for i in (1, 2, 3):
        system.connect(f"a.y[{i}]", f"b.u[{4 - i}]")
    system.connect("b.y[2]", "a.u[3]")
    return system


PROBES = [Probe("a_y2", "a.y[2]", "m"), Probe("b_y1", "b.y[1]"), Probe("b_y2", "b.y[2]"), Probe("b_y3", "b.y[3]"),
          Probe("sets", "b.sets_u"), Probe("z4", "a.z[4]")]


def test_matrix_products_in_a_ring_on_the_python_and_compiled_loops(matvec3, fast_runs):
    result, _ = _both(lambda: _ring(matvec3), PROBES, fast_runs, time_limit=0.006)
    assert result.success, result.message
    expected = _expected(6)
    np.testing.assert_allclose(result.recording["a_y2"], expected["a_y2"] * 1e-3, rtol=1e-15)  # probed in m
    for name in ("b_y1", "b_y2", "b_y3"):
        np.testing.assert_array_equal(result.recording[name], expected[name])
    np.testing.assert_array_equal(result.recording["sets"], np.arange(1, 8))  # one fmi3SetFloat64 of u a step
    np.testing.assert_array_equal(result.recording["z4"], 0.0)  # w unconnected: left at its start 0


def test_the_ring_survives_an_ssp_round_trip(matvec3, tmp_path, fast_runs):
    system = _ring(matvec3)
    system_to_ssp(system, tmp_path / "ring.ssd", tmp_path / "ring.ssv", fmu_sources={"a": str(matvec3),
                                                                                   "b": str(matvec3)})
    ssv = (tmp_path / "ring.ssv").read_text()
    assert '<ssv:Parameter name="a.A[3,1]">' in ssv and '<ssv:Parameter name="b.A[1,1]">' in ssv
    for c in system.components.values():
        c.close()

    def rebuilt() -> System:
        return build_system(read_ssd(tmp_path / "ring.ssd"), native=False)[0]

    first = rebuilt()
    np.testing.assert_array_equal(first.components["a"].get("A"), A_A)
    np.testing.assert_array_equal(first.components["b"].get("A"), np.diag([2.0, 1.0, 1.0]))
    assert [(c.source, c.target) for c in first.connections] == [
        ("a.y[1]", "b.u[3]"), ("a.y[2]", "b.u[2]"), ("a.y[3]", "b.u[1]"), ("b.y[2]", "a.u[3]")]
    for c in first.components.values():
        c.close()
    result, _ = _both(rebuilt, PROBES, fast_runs, time_limit=0.004)
    expected = _expected(4)
    for name in ("b_y1", "b_y2", "b_y3"):
        np.testing.assert_array_equal(result.recording[name], expected[name])


def test_isolated_component_with_arrays(matvec3):
    c = IsolatedFMUComponent(matvec3, "iso", parameters={"A[2,2]": 5.0})
    try:
        c.set("A", np.arange(9.0).reshape(3, 3))
        assert c.get("A")[2, 1] == 7.0
        c.setup(0.0)
        np.testing.assert_array_equal(c.get("y"), [8.0, 26.0, 44.0])  # (0 1 2; 3 4 5; 6 7 8) (1, 2, 3)
        c.set("u", [1.0, 0.0, 0.0])
        c.do_step(0.0, 1e-3)
        np.testing.assert_array_equal(c.get("y"), [0.0, 3.0, 6.0])
        with pytest.raises(FMUError, match=r"'u' is an array of shape 3 \(elements u\[1\] \.\. u\[3\]\): 'u\[4\]'"):
            c.variable("u[4]")
    finally:
        c.close()


# ----------------------------------------------------------------------------- check_fmu
def test_check_fmu_lists_arrays_and_runs_them(matvec3):
    report = check_fmu(matvec3, role="drive", mapping={"position": "y[2]"}, parameters={"A": 3 * np.eye(3)})
    shapes = {v.name: v.shape for v in report.variables}
    assert shapes["A"] == (3, 3) and shapes["w"] == (4,) and shapes["k"] == ()
    assert not report.problems and report.smoke_ok, report.to_text()
    assert report.smoke_outputs["y[3]"] == 9.0 and report.smoke_outputs["sets_u"] == 51.0  # set-up + 50 steps
    assert any("array 'w': dimension(s) 4 from structuralParameter 'n'" in n for n in report.notes)
    rows = {r.ours: r for r in report.role_rows}
    assert rows["position"].theirs == "y[2]" and rows["position"].status == "ok (converted: 1 m = 1000 mm)"
    text = report.to_text()
    assert "[array 3x3: A[1,1] .. A[3,3]]" in text


# ----------------------------------------------------------------------------- FMI 2.0: a[1] is a plain scalar
def test_fmi2_bracket_names_are_plain_scalars(tmp_path):
    """FMI 2.0 has no arrays: Scale (y = k u + c) with variables named u[1], y[1], k[2] exposes them as scalars,
    each its own value reference, and they still map to other names."""
    library = _compile("scale", cfmu.HERE / "units" / "scale.c", tmp_path)
    xml = (scale_xml(u0=2.0, k=3.0).replace('name="u"', 'name="u[1]"').replace('name="y"', 'name="y[1]"')
           .replace('name="k"', 'name="k[2]"'))
    path = tmp_path / "scale.fmu"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("modelDescription.xml", xml)
        zf.writestr("binaries/linux64/Scale.so", library)
    c = FMUComponent(path, "s")
    try:
        assert "u[1]" in c.names("input") and "y[1]" in c.names("output") and "k[2]" in c.names("parameter")
        c.setup(0.0)
        assert c.get("y[1]")[0] == 6.0
    finally:
        c.close()
    c = FMUComponent(path, "s", mapping={"gain": "k[2]"}, parameters={"gain": 0.5})
    try:
        c.setup(0.0)
        assert c.get("y[1]")[0] == 1.0
    finally:
        c.close()


def test_bare_fmu3_slaves_exchange_arrays_in_the_compiled_loop(matvec3):
    """FastFMULoop with fmpy FMU3Slave objects (no FMUComponent): the elements of an array are ports of their
    own, set and read in one call per array (the fixture refuses any other nValues).

    s (A = I, u = (1, 2, 3) at its start, unconnected) -> y = (1, 2, 3); t.u[1] <- s.y[3], t.u[2..3] keep
    their start (2, 3): t.y = (3, 2, 3) after the first step (the outputs follow the inputs of the step).
    """
    from orchestrator.fmu import fmi3
    from orchestrator.fmu.component import load_fmu
    from orchestrator.fmu.fast_loop import FastFMULoop

    loaded = load_fmu(matvec3)
    token = loaded.model_description.guid
    slaves, keep = {}, []
    for name in ("s", "t"):
        slave, *callbacks = fmi3.instantiate_co_simulation("MatVec3", token, loaded.unzip_dir, name,
                                                           lambda *a: None)
        slave.fmi3EnterInitializationMode(slave.component, False, 0.0, 0.0, False, 0.0)
        slave.fmi3ExitInitializationMode(slave.component)
        slaves[name] = slave
        keep.append(callbacks)
    try:
        loop = FastFMULoop(slaves, [("s.y[3]", "t.u[1]")], record=["t.y[1]", "t.y[2]", "t.y[3]", "t.sets_u"])
        result = loop.run(3, 1e-3)
        np.testing.assert_array_equal(result["t.y[1]"], [1.0, 3.0, 3.0, 3.0])  # row 0: initialised from u = (1, 2, 3)
        np.testing.assert_array_equal(result["t.y[2]"], 2.0)
        np.testing.assert_array_equal(result["t.y[3]"], 3.0)
        np.testing.assert_array_equal(result["t.sets_u"], [0.0, 1.0, 2.0, 3.0])
    finally:
        for slave in slaves.values():
            slave.fmi3Terminate(slave.component)
            slave.fmi3FreeInstance(slave.component)


def test_cnctwin_check_fmu_sets_and_maps_elements(matvec3, capsys):
    import argparse

    from orchestrator.cli_fmu import add_parsers

    parser = argparse.ArgumentParser(prog="cnctwin")
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["check-fmu", str(matvec3), "--set", "A[2,2]=3", "--set", "k=2", "--map", "pos=y[2]"])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "[array 3x3: A[1,1] .. A[3,3]]" in out and "[array 4: w[1] .. w[4]]" in out
    assert "with ['A[2,2]', 'k'] set" in out and "verdict: OK" in out


def test_check_fmu_reports_a_tunable_dimension_as_a_failed_smoke_run(matvec3, tmp_path):
    with zipfile.ZipFile(matvec3) as zf:
        library = zf.read("binaries/x86_64-linux/MatVec3.so")
    path = tmp_path / "tunable.fmu"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("modelDescription.xml", XML.replace('causality="structuralParameter" variability="fixed"',
                                                        'causality="structuralParameter" variability="tunable"'))
        zf.writestr("binaries/x86_64-linux/MatVec3.so", library)
    report = check_fmu(path)
    assert {v.name: v.shape for v in report.variables}["w"] == (4,)
    assert not report.smoke_ok and "tunable structural parameter 'n'" in report.smoke_message
