"""Fleet drivers for the `looming` binary: `looming_fleet.ray` runs one Ray task per log."""
