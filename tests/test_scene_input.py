"""Scene input that must be refused (exit code 2, one message naming the key, no traceback)
or warned about: non-finite numbers, absurd geometry, runaway parameter expressions,
unreadable scene paths, parts that overlap without coinciding, and a boundary condition's
duration that is not positive.

Most cases run in process through config.validate / config.load and build_particles on
MPI.COMM_SELF; a few run the `parsph` command for the exit code and the message.
"""

from __future__ import annotations

import os
import re
import tomllib

import pytest
from mpi4py import MPI

from conftest import BAR, CEILING, parsph
from parsph import build, config
from parsph.errors import InputError

# A small 2D scene with a value for every kind of vector, matrix and group selector.
SCENE = """\
[scene]
name = "input"
dimension = 2

[parameters]
n = 4
h = 0.25

[geometry]
[[geometry.parts]]
shape = "box"
lower = [0.0, 0.0]
upper = [1.0, 1.0]
spacing = "= h"

[material]
model = "saint_venant_kirchhoff"
density = 1000.0
youngs_modulus = 1.0e6
poisson_ratio = 0.3

[time]
end = 1.0e-3

[loads]
body_acceleration = [0.0, -9.81]

[groups.left]
box = { lower = [0.0, 0.0], upper = [0.1, 1.0] }
[groups.ball]
sphere = { center = [0.5, 0.5], radius = 0.2 }
[groups.top]
halfspace = { point = [0.0, 0.9], normal = [0.0, 1.0] }
[groups.corner]
nearest = [1.0, 1.0]
[groups.right]
extreme = { axis = 0, side = "max", tolerance = 0.01 }

[[bc]]
type = "velocity"
group = "left"
value = [0.0, 0.0]

[[walls]]
point = [0.0, -0.5]
normal = [0.0, 1.0]

[[tools]]
lower = [0.2, 1.5]
upper = [0.8, 2.0]

[[initial]]
type = "velocity"
value = [1.0, 0.0]
[[initial]]
type = "angular_velocity"
omega = [1.0]
center = [0.5, 0.5]
[[initial]]
type = "displacement_gradient"
gradient = [[0.0, 0.0], [0.0, 0.0]]
"""

HEAD_2D = SCENE[:SCENE.index("[parameters]")] + SCENE[SCENE.index("[material]"):SCENE.index("[loads]")]
HEAD_3D = HEAD_2D.replace("dimension = 2", "dimension = 3")


def validate(text: str = SCENE, *overrides: str) -> dict:
    raw = tomllib.loads(text)
    for item in overrides:
        config.apply_override(raw, *config.parse_override(item))
    return config.validate(raw)


def refused(text: str, *overrides: str) -> str:
    with pytest.raises(InputError) as info:
        validate(text, *overrides)
    return str(info.value)


def assert_bad_input(proc, *expect: str) -> None:
    """Exit code 2, one message holding every part of `expect`, no traceback."""
    assert proc.returncode == 2, f"exit code {proc.returncode}\n{proc.stderr}"
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.count("parsph: error") == 1, proc.stderr
    for part in expect:
        assert part in proc.stderr, f"{part!r} not in stderr:\n{proc.stderr}"


def test_base_scene_is_valid():
    scene = validate()
    assert scene.geometry.parts[0]["spacing"] == 0.25


# ------------------------------------------------------------------ 1. non-finite numbers
NON_FINITE = {
    "walls.0.point=[nan, 0.0]": "walls[0].point[0] must be finite, got nan",
    "walls.0.normal=[0.0, inf]": "walls[0].normal[1] must be finite, got inf",
    "walls.0.velocity=[-inf, 0.0]": "walls[0].velocity[0] must be finite, got -inf",
    "initial.0.value=[-inf, 0.0]": "initial[0].value[0] must be finite, got -inf",
    "initial.1.omega=[nan]": "initial[1].omega[0] must be finite, got nan",
    "initial.1.center=[0.5, nan]": "initial[1].center[1] must be finite, got nan",
    "initial.2.gradient=[[0.0, nan], [0.0, 0.0]]": "initial[2].gradient[0][1] must be finite, got nan",
    "bc.0.value=[nan, 0.0]": "bc[0].value[0] must be finite, got nan",
    "loads.body_acceleration=[0.0, nan]": "loads.body_acceleration[1] must be finite, got nan",
    "tools.0.lower=[nan, 1.5]": "tools[0].lower[0] must be finite, got nan",
    "tools.0.upper=[0.8, inf]": "tools[0].upper[1] must be finite, got inf",
    "geometry.parts.0.lower=[nan, 0.0]": "geometry.parts[0].lower[0] must be finite, got nan",
    "geometry.parts.0.upper=[1.0, inf]": "geometry.parts[0].upper[1] must be finite, got inf",
    "groups.left.box.upper=[inf, 1.0]": "groups.left.box.upper[0] must be finite, got inf",
    "groups.ball.sphere.center=[nan, 0.5]": "groups.ball.sphere.center[0] must be finite, got nan",
    "groups.ball.sphere.radius=nan": "groups.ball.sphere.radius must be finite, got nan",
    "groups.top.halfspace.normal=[0.0, nan]": "groups.top.halfspace.normal[1] must be finite, got nan",
    "groups.corner.nearest=[nan, 1.0]": "groups.corner.nearest[0] must be finite, got nan",
    "groups.right.extreme.tolerance=inf": "groups.right.extreme.tolerance must be finite, got inf",
    "parameters.h=nan": "parameters.h must be finite, got nan",
    "material.density=nan": "material.density must be finite, got nan",
    "time.end=inf": "time.end must be finite, got inf",
    "material.density=1" + "0" * 400: "material.density must be finite, got a 1329-bit integer",
    "walls.0.point=[1" + "0" * 400 + ", 0]": "walls[0].point[0] must be finite",
}


