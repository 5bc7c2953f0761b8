"""Foundation: errors and atomic file output; imports nothing of omavctl."""
