"""parsph: MPI-parallel corrected SPH for fast-transient solid mechanics."""

__version__ = "0.1.0"
