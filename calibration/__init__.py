"""flagtrack calibration: blinking-checkerboard pixel-to-plane mapping.

A blinking board on a screen in the light-sheet plane is recorded; its events make a pseudo-image
(:mod:`.pseudo_image`), whose inner corners (:mod:`.corners`) are matched to the board's grid with
the origin at the flag's root (:mod:`.frame`); a polynomial maps pixels to the plane in metres
(:mod:`.polynomial`, :mod:`.mapping`, :mod:`.fit`), saved as YAML (:mod:`.calfile`) with a residual
report (:mod:`.report`). See docs/calibration.md.

Public entry points (imported lazily: ``import flagtrack.calibration`` stays light, and OpenCV is
imported only when corners are detected):

- ``load_mapping(path) -> PolynomialMapping``: what the tracker applies to every event
  (``map(x_px, y_px) -> (x_m, y_m)``, ``units = "m"``, ``to_pixels`` for drawing);
- ``calibration_attrs(path) -> dict``: flat attributes (residuals, degree, the file's text) for outputs;
- ``calibrate_events``, ``BoardSpec``, ``GridFrame``, ``Direction``, ``BlinkSearch``,
  ``save_calibration``, ``load_calibration_data``, ``CalibrationError``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from flagtrack.calibration.mapping import PolynomialMapping

__all__ = [
    "BlinkSearch",
    "BoardSpec",
    "CalibrationError",
    "Direction",
    "GridFrame",
    "PolynomialMapping",
    "calibrate_events",
    "calibration_attrs",
    "load_calibration_data",
    "load_mapping",
    "save_calibration",
]

_WHERE = {
    "BlinkSearch": "pseudo_image",
    "BoardSpec": "fit",
    "CalibrationError": "errors",
    "Direction": "frame",
    "GridFrame": "frame",
    "PolynomialMapping": "mapping",
    "calibrate_events": "fit",
    "save_calibration": "calfile",
    "load_calibration_data": "calfile",
    "calibration_attrs": "calfile",
}


def load_mapping(path: Any) -> PolynomialMapping:
    """The pixel -> plane (metres) mapping of a calibration file written by ``flagtrack calibrate``.

    Raises:
        ConfigError: the file cannot be read.
        FormatError: it is not a valid calibration file.
    """
    from flagtrack.calibration.calfile import load_mapping as _load

    return _load(path)


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        import importlib

        module = importlib.import_module(f"{__name__}.{_WHERE[name]}")
        return getattr(module, "read_calibration_file" if name == "load_calibration_data" else name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
