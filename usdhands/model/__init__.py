"""The data model: skeletons, clips, hand maps and rotation helpers (numpy and scipy only)."""

from usdhands.model.clip import Clip
from usdhands.model.finger_dofs import FingerCurves, apply_finger_curves, finger_curves
from usdhands.model.handmap import FINGERS, SIDES, HandMap, HandSide
from usdhands.model.skeleton import Skeleton, forward_kinematics

__all__ = [
    "Clip", "Skeleton", "forward_kinematics", "HandMap", "HandSide", "FINGERS", "SIDES",
    "FingerCurves", "finger_curves", "apply_finger_curves",
]
