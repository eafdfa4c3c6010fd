"""`parsph run --profile`: flops counted from the kernels' source, and a profiled run the
same bit for bit as an unprofiled one."""

from __future__ import annotations

import numpy as np
from numba import njit

from conftest import RUNS, parsph
from parsph.profile import Call, Recorder, count_flops, traffic


@njit
def _axpy_norm(lo, hi, a, x, y, out):
    """out_i = 2 ((a x_i + y_i)^2)^(1/2): 5 operations per particle (a multiply, an add, the
    square, the power, the last multiply)."""
    for i in range(lo, hi):
        s = a[0] * x[i] + y[i]
        out[i] = (s * s) ** 0.5 * 2.0


@njit
def _dot(x, y):
    total = 0.0
    for i in range(len(x)):
        total += x[i] * y[i]
    return total


def test_flops_are_counted_from_the_source_and_scaled_from_a_sample_to_the_range():
    n = 1000
    x, y, out = np.ones(n), np.ones(n), np.zeros(n)
    flops = count_flops(Call("stage", _axpy_norm, (0, n, np.array([2.0]), x, y, out)))
    assert flops == 5 * n  # 64 particles counted, scaled to the 1000
    assert np.all(out == 0.0)  # the count does not write
    assert count_flops(Call("stage", _dot, (x[:50], y[:50]))) == 100  # not over a range: in full
    assert traffic((0, n, x, y, x[:10], out)) == 3 * 8 * n  # each buffer once


def test_a_profiled_run_prints_the_stage_table_and_computes_the_same(tmp_path):
    common = ["run", RUNS / "bar1d.toml", "--quiet", "--set", "time.end=2e-4", "--set", "output.snapshot_interval=1e-4"]
    plain = parsph([*common, "--out", tmp_path / "plain"])
    profiled = parsph([*common, "--out", tmp_path / "profiled", "--profile"])
    assert plain.returncode == 0 and profiled.returncode == 0, profiled.stderr
    lines = profiled.stdout.splitlines()
    table = lines[next(k for k, line in enumerate(lines) if "profile of step" in line) + 2:]
    rows = {line.split()[0]: line.split()[1:] for line in table if line.startswith("  ") and "pairs" not in line}
    flops_per_particle = float(rows["kinematics+stress"][2])
    assert flops_per_particle > 10  # the deformation gradient and the stress, at least
    assert "pairs per particle" in profiled.stdout
    from parsph.io import read_history

    a, b = read_history(str(tmp_path / "plain" / "history.h5")), read_history(str(tmp_path / "profiled" / "history.h5"))
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


def test_the_recorder_passes_dead_weak_proxies_and_leaves_nothing_wrapped():
    """The recorder finds the stage kernels among all live objects; a weak proxy whose
    referent is gone is among them in a long process (the test suite's workers) and must not
    stop it, and after it every compiled function is its own again."""
    import gc
    import weakref

    from numba.core.registry import CPUDispatcher

    from parsph.formulations import tlsph
    from physics import simulation

    class Referent:
        pass

    referent = Referent()
    proxy = weakref.proxy(referent)
    del referent
    gc.collect()
    sim = simulation("bar1d")
    sim.step()
    with Recorder(sim) as recorder:
        sim.step()
    assert any(call.kernel.py_func.__name__ == "forces" for call in recorder.calls)
    assert isinstance(tlsph.corrected_gradient_row, CPUDispatcher)
    assert type(proxy) is weakref.ProxyType
