"""Transition re-exports: the detectors moved to :mod:`hd_onboard.detectors` (one module per detector)
and the threshold arithmetic to :mod:`hd_onboard.calibration`.

Only the names the node modules (``hd_onboard.node``, ``hd_twin.node``) still import from here are
kept; every other importer uses the new modules. Delete this module once the node shells import
from :mod:`hd_onboard.detectors` (issue 16).
"""

from hd_onboard.detectors.ewma import ChannelThreshold  # noqa: F401
from hd_onboard.detectors.friction import FrictionReference  # noqa: F401
from hd_onboard.detectors.levels import LEVEL_NAMES, OK, STALE  # noqa: F401
from hd_onboard.detectors.stiffness import StiffnessReference  # noqa: F401
