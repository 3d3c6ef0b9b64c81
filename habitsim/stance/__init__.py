"""Stance: which feet are on the ground when, and keeping them there.

The stance labels of a clip, where they came from and every edit made to them, and the
torch-free algorithms that make and change them (planting, the footfall schedule,
conforming a decoded motion) live here, below the importer, refinement and the learning
core that use them.
"""
