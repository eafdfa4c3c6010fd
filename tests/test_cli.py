"""The `parsph` command line: bad input, the output directory, `check`, `info`, a 2-rank run.

Bad input must end with one clear message naming the problem, exit code 2 and no
traceback, on one rank and under `mpiexec -n 2` (where rank 0 prints it exactly once).
Every scene used here is generated under pytest's tmp_path from BAR, a copy of
runs/bar1d.toml (a 40-particle 1D bar), so the tests do not depend on edits to runs/.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import pytest

from conftest import BAR, CEILING, ROOT, RUNS, mpiexec, parsph, parsph_batch


# A small 2D scene (random particles in a patch) for the "zero particles" count.
PATCH_2D = """\
[scene]
name = "patch"
dimension = 2

[geometry]
[[geometry.parts]]
shape = "random_patch"
lower = [0.0, 0.0]
upper = [1.0, 0.1]
count = 0

[material]
model = "neo_hookean"
density = 1000.0
youngs_modulus = 1.0e6
poisson_ratio = 0.3

[time]
end = 1.0e-3
"""

# an expression of position in a condition of kind `kind` ("initial", "bc" or "tractions")
EXPRESSION = """
[parameters]
n = 10
[[{kind}]]
{type}group = "right_quarter"
expression = ["{text}"]
"""
# two bars side by side in contact, the right one possibly rigid (1D: the bar's lattice)
TWO_BARS = """\
[scene]
name = "two_bars"
dimension = 1
[geometry]
area = 1.0e-4
[kernel]
type = "cubic_spline"
support = 1.5
[[bodies]]
name = "left"
[[bodies.parts]]
shape = "box"
lower = [0.0]
upper = [0.1]
spacing = 0.01
[bodies.material]
model = "saint_venant_kirchhoff"
density = 7850.0
youngs_modulus = 200.0e9
poisson_ratio = 0.0
[[bodies]]
name = "right"
rigid = false
[[bodies.parts]]
shape = "box"
lower = [0.1]
upper = [0.2]
spacing = 0.01
[bodies.material]
model = "saint_venant_kirchhoff"
density = 7850.0
youngs_modulus = 200.0e9
poisson_ratio = 0.0
[[contact]]
bodies = ["left", "right"]
[groups.right]
box = { lower = [0.1], upper = [0.2] }
[time]
end = 1.0e-4
"""
BAR_MATERIAL = """[material]
model = "saint_venant_kirchhoff"
density = 7850.0
youngs_modulus = 200.0e9
poisson_ratio = 0.0
"""
J2_FAILURE = """[material]
model = "j2_plasticity"
density = 7850.0
youngs_modulus = 200.0e9
poisson_ratio = 0.0
yield_stress = 5.0e8
hardening_modulus = 0.0
jc_d1 = 0.5
"""
JOHNSON_COOK = """[material]
model = "johnson_cook"
density = 8960.0
youngs_modulus = 124.0e9
poisson_ratio = 0.34
jc_a = 90.0e6
jc_b = 292.0e6
jc_n = 0.31
room_temperature = 298.0
melting_temperature = 1356.0
specific_heat = 383.0
"""
MIE_GRUNEISEN = """[material]
model = "mie_gruneisen"
density = 8930.0
shear_modulus = 48.0e9
sound_speed = 3940.0
hugoniot_slope = 1.49
gruneisen_gamma = 2.0
"""
RUN_FILES = ("history.h5", "snapshots.h5", "snapshots.xdmf", "scene.json")
RANKS = [pytest.param(1, id="1rank"), pytest.param(2, id="2ranks", marks=pytest.mark.mpi)]
QUICK = ["--set", "time.max_steps=20", "--quiet"]


def edit(old: str, new: str, text: str = BAR) -> str:
    """`text` with the one occurrence of `old` replaced (fails loudly if BAR changes)."""
    assert text.count(old) == 1, f"{old!r} must occur once in the base scene"
    return text.replace(old, new)


def write(tmp_path: Path, text: str | bytes, name: str = "scene.toml") -> Path:
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


@dataclass
class Case:
    """One bad input: how to make the scene argument, extra arguments, expected stderr parts."""

    make: Callable[[Path], Path]
    expect: list[str]
    args: list[str] = field(default_factory=list)
    build: bool = False  # found only by `run` (geometry, groups, output directory), not by `check`
    two_ranks: bool = True  # also under mpiexec -n 2 (not for a variant of a case that is)


def scene(text):
    return lambda tmp: write(tmp, text)


def material(block: str, old: str = "", new: str = "") -> Callable[[Path], Path]:
    """The bar scene with the [material] `block` (its `old` line replaced by `new`)."""
    return scene(edit(BAR_MATERIAL, edit(old, new, block) if old else block))


def two_bars(old: str, new: str) -> Callable[[Path], Path]:
    """TWO_BARS with `old` replaced by `new`."""
    return scene(edit(old, new, TWO_BARS))


def rigid_right(material_line: str = "", extra: str = "") -> Callable[[Path], Path]:
    """TWO_BARS with the right bar rigid, its material's last line followed by
    `material_line`, and `extra` at the end."""
    text = edit("rigid = false", "rigid = true", TWO_BARS)
    if material_line:
        text = edit("poisson_ratio = 0.0\n[[contact]]", f"poisson_ratio = 0.0\n{material_line}\n[[contact]]", text)
    return scene(text + extra)


def probe(name: str, expect: list, two_ranks: bool = True) -> Case:
    """The bar scene with its probe named `name`."""
    return Case(scene(edit('name = "tip_displacement"', f'name = "{name}"')), expect, two_ranks=two_ranks)


def occupied_out(tmp: Path) -> Path:
    """The bar scene; the --out path given by the test is an existing regular file."""
    (tmp / "out").write_text("not a directory\n")
    return write(tmp, BAR)


BAD_INPUT = {
    "unknown-top-level-key": Case(
        scene(BAR + "\n[solver]\nthreads = 2\n"), ["unknown key 'solver'"]),
    "unknown-top-level-key-typo": Case(
        scene(edit("[material]", "[materal]")),
        ["unknown key 'materal'", "did you mean 'material'"]),
    "unknown-nested-key-suggestion": Case(
        scene(edit("youngs_modulus =", "youngs_modulous =")),
        ["material.youngs_modulous", "did you mean 'youngs_modulus'"]),
    "unknown-key-in-array-table": Case(
        scene(edit('type = "fixed"\ngroup = "A"', 'type = "fixed"\ngrup = "A"')),
        ["bc[0].grup", "did you mean 'group'"]),
    "missing-required-key": Case(
        scene(edit("density = 7850.0\n", "")), ["missing required key 'material.density'"]),
    "missing-required-model-key": Case(
        scene(edit("youngs_modulus = 200.0e9\n", "")),
        ["missing required key 'material.youngs_modulus'", "saint_venant_kirchhoff"]),
    "wrong-type": Case(
        scene(edit("density = 7850.0", 'density = "heavy"')),
        ["material.density", "must be a number", "'heavy'"]),
    "negative-density": Case(
        scene(edit("density = 7850.0", "density = -7850.0")),
        ["material.density", "must be > 0", "-7850"]),
    "poisson-ratio-0.5-compressible-neo-hookean": Case(
        scene(edit("poisson_ratio = 0.0", "poisson_ratio = 0.5",
                   edit('"saint_venant_kirchhoff"', '"neo_hookean"'))),
        ["material.poisson_ratio", "0.5"]),
    "zero-particles-count": Case(scene(PATCH_2D), ["geometry.parts[0].count", "must be > 0"]),
    "zero-particles-no-parts": Case(
        scene(edit('[[geometry.parts]]\nshape = "box"\nlower = [0.0]\nupper = [1.0]\n'
                   'spacing = 0.02564102564102564\nplacement = "node"\n', "parts = []\n")),
        ["geometry.parts is empty"]),
    "zero-particles-box-shorter-than-spacing": Case(
        scene(edit("upper = [1.0]\nspacing", "upper = [0.01]\nspacing")), ["geometry.parts", "spacing"],
        build=True),
    "group-selects-no-particles": Case(
        scene(edit("[groups.A]\nnearest = [0.0]", "[groups.A]\nbox = { lower = [2.0], upper = [3.0] }")),
        ["group 'A' selects no particles", "groups.A"], build=True),
    "undefined-group": Case(
        scene(edit('type = "fixed"\ngroup = "A"', 'type = "fixed"\ngroup = "AA"')),
        ["bc[0].group", "'AA'", "not defined"]),
    "file-not-found": Case(lambda tmp: tmp / "no_such_scene.toml", ["not found", "no_such_scene.toml"]),
    "directory-as-scene": Case(lambda tmp: tmp, ["is a directory"]),
    "invalid-toml": Case(
        scene(edit("cfl = 0.5", "cfl = 0.5.5")),
        ["not valid TOML", "scene.toml", f"line {BAR.splitlines().index('cfl = 0.5') + 1}"]),
    "non-toml-text": Case(scene("This is not a scene file.\n"), ["not valid TOML"]),
    "binary-file": Case(
        scene(b"\x89HDF\r\n\x1a\n\xff\xfe\x00\x01" + bytes(range(128, 256))),
        ["not valid TOML", "scene.toml"]),
    "set-bad-type": Case(
        scene(BAR), ["material.density", "must be a number", "'abc'"], ["--set", "material.density=abc"]),
    "set-unknown-key": Case(
        scene(BAR), ["material.youngs_modulous", "did you mean 'youngs_modulus'"],
        ["--set", "material.youngs_modulous=1e9"]),
    "set-without-equals": Case(scene(BAR), ["--set", "key.path=value"], ["--set", "material.density"]),
    "set-no-such-array-entry": Case(scene(BAR), ["bc.3", "no such entry"], ["--set", "bc.3.ramp=0.1"]),
    "out-is-a-file": Case(occupied_out, ["exists and is not a directory"], build=True),
    # expressions of position: evaluated in double precision, so an integer power cannot run
    # for ever, and a value that is not a finite real number is refused, naming the particle
    "expression-integer-power-tower": Case(
        scene(BAR + EXPRESSION.format(kind="initial", type='type = "velocity_field"\n', text="n**n**n")),
        ["initial[1].expression[0] = 'n**n**n' is inf at particle", "not a finite real number"], build=True),
    "expression-integer-power-in-bc": Case(
        scene(BAR + EXPRESSION.format(kind="bc", type='type = "displacement"\n', text="n**(n**7)")),
        ["bc[1].expression[0]", "is inf at particle"], build=True, two_ranks=False),
    "expression-integer-power-in-traction": Case(
        scene(BAR + EXPRESSION.format(kind="tractions", type="", text="n**n**n * x")),
        ["tractions[0].expression[0]", "is inf at particle"], build=True, two_ranks=False),
    "expression-complex-root": Case(
        scene(BAR + EXPRESSION.format(kind="initial", type='type = "displacement_field"\n',
                                      text="(-8)**(1/3) + 0*x")),
        ["initial[1].expression[0]", "is nan at particle", "not a finite real number"], build=True),
    "expression-complex-root-constant": Case(
        scene(BAR + EXPRESSION.format(kind="initial", type='type = "velocity_field"\n', text="(-n)**0.5")),
        ["initial[1].expression[0] = '(-n)**0.5' is nan at particle 30"], build=True, two_ranks=False),
    # probes write series of history.h5: their names must be plain and not the history's own
    "probe-named-time": probe("time", ["probes[0].name 'time'", "history's own series"]),
    "probe-named-like-a-momentum": probe("momentum_x", ["probes[0].name 'momentum_x'", "history's own series"],
                                         two_ranks=False),
    "probe-named-like-a-wall-force": probe("wall0_force_x", ["probes[0].name 'wall0_force_x'", "own series"],
                                           two_ranks=False),
    "probe-name-with-slash": probe("a/b", ["probes[0].name 'a/b' must be a plain name"]),
    "probe-name-empty": probe("", ["probes[0].name '' must be a plain name"], two_ranks=False),
    "probe-name-dot": probe(".", ["probes[0].name '.' must be a plain name"], two_ranks=False),
    "probe-name-like-a-body-series": probe("kinetic_energy.rod", ["name 'kinetic_energy.rod' must be a plain name"],
                                           two_ranks=False),
    # numbers that overflow double precision later are refused with the key that causes it
    "density-overflows-the-wave-speed": Case(
        scene(edit("density = 7850.0", "density = 1e-300")),
        ["material: the moduli or the P-wave speed", "= inf m/s", "density = 1e-300"]),
    "hourglass-stiffness-overflows": Case(
        scene(edit("hourglass = 0.0", "hourglass = 1e300")),
        ["formulation.hourglass = 1e+300", "hourglass stiffness of particle", "overflows"], build=True),
    # constants that are numbers but nonsense: refused with the key and its range
    "johnson-cook-failure-d1-negative": Case(
        material(J2_FAILURE, "jc_d1 = 0.5", "jc_d1 = -0.5"),
        ["material.jc_d1 + jc_d2 = -0.5 must be > 0", "would fail at once"]),
    "johnson-cook-failure-d1-negative-with-d3": Case(
        material(J2_FAILURE, "jc_d1 = 0.5", "jc_d1 = -2.2\njc_d2 = 5.43\njc_d3 = -0.47"),
        ["material.jc_d1 = -2.2 must be >= 0 with jc_d3 = -0.47", "triaxialities sigma* above 1.92"],
        two_ranks=False),
    "johnson-cook-failure-d4-negative": Case(
        material(J2_FAILURE, "jc_d1 = 0.5", "jc_d1 = 0.5\njc_d4 = -100.0"), ["material.jc_d4 must be >= 0"]),
    "johnson-cook-failure-d5-below-minus-one": Case(
        material(J2_FAILURE, "jc_d1 = 0.5", "jc_d1 = 0.5\njc_d5 = -1.0"), ["material.jc_d5 must be > -1.0"],
        two_ranks=False),
    "specific-heat-tiny": Case(
        material(JOHNSON_COOK, "specific_heat = 383.0", "specific_heat = 1e-300"),
        ["material.specific_heat must be in [10.0, 100000.0]", "1e-300"]),
    "hugoniot-slope-huge": Case(
        material(MIE_GRUNEISEN, "hugoniot_slope = 1.49", "hugoniot_slope = 1e6"),
        ["material.hugoniot_slope must be in [0.0, 5.0]"]),
    "contact-radius-tiny": Case(
        two_bars('bodies = ["left", "right"]', 'bodies = ["left", "right"]\nradius = 1e-300'),
        ["contact[0].radius must be > 0.5", "1e-300"]),
    "contact-stiffness-tiny": Case(
        two_bars('bodies = ["left", "right"]', 'bodies = ["left", "right"]\nstiffness = 1e-300'),
        ["contact[0].stiffness must be in [0.01, 10000.0]", "1e-300"]),
    "failure-of-a-rigid-body": Case(
        rigid_right("failure_strain = 0.1"), ["bodies[1].material.failure_strain: body 'right' is rigid"]),
    "broken-pairs-of-a-rigid-body": Case(
        rigid_right("break_pairs = true"), ["bodies[1].material.break_pairs: body 'right' is rigid"], two_ranks=False),
    "condition-stretching-a-rigid-body": Case(
        rigid_right(extra='[[bc]]\ntype = "displacement"\ngroup = "right"\nexpression = ["0.1 * (x - 0.1)"]\n'),
        ["bc[0] gives the particles of rigid body 'right' different values"], build=True),
    "skin-beyond-two-supports": Case(
        scene(edit('type = "tlsph"', 'type = "sph"\nkernel = "eulerian"\nskin = 1e300')),
        ["formulation.skin", "must be in [0.0, 2.0]"]),
}


@pytest.mark.parametrize("text", [
    TWO_BARS, edit("rigid = false", "rigid = true", TWO_BARS), edit(BAR_MATERIAL, J2_FAILURE),
    edit(BAR_MATERIAL, JOHNSON_COOK), edit(BAR_MATERIAL, MIE_GRUNEISEN)], ids=["two-bars", "two-bars-rigid",
                                                                            "j2-failure", "johnson-cook", "mie-gruneisen"])
def test_the_scenes_the_cases_edit_are_valid(text):
    from parsph.api import load_scene

    assert load_scene(text).scene.name


def assert_bad_input(proc, expect: list[str]) -> None:
    """Exit code 2, every expected part in stderr, one message, no traceback or abort."""
    err = proc.stderr
    assert proc.returncode == 2, f"exit code {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{err}"
    assert "Traceback" not in err, err
    assert "Abort" not in err, err  # an agreed error must not go through MPI_Abort
    for part in expect:
        assert part in err, f"{part!r} not in stderr:\n{err}"
    # printed once, by rank 0, even under several ranks
    assert err.count("parsph: error") == 1, err
    assert err.count(expect[0]) == 1, err


def assert_cases_refused(names: list, ranks: int, tmp_path) -> None:
    """The BAD_INPUT cases `names` one after another in one job of `ranks` ranks
    (conftest.parsph_batch: a process per case would spend most of its time starting): on one
    rank scene errors (found by config.load, the same code for `check` and `run`) as `check`
    and errors only `run` finds as `run`, on more as `run`. Each: exit code 2, one message,
    nothing printed to stdout, nothing run; the failures reported by case."""
    commands, outs = [], []
    for name in names:
        case, folder = BAD_INPUT[name], tmp_path / name
        folder.mkdir()
        outs.append(folder / "out")
        path = case.make(folder)
        args = ["run", path, "--out", outs[-1], *QUICK] if case.build or ranks > 1 else ["check", path]
        commands.append([*args, *case.args])
    failures = []
    for name, out, proc in zip(names, outs, parsph_batch(commands, ranks, tmp_path / "batch")):
        try:
            assert_bad_input(proc, BAD_INPUT[name].expect)
            assert proc.stdout == "", proc.stdout
            assert not (out / "history.h5").exists()  # nothing was run
        except AssertionError as exc:
            failures.append(f"{name}: {exc}")
    assert not failures, "\n\n".join(failures)


def test_bad_input_exit_2_with_one_clear_message(tmp_path):
    """Every case on one rank."""
    assert len(BAD_INPUT) > 40
    assert_cases_refused(list(BAD_INPUT), 1, tmp_path)


@pytest.mark.mpi
def test_bad_input_under_two_ranks_exit_2_with_one_clear_message(tmp_path):
    """Every case but the variants of another under mpiexec -n 2: the error on every rank,
    its message from rank 0 once."""
    names = [name for name, case in BAD_INPUT.items() if case.two_ranks]
    assert len(names) > 30
    assert_cases_refused(names, 2, tmp_path)


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0,
                    reason="root reads files regardless of their permissions")
@pytest.mark.parametrize("ranks", RANKS)
def test_unreadable_scene(ranks, tmp_path):
    path = write(tmp_path, BAR)
    path.chmod(0)
    try:
        proc = parsph(["run", path, "--out", tmp_path / "out", *QUICK], ranks=ranks)
    finally:
        path.chmod(0o644)
    assert_bad_input(proc, ["not readable", str(path)])


@pytest.mark.parametrize("ranks", RANKS)
@pytest.mark.parametrize("argv", [["run"], ["frobnicate"], ["run", "x.toml", "--bogus"]],
                         ids=["missing-scene", "unknown-command", "unknown-option"])
def test_usage_error(argv, ranks):
    proc = parsph(argv, ranks=ranks)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.count("usage: parsph") == 1, proc.stderr
    assert proc.stderr.count("parsph: error:") == 1, proc.stderr


def test_box_shorter_than_spacing_message(tmp_path):
    path = write(tmp_path, edit("upper = [1.0]\nspacing", "upper = [0.01]\nspacing"))
    proc = parsph(["run", path, "--out", tmp_path / "out", *QUICK])
    assert_bad_input(proc, ["geometry.parts[0]", "0.01"])
    assert "np.float64" not in proc.stderr


# ------------------------------------------------------------------ the output directory
def snapshot_files(out: Path) -> dict:
    return {f: ((out / f).read_bytes(), (out / f).stat().st_mtime_ns) for f in RUN_FILES}


@pytest.mark.mpi
def test_output_directory_holds_a_run(tmp_path):
    """A second run into the same --out is refused (and nothing is touched) unless
    --overwrite; a file of the user's survives even --overwrite."""
    path = write(tmp_path, BAR)
    out = tmp_path / "D"
    first = parsph(["run", path, "--out", out, *QUICK])
    assert first.returncode == 0, first.stderr
    assert "Traceback" not in first.stderr
    for f in RUN_FILES:
        assert (out / f).is_file(), f
    json.loads((out / "scene.json").read_text())
    notes = out / "my_notes.txt"
    notes.write_text("the user's own file\n")
    before = snapshot_files(out)

    for ranks in (1, 2):
        again = parsph(["run", path, "--out", out, *QUICK], ranks=ranks)
        assert_bad_input(again, ["already holds a run", str(out), "--overwrite"])
        assert snapshot_files(out) == before, f"a refused run changed the previous run ({ranks} ranks)"
        assert notes.read_text() == "the user's own file\n"

    replaced = parsph(["run", path, "--out", out, "--overwrite", *QUICK], ranks=2)
    assert replaced.returncode == 0, replaced.stderr
    assert "Traceback" not in replaced.stderr
    assert "replacing the previous run" in replaced.stdout  # never silently
    assert replaced.stdout.count("replacing the previous run") == 1
    after = snapshot_files(out)
    for f in RUN_FILES:
        assert after[f][1] != before[f][1], f"{f} was not rewritten by --overwrite"
    assert notes.read_text() == "the user's own file\n", "--overwrite deleted a file that is not a run file"


