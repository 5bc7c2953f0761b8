"""The truth simulator: plant, tasks and reference trajectories."""
