"""Physical constants and the ground-contact convention, each defined once.

Every module that needs gravity or the contact height imports it from here (the
generator, the gait statistics, the importer, the network's features, the MJCF builder,
the controllers, contact detection, the metrics, refinement, the robots).
"""

from __future__ import annotations

from typing import Final

__all__ = ["GRAVITY", "CONTACT_HEIGHT_PER_LEG"]

#: Standard gravity g [m/s²]: the species models' gravity, Froude numbers
#: (v² / (g·h)), the generator's and the controllers' dimensionless time and speed scales.
GRAVITY: Final[float] = 9.81
#: Contact height [share of the hind-leg length]: a toe lower than this over the ground
#: counts as in contact (docs/metrics.md: 2 %), for contact detection, the skating
#: metrics, a plan's contacts without labels and refinement's lowest swing clearance.
CONTACT_HEIGHT_PER_LEG: Final[float] = 0.02
