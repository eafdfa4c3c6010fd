"""MPI runtime: communicator, collective error handling, domain decomposition, halo exchange."""
