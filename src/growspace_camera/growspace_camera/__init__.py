"""The GrowSpace chamber's camera: photos of the real plant turned into the simulator's
observation, plant state and reward (``camera_node``), and the photo twin that measures it.

Nothing of this package is imported by ``growspace_sim``.
"""
