"""Example input files shipped with habitsim (see README.md in this folder)."""
