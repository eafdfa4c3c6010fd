#!/usr/bin/env python3
"""Convergence of every method on Timoshenko & Goodier's cantilever (runs/cantilever.toml,
[R §9.1]): L2 error of the displacement over the particles [R eq. 71-72] and energy-norm
error of the strain over each method's own integration points [R eq. 73-74:
sqrt(sum_q w_q e:C:e / sum_q w_q eps:C:eps), e = eps_h - eps], and the error of the tip
deflection (mean over the last column), after dynamic relaxation, for n = 4, 6, 8, 12, 16,
24 particles across the depth; fitted rates against the spacing. A run is reported only if
it is at rest at the end: kinetic energy at most REST times the strain energy (a run that
is still moving, or whose motion grows, is reported as not relaxed, without errors).

usage: tools/bench_cantilever.py [--n 4 6 8 12 16 24] [--methods tlsph tlsph_a0 sph sph_fixed rlm kbm efg efg_cells]
                                 [--json results/bench_cantilever.json]
"""

from __future__ import annotations

import argparse
import json
import os
import time
import tomllib

import numpy as np

from mpi4py import MPI

from parsph import config, readouts
from parsph.analytic import timoshenko_cantilever
from parsph.build import build_local
from parsph.simulation import Simulation

METHODS = {
    "tlsph": ("corrected SPH, alpha = 50", ['formulation.type="tlsph"']),
    "tlsph_a0": ("corrected SPH, alpha = 0", ['formulation.type="tlsph"', "formulation.hourglass=0"]),
    "sph": ("symmetrised SPH", ['formulation.type="sph"']),
    "sph_fixed": ("symmetrised SPH, fixed h", ['formulation.type="sph"']),  # support 2 spacings at n = 4
    "rlm": ("RLM", ['formulation.type="rlm"']),
    "kbm": ("KBM (stress points)", ['formulation.type="kbm"']),
    "efg": ("EFG nodal", ['formulation.type="efg"']),
    "efg_cells": ("EFG cells", ['formulation.type="efg"', 'formulation.integration="cells"']),
}


REST = 1e-10  # at rest: kinetic energy at most this fraction of the strain energy


def displacement(sim: Simulation) -> np.ndarray:
    """The displacement at the owned particles: the particle values, or on an EFG body the
    MLS approximation sum_J Phi_J(X_I) u_J [R eq. 40] (its particle values are not the
    displacement there; KBM keeps the particle values, as its constraints do)."""
    n = sim.state.n_owned
    formulation = sim.state.bodies[0].formulation
    if getattr(formulation, "shape", None) != "mls":
        return sim.state.u[:n]
    c = formulation.couplings[0]
    rows = np.repeat(np.arange(len(c.ptr) - 1), np.diff(c.ptr))
    return np.stack([np.bincount(rows, c.phi * sim.state.u[c.idx, a], len(c.ptr) - 1) for a in range(sim.state.dim)],
                    axis=1)[:n]


def errors(sim: Simulation, u_h: np.ndarray | None = None) -> tuple:
    """(L2 error of the displacement u_h over the particles (default: the particle values),
    energy-norm error over the integration points)."""
    p = sim.scene.parameters
    material = sim.scene.material
    exact = lambda X: timoshenko_cantilever(X, p["L"], p["D"], material["youngs_modulus"],  # noqa: E731
                                            material["poisson_ratio"], p["P"])
    n = sim.state.n_owned
    u, _ = exact(sim.state.X[:n])
    u_h = sim.state.u[:n] if u_h is None else u_h
    w = sim.state.volume[:n, None]
    l2 = np.sqrt(np.sum(w * (u_h - u) ** 2) / np.sum(w * u ** 2))
    X, F, weight = readouts.quadrature(sim)
    _, strain = exact(X)
    strain_h = 0.5 * (F + np.transpose(F, (0, 2, 1))) - np.eye(2)
    lam, mu = sim.state.bodies[0].constants.lam, sim.state.bodies[0].constants.mu

    def energy(e):
        trace = np.trace(e, axis1=1, axis2=2)
        return np.sum(weight * (lam * trace ** 2 + 2 * mu * np.einsum("nab,nab->n", e, e)))

    return float(l2), float(np.sqrt(energy(strain_h - strain) / energy(strain)))


def tip_error(sim: Simulation, u_h: np.ndarray) -> float:
    """Relative error of the tip deflection, the mean vertical displacement of the last column."""
    p, material = sim.scene.parameters, sim.scene.material
    tip = sim.group_index("tip")
    u, _ = timoshenko_cantilever(sim.state.X[tip], p["L"], p["D"], material["youngs_modulus"],
                                 material["poisson_ratio"], p["P"])
    return float(np.mean(u_h[tip, 1]) / np.mean(u[:, 1]) - 1.0)