@pytest.mark.parametrize("override", list(NON_FINITE))
def test_non_finite_number_is_refused_with_its_key(override):
    assert NON_FINITE[override] in refused(SCENE, override)


def test_non_finite_in_the_scene_file_and_from_an_expression(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("point = [0.0, -0.5]", "point = [nan, -0.5]"))
    with pytest.raises(InputError, match=re.escape("walls[0].point[0] must be finite, got nan")):
        config.load(str(path))
    message = refused(SCENE, 'walls.0.normal=[0.0, "= 1e308 * 10"]')
    assert "walls[0].normal[1]" in message and "1e308 * 10" in message


@pytest.mark.parametrize("command", ["check", "run"])
def test_nan_wall_ends_with_exit_2(command, tmp_path):
    """The wall at [nan] used to be ignored silently and the run ended with exit 0."""
    path = tmp_path / "bar.toml"
    path.write_text(BAR + "\n[[walls]]\npoint = [-1.0]\nnormal = [1.0]\n")
    extra = ["--out", tmp_path / "out", "--quiet", "--set", "time.max_steps=1"] if command == "run" else []
    proc = parsph([command, path, "--set", "walls.0.point=[nan]", *extra])
    assert_bad_input(proc, "walls[0].point[0] must be finite, got nan")


# ------------------------------------------------------------------ 2. absurd geometry
def box_2d(lower, upper, spacing, placement="cell"):
    return HEAD_2D + (f'[[geometry.parts]]\nshape = "box"\nlower = {lower}\nupper = {upper}\n'
                      f'spacing = {spacing}\nplacement = "{placement}"\n')


def part(head, **keys):
    body = "".join(f"{k} = {v!r}\n".replace("'", '"') for k, v in keys.items())
    return head + "[[geometry.parts]]\n" + body


ABSURD = {
    "box-upper-1e308": box_2d([0.0, 0.0], [1e308, 1.0], 0.1),
    "box-length-overflows": box_2d([-1e308, 0.0], [1e308, 1.0], 0.1),
    "box-spacing-1e-300": box_2d([0.0, 0.0], [1.0, 1.0], 1e-300),
    "box-node-product": box_2d([0.0, 0.0], [1.0, 1.0], 1e-5, "node"),
    "box-3d-product": part(HEAD_3D, shape="box", lower=[0.0, 0.0, 0.0], upper=[1.0, 1.0, 1.0], spacing=5e-4),
    "cylinder-radius": part(HEAD_3D, shape="cylinder", base_center=[0.0, 0.0, 0.0], radius=1e300,
                            length=1.0, spacing=1.0),
    "cylinder-count": part(HEAD_3D, shape="cylinder", base_center=[0.0, 0.0, 0.0], radius=1.0,
                           length=1.0, spacing=1e-4),
    "cylinder-spacing-1e-300": part(HEAD_3D, shape="cylinder", base_center=[0.0, 0.0, 0.0], radius=1.0,
                                    length=1.0, spacing=1e-300),
    "ring-radius": part(HEAD_2D, shape="ring", center=[0.0, 0.0], inner_radius=1.0, outer_radius=1e308,
                        spacing=0.1),
    "ring-spacing-1e-300": part(HEAD_2D, shape="ring", center=[0.0, 0.0], inner_radius=1.0,
                                outer_radius=2.0, spacing=1e-300),
    "disk-count": part(HEAD_2D, shape="disk", center=[0.0, 0.0], radius=1.0, spacing=1e-5),
    "random-patch-count": part(HEAD_2D, shape="random_patch", lower=[0.0, 0.0], upper=[1.0, 1.0],
                               count=2**31 + 1),
}