def test_overwrite_keeps_previous_run_when_new_scene_is_bad(tmp_path):
    good = write(tmp_path, BAR, "good.toml")
    bad = write(tmp_path, edit("[groups.A]\nnearest = [0.0]",
                               "[groups.A]\nbox = { lower = [2.0], upper = [3.0] }"), "bad.toml")
    out = tmp_path / "D"
    first = parsph(["run", good, "--out", out, *QUICK])
    assert first.returncode == 0, first.stderr
    before = snapshot_files(out)
    proc = parsph(["run", bad, "--out", out, "--overwrite", *QUICK])
    assert_bad_input(proc, ["group 'A' selects no particles"])
    assert all((out / f).exists() for f in RUN_FILES), "bad input destroyed the previous run"
    assert snapshot_files(out) == before


# ------------------------------------------------------------------ plot
@pytest.fixture(scope="module")
def bar_output(tmp_path_factory):
    """A short run of the bar with three snapshots."""
    folder = tmp_path_factory.mktemp("plot")
    proc = parsph(["run", write(folder, BAR), "--out", folder / "run", "--quiet", "--set", "time.end=2e-4",
                   "--set", "output.snapshot_interval=1e-4"])
    assert proc.returncode == 0, proc.stderr
    return folder / "run"


PLOT_REFUSALS = {  # name: (the arguments after `plot`, given the run's directory; expected stderr parts)
    "frames-negative": (lambda run: [run / "snapshots.h5", "--frames", "-3"], ["--frames = -3", "at least 1"]),
    "frames-zero": (lambda run: [run / "snapshots.h5", "--frames", "0"], ["--frames = 0", "at least 1"]),
    "limits-reversed": (lambda run: [run / "snapshots.h5", "--limits", "1", "0"], ["--limits 1 0", "LOW < HIGH"]),
    "frames-of-a-history": (lambda run: [run / "history.h5", "--frames", "2"], ["apply to a plot of snapshots"]),
    "directory": (lambda run: [run], ["is a directory: give a run's history.h5 or snapshots.h5"]),
    "toml-file": (lambda run: [RUNS / "bar1d.toml"], ["bar1d.toml cannot be read: it is not an HDF5 file"]),
    "output-in-a-missing-directory": (lambda run: [run / "history.h5", "-o", run / "missing" / "plot.png"],
                                      ["the plot cannot be written to", "plot.png"]),
    "output-under-a-file": (lambda run: [run / "history.h5", "-o", run / "scene.json" / "plot.png"],
                            ["the plot cannot be written to", "plot.png"]),
    "output-over-the-snapshots": (lambda run: [run / "history.h5", "-o", run / "snapshots.h5"],
                                  ["snapshots.h5 must be a .png file"]),
}


