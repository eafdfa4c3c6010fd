"""`parsph run --profile`: what each stage of the step does with the core.

One step of the run (the first past half its time or steps) is recorded: every call of a
compiled kernel made from Python (the stages', the stable step's, the integrator's) is
logged with its arguments and the stage it serves. After that step, for each logged call:

- bytes: the sizes of its array arguments, each buffer once: the traffic if the kernel
  streams each input and output once from memory (gathers of neighbours' values that miss
  the caches cost more, reuse from the caches less);
- flops: counted, not modelled: the kernel's Python source is run on a sample of its
  particles (calls over a range lo..hi of particles) or in full (small calls), on the
  arrays as the step left them, with every float read as a `Counted` value that counts each
  arithmetic operation and elementary function done on it, the writes kept aside; the
  sample's count is scaled to the range. Work done in numpy between kernels is not counted.

The per-stage figures are set against this core's theoretical peak (its clock and vector
width from /proc/cpuinfo, two fused multiply-add units) and its measured memory bandwidth
(a compiled triad over arrays far beyond the caches). `report` adds pairs and bytes per
particle (the arrays the simulation holds, `arrays_held`)."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import operator
import sys
import time

import numpy as np
from numba import njit
from numba.core.registry import CPUDispatcher

from parsph import pair_lanes
from parsph.formulations.base import CompiledOnce

SAMPLE = 64  # particles whose flops are counted per call over a range
FULL_LIMIT = 20000  # float elements up to which a call not over a range is counted in full


class Counted:
    """A float that counts the arithmetic done on it (class-wide `count`)."""

    __slots__ = ("v",)
    count = 0

    def __init__(self, v):
        self.v = float(v)

    def __float__(self):
        return self.v

    def __int__(self):
        return int(self.v)

    def __neg__(self):
        return Counted(-self.v)

    def __pos__(self):
        return self

    def __abs__(self):
        return Counted(abs(self.v))

    def __bool__(self):
        return bool(self.v)

    def __hash__(self):
        return hash(self.v)


def _value(x):
    return x.v if isinstance(x, Counted) else x


def _arithmetic(op, reflected=False):
    def apply(a, b):
        Counted.count += 1
        return Counted(op(_value(b), _value(a)) if reflected else op(_value(a), _value(b)))
    return apply


for _name in ("add", "sub", "mul", "truediv", "pow", "floordiv", "mod"):
    setattr(Counted, f"__{_name}__", _arithmetic(getattr(operator, _name)))
    setattr(Counted, f"__r{_name}__", _arithmetic(getattr(operator, _name), reflected=True))
for _name in ("lt", "le", "gt", "ge", "eq", "ne"):
    setattr(Counted, f"__{_name}__", lambda a, b, op=getattr(operator, _name): op(a.v, _value(b)))


class CountingArray:
    """A float array as a kernel's Python source sees it while flops are counted: elements
    read as Counted, writes kept in `writes` (the array itself is not changed)."""

    def __init__(self, base: np.ndarray, prefix: tuple = (), writes: dict | None = None):
        self.base, self.prefix = base, prefix
        self.writes = {} if writes is None else writes
        self.shape = base.shape[len(prefix):]
        self.ndim = len(self.shape)
        self.size = math.prod(self.shape)

    def __len__(self):
        return self.shape[0]

    def _index(self, key) -> tuple:
        key = self.prefix + (key if isinstance(key, tuple) else (key,))
        if not all(isinstance(k, (int, np.integer)) for k in key):
            raise TypeError("only element and row indexing is counted")
        return tuple(int(k) for k in key)

    def __getitem__(self, key):
        parts = key if isinstance(key, tuple) else (key,)
        if any(isinstance(k, slice) for k in parts):  # a view: read through, its own writes
            return CountingArray(self.base[self.prefix + parts])
        index = self._index(key)
        if len(index) < self.base.ndim:
            return CountingArray(self.base, index, self.writes)
        if index in self.writes:
            return self.writes[index]
        return Counted(self.base[index])

    def __setitem__(self, key, value):
        index = self._index(key)
        if len(index) < self.base.ndim:
            raise TypeError("only element writes are counted")
        self.writes[index] = value


def _counted_array(shape, fill=0.0) -> np.ndarray:
    out = np.empty(shape, dtype=object)
    out.ravel()[:] = [Counted(fill) for _ in range(out.size)]
    return out


class _NumpyForCounting:
    """numpy as a kernel's source sees it while flops are counted: new float arrays hold
    Counted values."""

    def __getattr__(self, name):
        return getattr(np, name)

    @staticmethod
    def empty(shape, dtype=float):
        return _counted_array(shape) if dtype in (float, np.float64) else np.empty(shape, dtype)

    zeros = empty

    @staticmethod
    def full(shape, value, dtype=float):
        return _counted_array(shape, value) if dtype in (float, np.float64) else np.full(shape, value, dtype)


class _MathForCounting:
    """math as a kernel's source sees it while flops are counted: each function on floats
    counts one operation."""

    def __getattr__(self, name):
        function = getattr(math, name)
        if not callable(function):
            return function

        def apply(*args):
            out = function(*(_value(a) for a in args))
            if isinstance(out, float):
                Counted.count += 1
                return Counted(out)
            if isinstance(out, tuple):
                Counted.count += 1
                return tuple(Counted(x) if isinstance(x, float) else x for x in out)
            return out
        return apply


def _parsph_modules() -> list:
    """parsph's modules but this one."""
    return [m for name, m in sorted(sys.modules.items())
            if name.startswith("parsph.") and name != __name__ and m is not None]


