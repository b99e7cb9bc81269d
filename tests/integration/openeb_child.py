"""Run in a child Python where the real ``metavision_hal`` imports (test_camera_metavision_openeb.py starts it).

The HAL opens a RAW file as a device (``DeviceDiscovery.open_raw_file``): :class:`FileCamera` is the
metavision adapter with only that open changed (and the end of the file is the end of the stream).

    python -m tests.integration.openeb_child read RAW OUT_DIR      # the adapter's events, info, and raw log
    python -m tests.integration.openeb_child service RAW OUT_DIR   # through the camera service, over Zenoh
    python -m tests.integration.openeb_child surface RAW OUT.json  # the bindings' names and buffer types
"""

from __future__ import annotations

import json
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.drivers.camera.base import CameraInfo, EndOfStream
from flagtrack.drivers.camera.metavision import MetavisionCamera, MetavisionConfig

EVENTS_PER_BUFFER = 1000  # RawFileConfig.n_events_to_read: many buffers per file, cut anywhere


class FileCamera(MetavisionCamera):
    """The metavision adapter on a RAW file opened by the HAL as a device (no index file is written)."""

    def __init__(self, path: Path, raw_log_dir: Path | None = None) -> None:
        super().__init__(MetavisionConfig(stall_timeout_s=0, raw_log_dir=str(raw_log_dir) if raw_log_dir else None))
        self.path = path

    def _open_device(self, hal: Any) -> Any:
        config = hal.RawFileConfig()
        config.build_index = False
        config.do_time_shifting = False  # the file's own times, as flagtrack's reader gives them
        config.n_events_to_read = EVENTS_PER_BUFFER
        return hal.DeviceDiscovery.open_raw_file(str(self.path), config)

    def _stream_stopped(self) -> None:
        raise EndOfStream()


def read(raw: Path, out: Path) -> None:
    """The adapter's events, triggers and info for the whole file; the HAL's log of its bytes in OUT_DIR/log."""
    camera = FileCamera(raw, out / "log")
    info = camera.open()
    events, triggers, reads, horizons = [], [], 0, []
    try:
        while True:
            if (data := camera.read(5.0)) is not None:
                reads += 1
                events.append(data.events)
                triggers.append(data.triggers)
                horizons.append(data.t_until_us)
    except EndOfStream:
        pass
    finally:
        camera.close()
    np.save(out / "events.npy", np.concatenate(events))
    np.save(out / "triggers.npy", np.concatenate(triggers))
    _write_info(out, info, reads=reads, horizons=horizons)


def service(raw: Path, out: Path) -> None:
    """What subscribers get when the camera service publishes the file through the adapter."""
    from flagtrack.daemon.schema import EventPacket
    from flagtrack.daemon.services.camera import CameraService, CameraStreamConfig
    from flagtrack.daemon.transport import Bus, BusConfig
    from flagtrack.drivers.formats.packets import decode_packet
    from tests.fakes.helpers import wait_subscribed
    from tests.integration.test_transport import free_port

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        Bus(BusConfig(namespace="flagtrack/openeb", listen=(endpoint,))) as cam_bus,
        Bus(BusConfig(namespace="flagtrack/openeb", connect=(endpoint,))) as sub_bus,
    ):
        packets_sub = sub_bus.subscribe(sub_bus.keys.camera_events("cam0"), EventPacket, capacity=1_000_000)
        wait_subscribed(cam_bus, cam_bus.keys.camera_events("cam0"))
        camera_service = CameraService(cam_bus, CameraStreamConfig(), FileCamera(raw))
        camera_service.start()
        camera_service.run(threading.Event())  # returns at the end of the file
        packets = []
        while len(packets) < camera_service.packets and (msg := packets_sub.recv(timeout_s=10.0)) is not None:
            packets.append(msg)
    decoded = [decode_packet(p.encoding, p.data, p.t_offset_us) for p in packets]
    np.save(out / "events.npy", np.concatenate([d[0] for d in decoded]))
    np.save(out / "triggers.npy", np.concatenate([d[1] for d in decoded]))
    (out / "info.json").write_text(
        json.dumps(
            {
                "packets": len(packets),
                "sent": camera_service.packets,
                "encodings": sorted({p.encoding for p in packets}),
                "end_of_stream": bool(packets and packets[-1].end_of_stream),
            }
        )
    )


def surface(raw: Path, out: Path) -> None:
    """The module's public classes and their public members, the event dtypes, and what its buffers are."""
    import metavision_hal as hal
    import metavision_sdk_base as base

    names = {}
    for name in dir(hal):
        cls = getattr(hal, name)
        if not name.startswith("_") and isinstance(cls, type):
            names[name] = sorted(m for m in dir(cls) if not m.startswith("_"))
            for inner in names[name]:
                if isinstance(getattr(cls, inner), type):
                    names[f"{name}.{inner}"] = sorted(m for m in dir(getattr(cls, inner)) if not m.startswith("_"))
    camera = FileCamera(raw)
    camera.open()
    buffer = camera._events_stream.get_latest_raw_data()
    camera.close()
    readable = {}
    for how, read_bytes in {
        "memoryview": memoryview,
        "bytes": bytes,
        "numpy": lambda b: np.asarray(b, np.uint8),
    }.items():
        try:
            read_bytes(buffer)
            readable[how] = True
        except TypeError:
            readable[how] = False
    dtypes = {"EventCD": base.EventCD, "EventExtTrigger": base.EventExtTrigger}
    result = {
        "names": names,
        "buffer_type": type(buffer).__name__,
        "buffer_readable": readable,
        "dtypes": {k: {"descr": str(np.dtype(v).descr), "itemsize": np.dtype(v).itemsize} for k, v in dtypes.items()},
    }
    out.write_text(json.dumps(result, indent=1))


def _write_info(out: Path, info: CameraInfo, **extra: object) -> None:
    fields = {
        "adapter": info.adapter,
        "width": info.width,
        "height": info.height,
        "encoding": info.encoding,
        "serial": info.serial,
        "settings": info.settings,
    }
    (out / "info.json").write_text(json.dumps({**fields, **extra}))


if __name__ == "__main__":
    command, source, target = sys.argv[1:4]
    {"read": read, "service": service, "surface": surface}[command](Path(source), Path(target))
