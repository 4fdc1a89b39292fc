"""Runs without processes: `swarm sim` (`sim`), the batch engine (`batch`), a run's output
directory (`results`) and its CSV export (`csv_export`)."""
