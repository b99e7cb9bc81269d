"""Modbus RTU framing for the simulated drive: CRC-16, request parsing, response encoding.

Only what a variable-frequency drive needs: read coils (0x01), read holding registers (0x03),
read input registers (0x04), write single coil (0x05), write single register (0x06), write
multiple registers (0x10). The client side uses pymodbus (:mod:`.modbus`); this module lets the
simulated tunnel be a real RTU peer on a pseudo-terminal without pymodbus's asyncio server.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

READ_COILS = 0x01
READ_HOLDING = 0x03
READ_INPUT = 0x04
WRITE_COIL = 0x05
WRITE_REGISTER = 0x06
WRITE_REGISTERS = 0x10

ILLEGAL_FUNCTION = 0x01
ILLEGAL_ADDRESS = 0x02
ILLEGAL_VALUE = 0x03

_FIXED_LENGTH = {READ_COILS: 8, READ_HOLDING: 8, READ_INPUT: 8, WRITE_COIL: 8, WRITE_REGISTER: 8}


def crc16(data: bytes) -> int:
    """Modbus CRC-16 (polynomial 0xA001 reflected, initial 0xFFFF) of ``data``."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def with_crc(body: bytes) -> bytes:
    """``body`` (device id + PDU) followed by its CRC, low byte first."""
    return body + struct.pack("<H", crc16(body))


@dataclass(frozen=True)
class Request:
    """One decoded request.

    Attributes:
        device_id: addressed device (0 = broadcast).
        function: function code.
        address: first register or coil.
        count: registers or coils to read (reads), 1 for single writes.
        values: values written (writes; coils as 0/1), empty for reads.
    """

    device_id: int
    function: int
    address: int
    count: int = 1
    values: tuple[int, ...] = ()


def frame_length(buffer: bytes) -> int | None:
    """Length of the request frame at the start of ``buffer``; ``None`` if not known yet.

    Returns 0 for a function code this module does not know (its length cannot be known).
    """
    if len(buffer) < 2:
        return None
    function = buffer[1]
    if function in _FIXED_LENGTH:
        return _FIXED_LENGTH[function]
    if function == WRITE_REGISTERS:
        return 9 + buffer[6] if len(buffer) >= 7 else None
    return 0


def split_frames(buffer: bytes) -> tuple[list[bytes], bytes]:
    """The complete request frames of ``buffer`` and the partial rest (dropped when a frame's end
    cannot be found: unknown function)."""
    frames: list[bytes] = []
    while (length := frame_length(buffer)) is not None and len(buffer) >= length:
        if length == 0:
            return frames, b""
        frames.append(buffer[:length])
        buffer = buffer[length:]
    return frames, buffer


def parse_request(frame: bytes) -> Request:
    """Decode one complete request frame (CRC included).

    Raises:
        ValueError: bad CRC, unknown function or inconsistent lengths.
    """
    if len(frame) < 4 or crc16(frame[:-2]) != struct.unpack("<H", frame[-2:])[0]:
        raise ValueError("bad CRC")
    device_id, function = frame[0], frame[1]
    if function in _FIXED_LENGTH and len(frame) == 8:
        address, value = struct.unpack(">HH", frame[2:6])
        if function in (READ_COILS, READ_HOLDING, READ_INPUT):
            return Request(device_id, function, address, count=value)
        if function == WRITE_COIL:
            if value not in (0x0000, 0xFF00):
                raise ValueError("coil value must be 0x0000 or 0xFF00")
            return Request(device_id, function, address, values=(int(value == 0xFF00),))
        return Request(device_id, function, address, values=(value,))
    if function == WRITE_REGISTERS and len(frame) >= 9:
        address, count, n_bytes = struct.unpack(">HHB", frame[2:7])
        if n_bytes != 2 * count or len(frame) != 9 + n_bytes:
            raise ValueError("inconsistent register count")
        values = struct.unpack(f">{count}H", frame[7 : 7 + n_bytes])
        return Request(device_id, function, address, count=count, values=values)
    raise ValueError(f"unsupported function 0x{function:02x} or length {len(frame)}")


def read_response(request: Request, values: list[int]) -> bytes:
    """Response frame to a read request with ``values`` (registers, or coils as 0/1)."""
    if request.function == READ_COILS:
        packed = bytearray((len(values) + 7) // 8)
        for i, bit in enumerate(values):
            if bit:
                packed[i // 8] |= 1 << (i % 8)
        data = bytes(packed)
    else:
        data = struct.pack(f">{len(values)}H", *values)
    return with_crc(bytes([request.device_id, request.function, len(data)]) + data)


def write_response(request: Request) -> bytes:
    """Response frame to a write request (the echo the standard prescribes)."""
    if request.function == WRITE_REGISTERS:
        body = struct.pack(">HH", request.address, request.count)
    elif request.function == WRITE_COIL:
        body = struct.pack(">HH", request.address, 0xFF00 if request.values[0] else 0)
    else:
        body = struct.pack(">HH", request.address, request.values[0])
    return with_crc(bytes([request.device_id, request.function]) + body)


def exception_response(device_id: int, function: int, code: int) -> bytes:
    """Exception response frame (function | 0x80, exception code)."""
    return with_crc(bytes([device_id, function | 0x80, code]))