@dataclasses.dataclass
class Call:
    stage: str
    kernel: object  # the compiled function (a numba dispatcher)
    args: tuple


class Recorder:
    """Logs the compiled kernels' calls of one step (see the module's docstring)."""

    def __init__(self, sim):
        self.calls: list[Call] = []
        self.labels = {stage.run.__code__: stage.name for body in sim.state.bodies for stage in body.stages}
        self.labels[type(sim.stable).limit.__code__] = "stable step"
        self.labels[type(sim.topology).move.__code__] = "reference update"
        self.labels[type(sim).step.__code__] = "integration"
        self.patched: list = []

    def _stage(self) -> str:
        frame = sys._getframe(2)
        while frame is not None:
            label = self.labels.get(frame.f_code)
            if label:
                return label
            frame = frame.f_back
        return "other"

    def _wrap(self, kernel):
        def call(*args):
            self.calls.append(Call(self._stage(), kernel, args))
            return kernel(*args)
        return call

    def __enter__(self):
        try:
            for module in _parsph_modules():
                for name, value in list(vars(module).items()):
                    if isinstance(value, CPUDispatcher):
                        self.patched.append((module, name, value))
                        setattr(module, name, self._wrap(value))
            for once in _compiled_once():
                self.patched.append((once, "kernel", once.kernel))
                once.kernel = self._wrap(once.kernel)
        except BaseException:  # nothing is left wrapped: the compiled code's globals are its own again
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc):
        for owner, name, value in reversed(self.patched):
            setattr(owner, name, value)
        self.patched = []


def _compiled_once() -> list:
    import gc

    # by type, not isinstance: that would ask a weak proxy among the objects for its referent,
    # which may be gone
    return [obj for obj in gc.get_objects() if type(obj) is CompiledOnce]


def traffic(args: tuple) -> int:
    """Bytes of the array arguments, each buffer once."""
    seen, total = set(), 0
    for a in args:
        if isinstance(a, np.ndarray):
            base = a if a.base is None else a.base
            if id(base) not in seen:
                seen.add(id(base))
                total += a.nbytes
    return total


def count_flops(call: Call) -> float | None:
    """Floating-point operations of the call (module docstring); None if its source cannot
    be run with counted values."""
    kernel = call.kernel
    args = call.args
    ranged = len(args) > 2 and all(isinstance(a, (int, np.integer)) for a in args[:2]) and args[1] > args[0]
    if not ranged and sum(a.size for a in args if isinstance(a, np.ndarray) and a.dtype == np.float64) > FULL_LIMIT:
        return None
    counted = tuple(CountingArray(a) if isinstance(a, np.ndarray) and a.dtype == np.float64 else a for a in args)
    try:
        with python_sources(counting=True):
            source = kernel.py_func
            Counted.count = 0
            if not ranged:
                source(*counted)
                return float(Counted.count)
            lo, hi = int(args[0]), int(args[1])
            picks = np.unique(np.linspace(lo, hi - 1, min(SAMPLE, hi - lo)).astype(np.int64))
            for i in picks:
                source(int(i), int(i) + 1, *counted[2:])
            return Counted.count * (hi - lo) / len(picks)
    except Exception:  # noqa: BLE001 - a construct the counting types do not follow
        return None


