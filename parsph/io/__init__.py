"""Output files: history time series and particle snapshots."""