@pytest.mark.parametrize("ranks", RANKS)
def test_plot_refuses_bad_input_and_keeps_the_run(bar_output, ranks, tmp_path):
    """Each of PLOT_REFUSALS is refused; none wrote a file and the run is whole. The cases
    run one after another in one MPI job (conftest.parsph_batch)."""
    from parsph.io import read_history, read_snapshots

    procs = parsph_batch([["plot", *args(bar_output)] for args, _ in PLOT_REFUSALS.values()], ranks, tmp_path)
    failures = []
    for (name, (_, expect)), proc in zip(PLOT_REFUSALS.items(), procs):
        try:
            assert_bad_input(proc, expect)
        except AssertionError as exc:
            failures.append(f"{name}: {exc}")
    assert not failures, "\n\n".join(failures)
    assert not list(bar_output.rglob("*.png")), "a refused plot wrote a file"
    assert len(read_snapshots(bar_output)) == 3 and len(read_history(bar_output)["time"]) > 1


# ------------------------------------------------------------------ check, info, run
@pytest.mark.parametrize("ranks", RANKS)
def test_check_prints_resolved_scene(ranks):
    proc = parsph(["check", RUNS / "bar1d.toml"], ranks=ranks)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    scene = json.loads(proc.stdout)  # a single JSON document: printed once
    assert scene["scene"]["name"] == "bar1d"
    assert scene["formulation"]["force_form"] == "pair"
    assert scene["kernel"]["neighbours"] == 0
    assert scene["time"]["dt"] == 0.0 and scene["time"]["max_steps"] == 0
    assert scene["output"]["history_every"] == 10
    assert scene["bc"][0]["components"] == [0] and scene["bc"][0]["value"] == [0.0]
    assert scene["groups"]["all"] == {"all": True}


