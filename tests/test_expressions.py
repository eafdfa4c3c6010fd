"""Initial fields written as expressions of position (parsph/expressions.py, initial types
velocity_field and displacement_field): what they set, and what they refuse."""

from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import parsph_batch
from parsph.errors import InputError
from physics import block_2d, scene_from, simulation

FIELD = """
[parameters]
a = 3.0
[[initial]]
type = "{kind}"
group = "all"
expression = {expression}
[groups.all]
all = true
"""


def scene_text(expression, kind="velocity_field"):
    return block_2d() + FIELD.format(kind=kind, expression=expression)


def test_velocity_and_displacement_fields_take_the_value_of_the_expression_at_each_particle():
    sim = simulation(scene_text('["exp(-a*(x-0.5)**2) * sin(y)", "-y/2 + minimum(x, 0.3)"]'))
    X, v = sim.quantity("reference_position"), sim.quantity("velocity")
    assert np.allclose(v[:, 0], np.exp(-3.0 * (X[:, 0] - 0.5) ** 2) * np.sin(X[:, 1]), rtol=1e-15, atol=0)
    assert np.allclose(v[:, 1], -X[:, 1] / 2 + np.minimum(X[:, 0], 0.3), rtol=1e-15, atol=1e-17)
    sim = simulation(scene_text('["1e-3*x*y", "0"]', kind="displacement_field"))
    assert np.allclose(sim.quantity("displacement")[:, 0], 1e-3 * X[:, 0] * X[:, 1], rtol=1e-15, atol=0)
    assert not sim.quantity("velocity").any()


@pytest.mark.parametrize("expression, message", [
    ('["__import__(\'os\').getcwd()", "0"]', "may use numbers"),
    ('["x.real", "0"]', "may use numbers"),
    ('["exp(x, 2)", "0"]', "may use numbers"),
    ('["b * x", "0"]', "unknown name 'b'"),
    ('["z", "0"]', "unknown name 'z'"),
    ('["x +", "0"]', "is not an expression"),
    ('["1", "2", "3"]', "must have 2 components"),
    ('["' + "(" * 200 + "x" + ")" * 200 + '", "0"]', "characters long"),
])
def test_anything_but_arithmetic_of_position_and_parameters_is_refused(expression, message):
    with pytest.raises(InputError, match=message):
        scene_from(scene_text(expression))


NOT_FINITE = [
    ('["log(x - 0.5)", "0"]', r"initial\[0\].expression\[0\] = 'log\(x - 0.5\)' is nan at particle 0"),
    ('["10.0**400 * x", "0"]', "is inf at particle 0"),
    ('["1/(x - x)", "0"]', "is inf at particle 0"),
]


@pytest.mark.parametrize("ranks", [1, pytest.param(2, marks=pytest.mark.mpi)])
def test_a_value_that_is_not_finite_ends_the_run_with_exit_2_naming_the_particle(ranks, tmp_path):
    """Each of NOT_FINITE; the runs one after another in one MPI job (conftest.parsph_batch)."""
    commands = []
    for k, (expression, _) in enumerate(NOT_FINITE):
        path = tmp_path / f"block{k}.toml"
        path.write_text(scene_text(expression))
        commands.append(["run", path, "--out", tmp_path / f"out{k}", "--quiet"])
    for (expression, message), proc in zip(NOT_FINITE, parsph_batch(commands, ranks, tmp_path / "batch")):
        assert proc.returncode == 2, f"{expression}: {proc.stderr}"
        assert "Traceback" not in proc.stderr
        assert re.search(message, proc.stderr), proc.stderr
