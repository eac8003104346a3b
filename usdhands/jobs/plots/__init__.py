"""PNG plots the jobs write with their ``plot`` option (matplotlib, Agg backend, imported on use)."""
