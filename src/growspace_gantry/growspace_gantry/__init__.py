"""growspace_gantry: an LED gantry (GRBL 1.1 over serial) on the GrowSpace chamber topics.

Layers: ``grbl`` (the protocol, pure), ``link`` (bytes over pyserial), ``calibration``
(chamber metres -> machine millimetres), ``controller`` (one GRBL machine: streaming, moves,
lamp, faults), ``node`` (topics, lockstep, watchdog, e-stop, recording), ``main`` (rclpy).
"""
