"""The field registry: a field declared in one place (tests/mpi/field_plugin.py) migrates
with its particle across ranks, is written to checkpoints, survives a restart on another
rank count and appears in the snapshots, with no other change to the code. And the
derivations the registry replaces: which fields migrate, checkpoint and how they mirror."""

from __future__ import annotations

import subprocess
import sys

import h5py
import numpy as np
import pytest

from conftest import CEILING, ROOT, mpiexec
from parsph.io import read_snapshots

PLUGIN = ROOT / "tests" / "mpi" / "field_plugin.py"

# A block (with a tab that makes the ranks' work unequal) turning by about 45 degrees,
# with the updated reference, re-partitioned at every update (every 10 steps): the
# ownership cut stays across the x axis while the body turns, so particles change ranks.
SCENE = """
[scene]
name = "field_plugin"
dimension = 2
[[geometry.parts]]
shape = "box"
lower = [0.0, 0.0]
upper = [1.2, 0.8]
spacing = 0.1
[[geometry.parts]]
shape = "box"
lower = [0.0, 0.8]
upper = [0.2, 1.0]
spacing = 0.1
[kernel]
type = "wendland_c2"
support = 2.5
[material]
model = "neo_hookean"
density = 1000.0
youngs_modulus = 1.0e6
poisson_ratio = 0.3
[formulation]
type = "ulsph"
update_every = 10
[parallel]
rebalance = 0.0
[[initial]]
type = "angular_velocity"
omega = [30.0]
center = [0.6, 0.4]
[time]
end = 1.0
max_steps = 60
cfl = 0.3  # about a quarter turn in 60 steps
[output]
history_every = 10
snapshot_interval = 1.0e-3
snapshot_fields = ["position", "reference_position", "rank", "tag", "velocity"]
checkpoint_every = 30
"""


def _plugin(args, ranks):
    cmd = [sys.executable, str(PLUGIN), *map(str, args)]
    if ranks > 1:
        cmd = [mpiexec(), "-n", str(ranks), *cmd]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=CEILING, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc


def _snapshots(out):
    return [snapshot.fields for snapshot in read_snapshots(out, which=[0, -1])]


@pytest.mark.mpi
def test_a_field_declared_in_one_place_migrates_checkpoints_restarts_and_shows(tmp_path):
    sys.path.insert(0, str(PLUGIN.parent))
    from field_plugin import tag

    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    straight, split = tmp_path / "straight", tmp_path / "split"
    _plugin(["run", scene, "--out", straight, "--quiet"], ranks=2)
    first, last = _snapshots(straight)
    # the field followed its particle: it still names the particle's id and reference position
    X = last["reference_position"][:, :2]
    assert last["tag"].shape == last["gid"].shape
    assert np.array_equal(last["tag"], tag(X, last["gid"]))
    assert np.count_nonzero(first["rank"] != last["rank"]) > 5  # particles changed ranks
    with h5py.File(straight / "checkpoints" / "step_00000060.h5", "r") as f:
        assert np.array_equal(f["tag"][()], last["tag"])  # stored in the checkpoint, in gid order
    # stopped at step 30 on 2 ranks, continued from the checkpoint on 1 rank
    _plugin(["run", scene, "--out", split, "--quiet", "--set", "time.max_steps=30"], ranks=2)
    _plugin(["run", scene, "--out", split, "--quiet", "--restart", "latest"], ranks=1)
    compare = subprocess.run([sys.executable, str(ROOT / "tools" / "compare_outputs.py"), straight, split],
                             capture_output=True, text=True, cwd=ROOT)
    assert compare.returncode == 0, compare.stdout + compare.stderr
    assert np.array_equal(_snapshots(split)[1]["tag"], last["tag"])


def test_the_registry_decides_what_migrates_checkpoints_and_mirrors():
    from parsph import fields
    from parsph.formulations import nodal

    assert nodal.UPDATED_FIELDS  # imported: declares the updated reference's fields
    tl, ul = fields.carried({"tlsph"}), fields.carried({"ulsph", "updated"})
    assert "Xr" not in tl and {"Xr", "Fr", "measure_r", "volume_r"} <= set(ul)
    assert fields.checkpointed(ul)[:9] == ["gid", "X", "measure", "volume", "mass", "support", "groups",
                                           "u", "v"]
    sign = np.array([[-1.0, 1.0]])
    offset = np.array([[2.0, 0.0]])  # the plane x = 1
    assert np.array_equal(fields.get("X").reflect(np.array([[0.25, 3.0]]), sign, offset), [[1.75, 3.0]])
    assert np.array_equal(fields.get("u").reflect(np.array([[0.5, 3.0]]), sign, offset), [[-0.5, 3.0]])
    Fr = np.array([[[1.0, 2.0], [3.0, 4.0]]])
    assert np.array_equal(fields.get("Fr").reflect(Fr, sign, offset), [[[1.0, -2.0], [-3.0, 4.0]]])
    assert np.array_equal(fields.get("mass").reflect(np.array([7.0]), sign, offset), [7.0])
    with pytest.raises(ValueError, match="declared twice"):
        fields.register(fields.Field("X", "vector"))
