"""The calibration file (YAML): what ``flagtrack calibrate`` writes and ``reconstruct`` loads.

Layout (version 1)::

    format: flagtrack-calibration
    version: 1
    units: m                       # plane coordinates out of the mapping
    created: 2025-01-01T12:00:00+00:00
    source: checkerboard.raw       # the recording
    image_size: [640, 480]         # sensor, pixels (pixel centres at integers)
    board: {inner_corners: [9, 6], square_mm: 20.0}
    frame: {origin_corner: top-left, x_axis: right, y_axis: up, origin_offset_mm: [0.0, 0.0]}
    degree: 3
    forward:                       # pixel -> plane: X = sum_k x[k] u^i v^j, u = (x_px - cx) / scale
      degree: 3
      centre: [319.5, 239.5]
      scale: 320.0
      exponents: [[0, 0], [1, 0], [0, 1], ...]     # (i, j) of u^i v^j, one per coefficient
      x: [...]
      y: [...]
    inverse: {...}                 # plane (m) -> pixel, same layout
    residuals: {n_corners, mean_mm, max_mm, rms_mm, mean_px, max_px, loo_*, inverse_max_px, pixel_size_mm}
    blink: {period_us, n_on, n_off, half_window_us, strength, first_on_us}
    corners:                       # what the fit used, image order [j][i] flattened
      shape: [n_rows, n_cols]
      pixels: [[x, y], ...]
      plane_m: [[x, y], ...]

Only ``format``, ``version``, ``image_size``, ``forward`` and ``inverse`` are needed to map;
the rest documents the calibration.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

from flagtrack.calibration.fit import Calibration
from flagtrack.calibration.mapping import PolynomialMapping
from flagtrack.calibration.polynomial import Polynomial2D, exponents
from flagtrack.daemon.errors import ConfigError, FormatError

FORMAT = "flagtrack-calibration"
VERSION = 1


def calibration_to_mapping(cal: Calibration) -> dict[str, Any]:
    """The file's content as plain data."""
    m = cal.mapping
    return {
        "format": FORMAT,
        "version": VERSION,
        "units": m.units,
        "created": cal.created,
        "source": cal.source,
        "image_size": list(m.image_size),
        "board": {"inner_corners": list(cal.board.inner_corners), "square_mm": cal.board.square_m * 1e3},
        "frame": cal.frame.to_mapping(),
        "degree": m.degree,
        "forward": m.forward.to_mapping(),
        "inverse": m.inverse.to_mapping(),
        "residuals": cal.residuals.to_mapping(),
        "blink": cal.blink,
        "corners": {
            "shape": list(cal.corners_px.shape[:2]),
            "pixels": np.round(cal.corners_px.reshape(-1, 2), 4).tolist(),
            "plane_m": np.round(cal.plane_m.reshape(-1, 2), 9).tolist(),
        },
    }


def save_calibration(cal: Calibration, path: str | Path) -> Path:
    """Write ``cal`` as YAML to ``path`` (parents created); return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = yaml.safe_dump(calibration_to_mapping(cal), sort_keys=False, default_flow_style=None, width=120)
    path.write_text("# flagtrack calibration: pixel -> plane (metres) mapping; see docs/calibration.md\n" + text)
    return path


def read_calibration_file(path: str | Path) -> dict[str, Any]:
    """The file's YAML content, checked for format and version.

    Raises:
        ConfigError: the file cannot be read.
        FormatError: not YAML, not a calibration file, or a version this flagtrack does not know.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read calibration file: {exc.strerror}", path=str(path)) from exc
    except UnicodeDecodeError as exc:  # a recording given as the calibration, say
        raise FormatError(f"not a calibration file (not UTF-8 text at byte {exc.start})", path=str(path)) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise FormatError(f"not a YAML file: {getattr(exc, 'problem', exc)}", path=str(path)) from exc
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise FormatError(
            f"not a calibration file (no 'format: {FORMAT}'; make one with flagtrack calibrate)", path=str(path)
        )
    if data.get("version") != VERSION:
        raise FormatError(
            f"calibration file version {data.get('version')!r} is not supported (this flagtrack "
            f"reads version {VERSION})",
            path=str(path),
        )
    return data


def _polynomial(data: dict[str, Any], key: str, path: str) -> Polynomial2D:
    section = data.get(key)
    if not isinstance(section, dict):
        raise FormatError(f"missing '{key}' section", path=path)
    try:
        degree = int(section["degree"])
        terms = [tuple(int(v) for v in e) for e in section["exponents"]]
        if terms != exponents(degree):
            raise ValueError(f"exponents do not list the degree-{degree} monomials in order")
        centre = tuple(float(v) for v in section["centre"])
        if len(centre) != 2:
            raise ValueError("centre must be [x, y]")
        return Polynomial2D(
            degree,
            (centre[0], centre[1]),
            float(section["scale"]),
            tuple(float(v) for v in section["x"]),
            tuple(float(v) for v in section["y"]),
        )
    except KeyError as exc:
        raise FormatError(f"'{key}' lacks '{exc.args[0]}'", path=path) from exc
    except (TypeError, ValueError) as exc:
        raise FormatError(f"bad '{key}' section: {exc}", path=path) from exc


def load_mapping(path: str | Path) -> PolynomialMapping:
    """The pixel -> plane (metres) mapping of a calibration file (``units = "m"``).

    Raises:
        ConfigError: the file cannot be read.
        FormatError: the file is not a valid calibration file.
    """
    data = read_calibration_file(path)
    size = data.get("image_size")
    if not (isinstance(size, list) and len(size) == 2 and all(isinstance(v, int) and v > 0 for v in size)):
        raise FormatError("'image_size' must be [width, height] in pixels", path=str(path))
    if data.get("units", "m") != "m":
        raise FormatError(f"units {data.get('units')!r} not supported (m)", path=str(path))
    return PolynomialMapping(
        _polynomial(data, "forward", str(path)), _polynomial(data, "inverse", str(path)), (size[0], size[1])
    )


def calibration_attrs(path: str | Path) -> dict[str, Any]:
    """Flat output attributes describing a calibration file: summary numbers and the whole file's text.

    For centreline files (``reconstruct``) so that an output in metres carries its calibration.

    Raises:
        ConfigError, FormatError: as :func:`load_mapping`.
    """
    data = read_calibration_file(path)
    res = data.get("residuals") or {}
    attrs: dict[str, Any] = {
        "calibration_degree": data.get("degree"),
        "calibration_created": str(data.get("created")),
        "calibration_source": str(data.get("source")),
        "calibration_yaml": Path(path).read_text(),
    }
    for key in ("mean_mm", "max_mm", "mean_px", "max_px", "loo_max_px", "pixel_size_mm"):
        if key in res:
            attrs[f"calibration_{key}"] = res[key]
    return attrs