@pytest.mark.timeout(CEILING)  # refused before anything is allocated: a hang or a huge allocation fails
@pytest.mark.parametrize("name", list(ABSURD))
def test_part_with_too_many_particles_is_refused(name):
    with pytest.raises(InputError) as info:
        build.build_particles(validate(ABSURD[name]), MPI.COMM_SELF)
    message = str(info.value)
    assert message.startswith("geometry.parts[0]: "), message
    assert "2^31" in message


def test_parts_with_too_many_particles_in_all_are_refused():
    text = ABSURD["random-patch-count"].replace(f"count = {2**31 + 1}", f"count = {2**30 + 1}")
    text += text[text.index("[[geometry.parts]]"):]
    with pytest.raises(InputError, match=re.escape(f"geometry.parts produce {2**31 + 2} particles in all")):
        build.build_particles(validate(text), MPI.COMM_SELF)


def test_box_upper_1e308_ends_with_exit_2(tmp_path):
    path = tmp_path / "bar.toml"
    path.write_text(BAR)
    proc = parsph(["run", path, "--out", tmp_path / "out", "--quiet",
                   "--set", "geometry.parts.0.upper=[1e308]"])
    assert_bad_input(proc, "geometry.parts[0]", "1e+308", "2^31")


# ------------------------------------------------------------------ 3. parameter expressions
BEYOND = "cannot be evaluated (a result beyond 1.8e308 in magnitude)"
RUNAWAY = {
    "= 10**10**10": BEYOND,
    "= 9**9**9**9": BEYOND,
    "= 2**2**2**2**2**2": BEYOND,
    "= 1e308*10": BEYOND,
    "= -1e308 - 1e308": BEYOND,
    "= 1e999": BEYOND,
    "= 10**400 / 10**399": BEYOND,
    "= (-8)**(1/3)": "cannot be evaluated (no real value)",
    "= " + "(" * 100_000 + "1" + ")" * 100_000: "characters long",
    "= " + "-" * 100_000 + "1": "characters long",
    "= " + "+".join(["n"] * 200): "characters long",
}


@pytest.mark.timeout(CEILING)  # bounded before it is computed: a hang fails the test
@pytest.mark.parametrize("expression", list(RUNAWAY), ids=lambda e: e[:24])
def test_runaway_expression_is_refused(expression):
    message = refused(SCENE, f"material.density={expression}")
    assert message.startswith("material.density: "), message
    assert RUNAWAY[expression] in message, message


def test_bounded_expressions_keep_their_type():
    scene = validate(part(HEAD_2D, shape="random_patch", lower=[0.0, 0.0], upper=[1.0, 1.0],
                          count="= n*n").replace("[material]", "[parameters]\nn = 7\n\n[material]"))
    count = scene.geometry.parts[0]["count"]
    assert count == 49 and isinstance(count, int)
    assert validate(SCENE, "material.density== 2**1000 / 2**990").material.density == 1024.0
    assert validate(SCENE, "material.density== 10**-400 + 1").material.density == 1.0
    assert validate(SCENE, "material.density== " + "-" * 290 + "5").material.density == 5.0


@pytest.mark.timeout(CEILING)
@pytest.mark.parametrize("expression", ["= 10**10**10", "= 9**9**9**9", "= " + "(" * 5000 + "1" + ")" * 5000])
def test_runaway_expression_ends_with_exit_2(expression, tmp_path):
    path = tmp_path / "bar.toml"
    path.write_text(BAR)
    proc = parsph(["check", path, "--set", f"material.density={expression}"])
    assert_bad_input(proc, "material.density")


# ------------------------------------------------------------------ 4. unreadable scene paths
@pytest.mark.skipif(not os.path.exists("/proc/self/mem"), reason="needs /proc/self/mem")
def test_scene_path_with_an_io_error():
    with pytest.raises(InputError, match=re.escape("scene file /proc/self/mem cannot be read: ")):
        config.load("/proc/self/mem")


@pytest.mark.timeout(CEILING)
def test_fifo_and_device_are_refused_without_waiting(tmp_path):
    fifo = tmp_path / "scene.toml"
    os.mkfifo(fifo)
    for path in (str(fifo), "/dev/zero"):
        message = f"scene path is not a regular file (a pipe or a device): {path}"
        with pytest.raises(InputError, match=re.escape(message)):
            config.load(path)


