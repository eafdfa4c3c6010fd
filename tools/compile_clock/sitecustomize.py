"""Numba's compile time in every Python process of a test run.

tools/test puts this folder on PYTHONPATH and names a folder in PARSPH_COMPILE_LOG; Python
then loads this module at the start of every process (pytest's workers, the `parsph` runs
the tests start, every MPI rank). Once the process imports numba, a listener times each
outermost compilation (a cache miss: "numba:compile" events; loading from the on-disk
cache is not one), and at exit the process writes a line "SECONDS NAME TEST" per
compilation (TEST: the pytest test that ran, from PYTEST_CURRENT_TEST) to PID.txt in that
folder. tools/compile_clock/report.py sums them. Without
PARSPH_COMPILE_LOG it does nothing.
"""

import os

if os.environ.get("PARSPH_COMPILE_LOG"):
    import atexit
    import importlib.abc
    import importlib.util
    import sys
    import time

    _clock = {"depth": 0, "start": 0.0}
    _compiled = []  # (seconds, function name, test) of each outermost compilation

    def _listen(event):
        """Register the timer with numba.core.event (the module, just executed)."""

        class Timer(event.Listener):
            def on_start(self, ev):
                if _clock["depth"] == 0:
                    _clock["start"] = time.perf_counter()
                _clock["depth"] += 1

            def on_end(self, ev):
                _clock["depth"] -= 1
                if _clock["depth"] == 0:
                    name = getattr(ev.data["dispatcher"], "py_func", None)
                    name = getattr(name, "__qualname__", "?").replace(".<locals>.", ".")
                    test = os.environ.get("PYTEST_CURRENT_TEST", "-").split(" ")[0]
                    _compiled.append((time.perf_counter() - _clock["start"], name, test))

        event.register("numba:compile", Timer())

    class _WhenNumbaLoads(importlib.abc.MetaPathFinder):
        """Registers the timer right after numba.core.event is executed (no cost for a
        process that never imports numba)."""

        def find_spec(self, name, path, target=None):
            if name != "numba.core.event":
                return None
            sys.meta_path.remove(self)
            spec = importlib.util.find_spec(name)
            run = spec.loader.exec_module

            def exec_module(module):
                run(module)
                _listen(module)

            spec.loader.exec_module = exec_module
            return spec

    def _write():
        if _compiled:
            path = os.path.join(os.environ["PARSPH_COMPILE_LOG"], f"{os.getpid()}.txt")
            with open(path, "w") as fh:
                fh.writelines(f"{seconds:.3f} {name} {test}\n" for seconds, name, test in _compiled)

    sys.meta_path.insert(0, _WhenNumbaLoads())
    atexit.register(_write)