def test_output_cut_off_by_its_reader_ends_quietly():
    """`parsph check SCENE | head -1`: the pipe closes under the printing rank; the command
    ends with the broken-pipe status (128 + SIGPIPE) and no traceback."""
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "parsph", "check", str(RUNS / "rings.toml")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    proc.stdout.close()  # the reader goes away before the scene is printed (imports take longer)
    stderr = proc.stderr.read().decode()
    assert proc.wait(timeout=CEILING) == 141
    assert "Traceback" not in stderr and stderr == "", stderr


def test_check_applies_set(tmp_path):
    proc = parsph(["check", write(tmp_path, BAR), "--set", "time.end=1e-4",
                   "--set", "bc.0.ramp=0.5", "--set", "formulation.force_form=virtual_work"])
    assert proc.returncode == 0, proc.stderr
    scene = json.loads(proc.stdout)
    assert scene["time"]["end"] == 1e-4
    assert scene["bc"][0]["ramp"] == 0.5
    assert scene["formulation"]["force_form"] == "virtual_work"


def info_value(stdout: str, key: str) -> str:
    found = re.findall(rf"^{re.escape(key)}\s{{2,}}(.*)$", stdout, re.M)
    assert len(found) == 1, f"{key!r} must appear once in:\n{stdout}"
    return found[0].strip()