def test_deeply_nested_scene_file_and_override(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(InputError, match="not valid TOML: arrays or tables nested too deeply"):
        config.load(str(path))
    with pytest.raises(InputError, match=re.escape("--set walls.0.point: the value is nested too deeply")):
        config.parse_override("walls.0.point=" + "[" * 5000 + "]" * 5000)


@pytest.mark.parametrize("path", ["/proc/self/mem", "DIR"])
def test_unreadable_scene_path_ends_with_exit_2(path, tmp_path):
    path = str(tmp_path) if path == "DIR" else path
    if not os.path.exists(path):
        pytest.skip(f"no {path}")
    proc = parsph(["check", path])
    assert_bad_input(proc, path, "directory" if os.path.isdir(path) else "cannot be read")


# ------------------------------------------------------------------ 5. overlapping parts
def boxes(*specs):
    """A 2D scene of boxes (lower x, upper x, spacing, placement) on y in [0, 0.5]."""
    text = HEAD_2D
    for x0, x1, h, placement in specs:
        text += (f'[[geometry.parts]]\nshape = "box"\nlower = [{x0}, 0.0]\nupper = [{x1}, 0.5]\n'
                 f'spacing = {h}\nplacement = "{placement}"\n')
    return text


def built(text, capsys):
    """(particle count, warnings printed) of the single-process build of `text`."""
    capsys.readouterr()
    count = len(build.build_particles(validate(text), MPI.COMM_SELF)["gid"])
    return count, [line for line in capsys.readouterr().err.splitlines() if "warning" in line]


@pytest.mark.parametrize("placement", ["cell", "node"])
def test_parts_overlapping_by_half_a_cell_warn(placement, capsys):
    count, warnings = built(boxes((0.0, 1.0, 0.05, placement), (0.975, 1.975, 0.05, placement)), capsys)
    nodes = int(placement == "node")
    assert count == 2 * (20 + nodes) * (10 + nodes)  # both kept
    close = 10 if placement == "cell" else 2 * 11  # node lattices: two columns of parts[1]
    assert warnings == [
        f"parsph: warning: geometry.parts[0] and geometry.parts[1] overlap: {close} particles of "
        f"parts[1] lie within half a spacing (0.025) of parts[0]'s particles (not coincident, so both "
        f"are kept and the density doubles there)"]


def test_interleaved_parts_warn_for_each_pair(capsys):
    _, warnings = built(boxes((0.0, 1.0, 0.1, "cell"), (0.53, 1.53, 0.1, "cell"), (2.0, 3.0, 0.05, "cell"),
                              (2.26, 2.76, 0.05, "cell")), capsys)
    pairs = [re.search(r"parts\[(\d)\] and geometry.parts\[(\d)\]", w).groups() for w in warnings]
    assert pairs == [("0", "1"), ("2", "3")]


@pytest.mark.parametrize("specs", [
    [(0.0, 1.0, 0.05, "cell"), (1.0, 2.0, 0.05, "cell")],
    [(0.0, 1.0, 0.1, "cell"), (1.0, 2.0, 0.05, "cell"), (2.0, 2.5, 0.025, "cell")],
    [(0.0, 1.0, 0.1, "node"), (1.0, 2.0, 0.05, "node")],
    [(0.0, 1.0, 0.05, "node"), (1.0, 2.0, 0.05, "node")],
], ids=["cell", "cell-three-spacings", "node-two-spacings", "node"])
def test_touching_parts_do_not_warn(specs, capsys):
    _, warnings = built(boxes(*specs), capsys)
    assert warnings == []


def test_coincident_parts_merge_silently(capsys):
    count, warnings = built(boxes((0.0, 1.0, 0.05, "cell"), (0.5, 1.5, 0.05, "cell")), capsys)
    assert count == 30 * 10
    assert warnings == []


@pytest.mark.mpi
def test_overlap_warning_on_two_ranks_is_printed_once(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(boxes((0.0, 1.0, 0.05, "cell"), (0.975, 1.975, 0.05, "cell")))  # overlap at the rank cut
    proc = parsph(["run", path, "--out", tmp_path / "out", "--quiet", "--set", "time.max_steps=1"], ranks=2)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.count("overlap") == 1, proc.stderr  # once, not once per rank
    assert "geometry.parts[0] and geometry.parts[1] overlap: 10 particles of parts[1]" in proc.stderr


# ------------------------------------------------------------------ 6. a condition's duration
@pytest.mark.parametrize("duration", ["0", "-1.0e-3"])
def test_bc_duration_must_be_positive(duration, tmp_path):
    """A condition acts for t < duration: a duration of 0 or less would never act."""
    assert f"bc[0].duration must be > 0 (got {float(duration)})" in refused(SCENE, f"bc.0.duration={duration}")
    path = tmp_path / "bar.toml"
    path.write_text(BAR)
    proc = parsph(["check", path, "--set", f"bc.0.duration={duration}"])
    assert_bad_input(proc, "bc[0].duration must be > 0")
