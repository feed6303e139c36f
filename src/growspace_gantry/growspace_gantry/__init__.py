"""growspace_gantry: an LED gantry (GRBL 1.1 over serial) on the GrowSpace chamber topics.

Layers: ``grbl`` (the protocol, pure), ``position`` (which reported positions to believe, pure),
``motion`` (a jog's life as GRBL allows it, pure), ``link`` (bytes over pyserial),
``calibration`` (chamber metres -> machine millimetres), ``controller`` (one GRBL machine:
connection, streaming, reports), ``safety`` (the safety rules, in one place), ``node`` (topics,
lockstep, recording), ``status`` (``gantry/status``), ``main`` (rclpy).
"""