def scene_of(method: str, n: int) -> dict:
    """runs/cantilever.toml with the method's overrides at n particles across the depth."""
    raw_overrides = [*METHODS[method][1], f"parameters.n={n}"]
    if method == "sph_fixed":  # the support of n = 4 at every resolution
        raw_overrides.append(f"kernel.support={2.0 * n / 4}")
    with open(os.path.join(os.path.dirname(__file__), "..", "runs", "cantilever.toml"), "rb") as fh:
        raw = tomllib.load(fh)
    for text in raw_overrides:
        config.apply_override(raw, *config.parse_override(text))
    return config.validate(raw)


def run(method: str, n: int) -> dict:
    """One relaxed run; its errors only if it is at rest at the end (`relaxed`), else None."""
    scene = scene_of(method, n)
    start = time.process_time()
    sim = Simulation(scene, build_local(scene, MPI.COMM_SELF), MPI.COMM_SELF)
    end = scene.time.end
    while sim.t < end * (1 - 1e-12):
        sim.step(end)
    seconds = time.process_time() - start
    kinetic = float(0.5 * np.sum(sim.state.mass[:sim.state.n_owned, None] * sim.state.v[:sim.state.n_owned] ** 2))
    strain = sim.ledger.local(sim, "strain")
    row = {"method": method, "n": n, "particles": sim.state.n_owned, "spacing": scene.parameters["D"] / n,
           "steps": sim.step_count, "cpu_seconds": seconds, "kinetic_energy": kinetic, "strain_energy": strain,
           "relaxed": bool(kinetic <= REST * strain), "l2": None, "energy": None, "tip": None}
    if row["relaxed"]:
        u_h = displacement(sim)
        row["l2"], row["energy"] = errors(sim, u_h)
        row["tip"] = tip_error(sim, u_h)
    return row


def rate(rows: list, key: str) -> float:
    """Slope of log(error) against log(spacing) over the rows."""
    h = np.log([r["spacing"] for r in rows])
    e = np.log([r[key] for r in rows])
    return float(np.polyfit(h, e, 1)[0])


def plot(rows: list, path: str) -> None:
    """Work-precision chart of the relaxed rows: energy error against CPU time, L2 and energy
    error against the spacing, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    for method, (label, _) in METHODS.items():
        sel = [r for r in rows if r["method"] == method and r["relaxed"]]
        if not sel:
            continue
        axes[0].loglog([r["cpu_seconds"] for r in sel], [r["energy"] for r in sel], marker="o", label=label)
        axes[1].loglog([r["spacing"] for r in sel], [r["l2"] for r in sel], marker="o", label=label)
        axes[2].loglog([r["spacing"] for r in sel], [r["energy"] for r in sel], marker="o", label=label)
    axes[0].set(xlabel="CPU time [s]", ylabel="energy-norm error", title="work-precision")
    axes[1].set(xlabel="spacing", ylabel="L2 error of u", title="displacement")
    axes[2].set(xlabel="spacing", ylabel="energy-norm error", title="strain energy")
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7)
    fig.suptitle("Timoshenko-Goodier cantilever (runs/cantilever.toml)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[4, 6, 8, 12, 16, 24])
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    ap.add_argument("--json", default="results/bench_cantilever.json")
    args = ap.parse_args()
    rows = []
    for method in args.methods:
        mine = []
        for n in args.n:
            mine.append(run(method, n))
            r = mine[-1]
            head = (f"{METHODS[method][0]:26s} n = {n:3d} ({r['particles']:5d} particles, {r['steps']:6d} steps, "
                    f"{r['cpu_seconds']:.1f} s): ")
            if r["relaxed"]:
                print(head + f"L2 {r['l2']:.3e}  energy {r['energy']:.3e}  tip {r['tip']:+.3e}  "
                      f"(kinetic/strain energy {r['kinetic_energy'] / r['strain_energy']:.1e})", flush=True)
            else:
                print(head + f"NOT RELAXED: kinetic energy {r['kinetic_energy']:.3e}, "
                      f"strain energy {r['strain_energy']:.3e}", flush=True)
        relaxed = [r for r in mine if r["relaxed"]]
        if len(relaxed) > 1:
            over = "" if len(relaxed) == len(mine) else f" (over the relaxed n = {[r['n'] for r in relaxed]})"
            print(f"{METHODS[method][0]:26s} rates: L2 {rate(relaxed, 'l2'):.2f}, "
                  f"energy {rate(relaxed, 'energy'):.2f}{over}", flush=True)
        rows += mine
    os.makedirs(os.path.dirname(args.json) or ".", exist_ok=True)
    with open(args.json, "w") as fh:
        json.dump(rows, fh, indent=2)
    plot(rows, os.path.splitext(args.json)[0] + ".png")


if __name__ == "__main__":
    main()