@pytest.mark.parametrize("ranks", RANKS)
def test_info(ranks):
    import h5py

    proc = parsph(["info"], ranks=ranks)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert info_value(proc.stdout, "MPI ranks") == str(ranks)
    assert info_value(proc.stdout, "parsph")  # every line once: not printed by each rank
    assert len(info_value(proc.stdout, "numba threads per rank").split(",")) == ranks
    if h5py.get_config().mpi:
        assert info_value(proc.stdout, "parallel HDF5") == "yes"
    else:
        assert info_value(proc.stdout, "parallel HDF5").startswith("no")


@pytest.mark.mpi
def test_run_two_ranks_writes_finite_history(tmp_path):
    import h5py
    import numpy as np

    out = tmp_path / "out"
    proc = parsph(["run", RUNS / "bar1d.toml", "--out", out, "--set", "time.max_steps=50", "--quiet"],
                  ranks=2)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "2 rank(s)" in proc.stdout and proc.stdout.count("parsph: scene") == 1
    with h5py.File(out / "history.h5", "r") as f:
        series = {name: np.asarray(f[name])
                  for name in ("time", "step", "kinetic_energy", "tip_displacement")}
    for name, values in series.items():
        assert values.ndim == 1 and len(values) >= 2, name
        assert np.all(np.isfinite(values)), name
    assert np.all(np.diff(series["time"]) > 0)
    assert series["step"][-1] == 50
    assert series["kinetic_energy"][0] > 0  # the right quarter starts at 5 m/s
    assert series["tip_displacement"][-1] > 0  # ... and moves right


