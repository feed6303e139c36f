"""The photo twin: simulated chambers drawn as a camera would see them (tests, benchmark,
and a capture source, so the whole loop runs without hardware)."""

from growspace_camera.twin.draw import PhotoTwin, TwinJitter, TwinPhoto
from growspace_camera.twin.pose import look_at_plane, Pose
from growspace_camera.twin.variation import FACTORS, HELD_OUT_FIRST, Variation

__all__ = ['FACTORS', 'HELD_OUT_FIRST', 'PhotoTwin', 'TwinJitter', 'TwinPhoto', 'Pose',
           'Variation', 'look_at_plane']