@contextlib.contextmanager
def python_sources(counting: bool = False):
    """Within, parsph's compiled functions are their Python sources: the sources call each
    other's sources, not machine code, and the compiled-only helpers (pair_lanes' intrinsics)
    are numpy and Python equivalents. With `counting`, new float arrays hold Counted values
    and math's functions count (count_flops)."""
    lanes = (lambda rows: _counted_array((rows, pair_lanes.LANES))) if counting else (
        lambda rows: np.zeros((rows, pair_lanes.LANES)))
    intrinsics = ((pair_lanes.lane_block, lanes), (pair_lanes.quotient, operator.truediv))
    restore = []
    try:
        for module in _parsph_modules():
            for name, value in list(vars(module).items()):
                if isinstance(value, CPUDispatcher):
                    restore.append((module, name, value))
                    setattr(module, name, value.py_func)
                for intrinsic, python in intrinsics:
                    if value is intrinsic:
                        restore.append((module, name, value))
                        setattr(module, name, python)
            for name, proxy in (("np", _NumpyForCounting()), ("math", _MathForCounting())) if counting else ():
                if getattr(module, name, None) in (np, math):
                    restore.append((module, name, getattr(module, name)))
                    setattr(module, name, proxy)
        yield
    finally:
        for owner, name, value in reversed(restore):
            setattr(owner, name, value)


@njit(cache=True)
def _triad(a, b, c, s):
    for i in range(len(a)):
        a[i] = b[i] + s * c[i]


def memory_bandwidth() -> float:
    """Bytes per second of a compiled triad a = b + s c over 3 x 32 MB (best of 5)."""
    n = 4_000_000
    a, b, c = np.zeros(n), np.ones(n), np.ones(n)
    _triad(a, b, c, 0.5)
    best = math.inf
    for _ in range(5):
        start = time.perf_counter()
        _triad(a, b, c, 0.5)
        best = min(best, time.perf_counter() - start)
    return 24.0 * n / best


def peak_flops() -> tuple[float, str]:
    """This core's theoretical peak in double precision (flop/s) and how it was found:
    clock x 2 fused multiply-add units x the vector width, from /proc/cpuinfo."""
    try:
        with open("/proc/cpuinfo") as fh:
            text = fh.read()
    except OSError:
        return math.nan, "no /proc/cpuinfo"
    mhz = [float(line.split(":")[1]) for line in text.splitlines() if line.startswith("cpu MHz")]
    flags = next((line.split(":")[1].split() for line in text.splitlines() if line.startswith("flags")), [])
    lanes = 8 if "avx512f" in flags else 4 if "avx" in flags else 2
    per_cycle = 2 * lanes * (2 if "fma" in flags else 1)  # two vector units, a multiply and an add each
    if not mhz:
        return math.nan, "no clock in /proc/cpuinfo"
    return mhz[0] * 1e6 * per_cycle, f"{mhz[0]:.0f} MHz x {per_cycle} flop/cycle"


def arrays_held(obj, prefix: str = "", seen: set | None = None, out: list | None = None, depth: int = 0) -> list:
    """(name, array) for every numpy array reachable from obj's attributes, dicts, lists
    and dataclass fields, five levels of them deep, each buffer once (a view, or the
    total-Lagrangian d = u, is counted under the first name found)."""
    seen = set() if seen is None else seen
    out = [] if out is None else out
    if isinstance(obj, np.ndarray):
        base = obj if obj.base is None else obj.base
        if id(base) not in seen and obj.nbytes:
            seen.add(id(base))
            out.append((prefix, obj))
        return out
    if depth > 4:
        return out
    if isinstance(obj, dict):
        items = obj.items()
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        items = ((f.name, getattr(obj, f.name)) for f in dataclasses.fields(obj))
    elif hasattr(obj, "__dict__") and type(obj).__module__.startswith("parsph"):
        items = vars(obj).items()
    elif isinstance(obj, (list, tuple)):
        items = ((str(k), v) for k, v in enumerate(obj))
    else:
        return out
    for name, value in items:
        arrays_held(value, f"{prefix}.{name}" if prefix else str(name), seen, out, depth + 1)
    return out


