"""Output files: history time series and particle snapshots, and reading them back
(read_history, read_snapshots)."""

from parsph.io.results import Snapshot, read_history, read_snapshots, snapshot_steps

__all__ = ["Snapshot", "read_history", "read_snapshots", "snapshot_steps"]
