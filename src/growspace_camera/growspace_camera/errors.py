"""The camera's one error type: a photo that could not be read, with a reason a program can use.

A step that cannot read its photo raises ``CameraError`` instead of returning a number; the
node turns it into a measurement with ``ok = false`` and the reason, never into a reward.
"""

from __future__ import annotations

# Reasons, in the order a photo meets them (``CameraError.code``).
NO_PHOTO = 'no_photo'  # the source gave no frame (device missing, end of a file)
EXPOSURE = 'exposure'  # too dark or overexposed to read
MARKERS = 'markers'  # too few markers for a fit and no last good fit to hold
FIT = 'fit'  # the markers do not agree with the layout (moved, misprinted, wrong ids)
NO_PLANT = 'no_plant'  # nothing plant-like in the chamber (an empty pot)
PLANTS = 'plants'  # not as many stem bases as the challenge has plants, or plants not told apart
UNEXPLAINED = 'unexplained'  # most of the plant mask is not part of any plant from a stem base
BAD_INPUT = 'bad_input'  # a request the camera cannot serve (unknown challenge, bad target)
CODES = (NO_PHOTO, EXPOSURE, MARKERS, FIT, NO_PLANT, PLANTS, UNEXPLAINED, BAD_INPUT)


class CameraError(Exception):
    """A photo the pipeline could not read, or a request it could not serve.

    Attributes:
        code: One of ``CODES``: what went wrong, for programs (logs, status, tests).
        message: What went wrong and what was seen, for people.
    """

    def __init__(self, code: str, message: str) -> None:
        if code not in CODES:
            raise ValueError(f'code must be one of {CODES}, got {code!r}.')
        super().__init__(message)
        self.code = code
        self.message = message

    def __str__(self) -> str:
        return f'{self.code}: {self.message}'