class Profile:
    """The recorded step's per-stage flops and bytes, and the core's limits."""

    def __init__(self):
        self.step = 0
        self.flops: dict = {}  # stage -> flops of the recorded step on this rank
        self.bytes: dict = {}
        self.partial: set = set()  # stages with a call whose flops were not counted
        self.uncounted: set = set()  # the kernels of those calls

    def record(self, sim, step) -> float:
        """Take one step (`step()`, returning its dt) with the kernels' calls logged, then
        count them."""
        with Recorder(sim) as recorder:
            dt = step()
        self.step = sim.step_count
        for call in recorder.calls:
            flops = count_flops(call)
            if flops is None:
                self.partial.add(call.stage)
                self.uncounted.add(call.kernel.py_func.__name__)
            self.flops[call.stage] = self.flops.get(call.stage, 0.0) + (flops or 0.0)
            self.bytes[call.stage] = self.bytes.get(call.stage, 0) + traffic(call.args)
        return dt

    def report(self, sim, worst: dict, steps: int) -> list:
        """Collective: lines of the per-stage table (the slowest rank's time per step in
        `worst`, seconds over `steps` steps) and the rank-summed pairs and bytes."""
        comm = sim.comm
        names = list(worst)
        local = np.array([[self.flops.get(k, 0.0), self.bytes.get(k, 0)] for k in names] or np.zeros((0, 2)))
        held = sum(a.nbytes for _, a in arrays_held(sim))
        counts = np.array([sim.state.n_owned, sim.topology.pair_count(), held], float)
        if comm.size > 1:
            local = comm.allreduce(local)
            counts = comm.allreduce(counts)
            self.partial = set().union(*comm.allgather(self.partial))
            self.uncounted = set().union(*comm.allgather(self.uncounted))
        particles, pairs, held = counts
        peak, how = peak_flops()
        bandwidth = memory_bandwidth()
        lines = [f"parsph: profile of step {self.step} (flops counted, bytes = array arguments once; per core: "
                 f"peak {peak / 1e9:.1f} GFLOP/s from {how}, memory {bandwidth / 1e9:.1f} GB/s measured):",
                 f"  {'stage':<22}{'ms/step':>9}{'%':>5}{'flop/particle':>15}{'GFLOP/s':>9}{'% peak':>8}"
                 f"{'B/particle':>12}{'GB/s':>7}{'% memory':>10}"]
        total = sum(worst.values())
        for (name, seconds), (flops, nbytes) in zip(worst.items(), local):
            per_step = seconds / steps
            core_seconds = per_step * comm.size
            rate = flops / core_seconds if core_seconds else 0.0
            data = nbytes / core_seconds if core_seconds else 0.0
            counted = name not in self.partial
            flop_cells = (f"{flops / particles:>15.0f}{rate / 1e9:>9.2f}{100 * rate / peak:>8.1f}" if counted and flops
                          else f"{'-':>15}{'-':>9}{'-':>8}")
            byte_cells = (f"{nbytes / particles:>12.0f}{data / 1e9:>7.2f}{100 * data / bandwidth:>10.1f}" if nbytes
                          else f"{'-':>12}{'-':>7}{'-':>10}")
            lines.append(f"  {name:<22}{1e3 * per_step:>9.3f}{100 * seconds / total:>5.0f}{flop_cells}{byte_cells}")
        lines.append(f"  {pairs / particles:.1f} pairs per particle; the simulation's arrays {held / particles:.0f} B per "
                     f"particle; peak resident memory {peak_memory(comm) / 1e6:.0f} MB (largest rank)")
        if self.uncounted:
            lines.append(f"  flops not counted (their source does not run on counted values): "
                         f"{', '.join(sorted(self.uncounted))}")
        return lines


def peak_memory(comm) -> float:
    """The largest rank's peak resident memory in bytes (collective)."""
    import resource

    from mpi4py import MPI

    return comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024.0, op=MPI.MAX)
