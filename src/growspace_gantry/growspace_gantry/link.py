"""The serial link: moves bytes to and from the controller and reports a lost connection.

It knows nothing of GRBL beyond line endings. pyserial opens a real port (``/dev/ttyUSB0``)
or, in the tests, a pseudo-terminal: never anything else.
"""

from __future__ import annotations

from typing import Protocol


class LinkLost(Exception):
    """The port cannot be opened, or it failed while in use (unplugged, powered off)."""


class Link(Protocol):
    """What the controller needs from a byte link."""

    def write(self, data: bytes) -> None:
        """Write all of ``data``. Raises LinkLost."""

    def read_lines(self) -> list[str]:
        """Complete lines received so far, without line endings; never blocks. Raises
        LinkLost."""

    def close(self) -> None:
        """Release the port. Idempotent."""


class SerialLink:
    """A pyserial port, 8N1, read without blocking.

    Args:
        port: the device path.
        baud: the controller's baud rate (GRBL 1.1: 115200).
        write_timeout_s: how long a write may block before the link counts as lost.

    Raises:
        LinkLost: the port cannot be opened (naming the port and the OS reason).
    """

    def __init__(self, port: str, baud: int = 115200, write_timeout_s: float = 1.0) -> None:
        import serial

        self._serial_error = serial.SerialException
        try:
            self._port = serial.Serial(port, baud, timeout=0, write_timeout=write_timeout_s)
        except (serial.SerialException, OSError, ValueError) as e:
            raise LinkLost(f'cannot open {port}: {e}') from None
        self.name = port
        self._partial = b''

    def write(self, data: bytes) -> None:
        try:
            self._port.write(data)
        except (self._serial_error, OSError) as e:
            raise LinkLost(f'{self.name}: write failed: {e}') from None

    def read_lines(self) -> list[str]:
        try:
            chunk = self._port.read(self._port.in_waiting or 1)
        except (self._serial_error, OSError) as e:
            raise LinkLost(f'{self.name}: read failed: {e}') from None
        if not chunk:
            return []
        data = self._partial + chunk
        *lines, self._partial = data.replace(b'\r', b'').split(b'\n')
        # GRBL prints ASCII; a byte that is not (line noise) must not stop the driver.
        return [line.decode('ascii', 'replace') for line in lines]

    def close(self) -> None:
        try:
            self._port.close()
        except (self._serial_error, OSError):
            pass
