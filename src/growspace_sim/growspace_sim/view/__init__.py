"""What a person looks at: 3D markers and a human-size image of a chamber, built from its topics.

Pure modules (numpy, OpenCV and our message codec; no rclpy), so ``view_node``, a benchmark
and a test build the same frames:

- ``scene``: collects ``chamber/config``, ``plant/state``, ``light/state`` and ``step_result``
  into one ``Frame`` per tick; target and photons come from a ``Simulation`` rebuilt from the
  config and seed and kept in step (see ``Scene``).
- ``markers``: a ``visualization_msgs/MarkerArray`` of a frame (frame ``chamber``, metres).
- ``image``: an anti-aliased RGB view image of a frame with a text overlay.
- ``marker_png``: a MarkerArray drawn from the front, as RViz shows it (README picture).
- ``sample``: the messages of a seeded episode, built in process (benchmark, tests).
- ``foxglove_server``: the Foxglove WebSocket server (needs ``foxglove-sdk``; not imported here).
"""

from growspace_sim.view.scene import Frame, Scene, ViewInputError

__all__ = ['Frame', 'Scene', 'ViewInputError']
