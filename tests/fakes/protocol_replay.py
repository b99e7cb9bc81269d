"""pyserial's handler of ``replay://N`` URLs (see :mod:`tests.fakes.serial_replay`): ``serial_for_url``
imports ``<package>.protocol_<scheme>`` from ``serial.protocol_handler_packages`` and opens its ``Serial``."""

from tests.fakes.serial_replay import ReplayPort as Serial

__all__ = ["Serial"]