@pytest.mark.mpi
@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this system")
def test_more_ranks_than_cores_get_one_warning(tmp_path):
    """Two ranks allowed one core between them (their CPU affinity): rank 0 warns once that
    they slow each other down and to run fewer; the run goes on. With a core each (if the
    machine has two) there is no warning."""
    import subprocess
    import sys

    cores = sorted(os.sched_getaffinity(0))

    def run(allowed):
        cmd = [mpiexec(), "-n", "2", sys.executable, "-m", "parsph", "run", str(RUNS / "bar1d.toml"), "--out",
               str(tmp_path / f"cores_{len(allowed)}"), "--quiet", "--set", "time.max_steps=2"]
        return subprocess.run(cmd, capture_output=True, text=True, timeout=CEILING, cwd=ROOT,
                              env={**os.environ, "PYTHONUNBUFFERED": "1"},
                              preexec_fn=lambda: os.sched_setaffinity(0, allowed))

    proc = run(cores[:1])
    assert proc.returncode == 0, proc.stderr
    warning = "parsph: warning: 2 ranks share 1 core(s) on a node"
    assert proc.stderr.count(warning) == 1 and proc.stderr.count("warning") == 1, proc.stderr
    assert "busy-polling" in proc.stderr and "run fewer ranks (-n 1)" in proc.stderr, proc.stderr
    assert "parsph: scene" in proc.stdout
    if len(cores) >= 2:
        proc = run(cores[:2])
        assert proc.returncode == 0 and "warning" not in proc.stderr, proc.stderr
