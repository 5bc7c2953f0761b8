"""Learning from logs: residuals, point selection, effect estimation, the GP, the model file."""
