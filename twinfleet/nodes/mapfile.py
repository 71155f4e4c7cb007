"""ROS map_server maps: a YAML description plus a PGM image (P5 binary or P2 ASCII).

This is the only module of the domain code that does I/O. Grid convention:
array index ``[row, col]`` is the model's cell ``(x, y)``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
import yaml

from twinfleet.nodes.grid import inflate, inflate_one_pass
from twinfleet.nodes.profile import Profile, profile_named

#: Model threshold: occupied iff gray < 204 (= 0.8 · 255), docs/robots.md §2.
MODEL_FREE_GRAY = 204


class MapError(ValueError):
    """A map file is malformed; the message names the file and the rule broken."""


@dataclass(frozen=True, eq=False)
class OccupancyMap:
    """A loaded map.

    Attributes:
        gray: uint8 image as read, shape (rows, cols), read-only.
        resolution: metres per cell.
        origin: (x, y, yaw) of the lower-left pixel in the world, as in the YAML.
        occupied_thresh: ROS occupied threshold (probability).
        free_thresh: ROS free threshold (probability).
        negate: ROS negate flag.
        source: the YAML path (or the PGM path when loaded without YAML).
        maxval: the PGM maxval.
    """

    gray: np.ndarray
    resolution: float
    origin: tuple[float, float, float]
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    negate: bool = False
    source: str = ""
    maxval: int = 255

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the grid."""
        return (int(self.gray.shape[0]), int(self.gray.shape[1]))

    def occupied(self, profile: Profile) -> np.ndarray:
        """Occupancy grid by the profile's rule.

        Args:
            profile: ``gray204`` → gray < 204 (scaled to maxval); ``ros_trinary`` →
                p = (maxval − g)/maxval (g/maxval if negate), occupied if
                p > occupied_thresh, free if p < free_thresh, unknown counts as occupied.

        Returns:
            Bool array (rows, cols), True = occupied.
        """
        g = self.gray.astype(np.float64)
        if profile.occupancy == "gray204":
            return g < MODEL_FREE_GRAY * self.maxval / 255.0
        p = g / self.maxval if self.negate else (self.maxval - g) / self.maxval
        # Unknown (free_thresh <= p <= occupied_thresh) is treated as occupied.
        return ~(p < self.free_thresh)


def _pgm_tokens(data: bytes, count: int, path: Path) -> tuple[list[bytes], int]:
    """Read ``count`` header tokens, skipping ``#`` comments; return them and the end offset."""
    tokens: list[bytes] = []
    i, n = 0, len(data)
    while len(tokens) < count:
        while i < n and data[i : i + 1].isspace():
            i += 1
        if i < n and data[i : i + 1] == b"#":
            while i < n and data[i : i + 1] not in (b"\n", b"\r"):
                i += 1
            continue
        if i >= n:
            raise MapError(f"{path}: PGM header truncated (expected {count} fields)")
        j = i
        while j < n and not data[j : j + 1].isspace() and data[j : j + 1] != b"#":
            j += 1
        tokens.append(data[i:j])
        i = j
    return tokens, i


def _header_int(tok: bytes, what: str, path: Path) -> int:
    try:
        return int(tok)
    except ValueError:
        raise MapError(f"{path}: PGM {what} must be an integer, got {tok!r}") from None


def read_pgm(path: str | Path) -> tuple[np.ndarray, int]:
    """Read a P5 or P2 PGM file.

    Args:
        path: the file.

    Returns:
        (uint8 array of shape (height, width), maxval).

    Raises:
        MapError: missing file, wrong magic, bad header, maxval outside 1..255,
            truncated or excess data, sample above maxval.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise MapError(f"{path}: cannot read PGM image ({e.strerror})") from None
    magic = data[:2]
    if magic not in (b"P5", b"P2"):
        raise MapError(f"{path}: not a PGM file: magic {magic!r}, expected b'P5' or b'P2'")
    toks, end = _pgm_tokens(data[2:], 3, path)
    end += 2
    width, height, maxval = (_header_int(t, w, path) for t, w in zip(toks, ("width", "height", "maxval"), strict=True))
    if width <= 0 or height <= 0:
        raise MapError(f"{path}: PGM size must be positive, got {width}x{height}")
    if not 1 <= maxval <= 255:
        raise MapError(f"{path}: PGM maxval must be in 1..255 (8-bit), got {maxval}")
    size = width * height
    if magic == b"P5":
        raster = data[end + 1 :]  # exactly one whitespace byte after maxval
        if len(raster) < size:
            raise MapError(f"{path}: PGM data truncated: {len(raster)} bytes, expected {size}")
        if len(raster) > size:
            raise MapError(f"{path}: PGM size mismatch: {len(raster)} data bytes, expected {size}")
        arr: np.ndarray = np.frombuffer(raster, dtype=np.uint8).reshape(height, width).copy()
    else:
        # ASCII rasters may carry comments too.
        words = re.sub(rb"#[^\r\n]*", b" ", data[end:]).split()
        if len(words) != size:
            raise MapError(f"{path}: PGM size mismatch: {len(words)} samples, expected {size}")
        try:
            vals = np.array([int(w) for w in words], dtype=np.int64)
        except ValueError:
            raise MapError(f"{path}: PGM P2 sample is not an integer") from None
        if vals.min() < 0:
            raise MapError(f"{path}: PGM sample below 0")
        arr = vals.reshape(height, width)
    if int(arr.max()) > maxval:
        raise MapError(f"{path}: PGM sample {int(arr.max())} exceeds maxval {maxval}")
    return arr.astype(np.uint8), maxval


def _number(doc: dict, key: str, path: Path, default: float | None = None) -> float:
    if key not in doc:
        if default is None:
            raise MapError(f"{path}: missing key {key!r}")
        return default
    v = doc[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise MapError(f"{path}: key {key!r} must be a finite number, got {v!r}")
    return float(v)


def load_map(yaml_path: str | Path) -> OccupancyMap:
    """Load a ROS map_server map (YAML + PGM, image path relative to the YAML).

    Args:
        yaml_path: the YAML file.

    Returns:
        The map.

    Raises:
        MapError: unreadable YAML, missing or ill-typed keys, non-positive
            resolution, thresholds outside [0, 1], missing or malformed image.
    """
    path = Path(yaml_path)
    try:
        doc = yaml.safe_load(path.read_text())
    except OSError as e:
        raise MapError(f"{path}: cannot read map YAML ({e.strerror})") from None
    except yaml.YAMLError as e:
        raise MapError(f"{path}: invalid YAML: {e}") from None
    if not isinstance(doc, dict):
        raise MapError(f"{path}: map YAML must be a mapping")
    image = doc.get("image")
    if not isinstance(image, str) or not image:
        raise MapError(f"{path}: missing key 'image' (path of the PGM file)")
    res = _number(doc, "resolution", path)
    if res <= 0:
        raise MapError(f"{path}: 'resolution' must be positive, got {res}")
    origin = doc.get("origin")
    if (
        not isinstance(origin, list)
        or len(origin) != 3
        or not all(isinstance(o, int | float) and not isinstance(o, bool) for o in origin)
    ):
        raise MapError(f"{path}: 'origin' must be a list of 3 numbers [x, y, yaw], got {origin!r}")
    occ_t = _number(doc, "occupied_thresh", path, 0.65)
    free_t = _number(doc, "free_thresh", path, 0.196)
    if not (0.0 <= free_t <= occ_t <= 1.0):
        raise MapError(f"{path}: thresholds need 0 <= free_thresh <= occupied_thresh <= 1")
    negate = doc.get("negate", 0)
    if negate not in (0, 1, True, False):
        raise MapError(f"{path}: 'negate' must be 0 or 1, got {negate!r}")
    img_path = path.parent / image
    if not img_path.exists():
        raise MapError(f"{path}: image {image!r} not found (looked for {img_path})")
    gray, maxval = read_pgm(img_path)
    gray.setflags(write=False)
    return OccupancyMap(
        gray=gray,
        resolution=res,
        origin=(float(origin[0]), float(origin[1]), float(origin[2])),
        occupied_thresh=occ_t,
        free_thresh=free_t,
        negate=bool(negate),
        source=str(path),
        maxval=maxval,
    )


def pgm_bytes(gray: np.ndarray, comment: str = "") -> bytes:
    """Encode a uint8 array as a P5 PGM (maxval 255), optionally with one comment line."""
    rows, cols = gray.shape
    head = b"P5\n" + (f"# {comment}\n".encode() if comment else b"")
    head += f"{cols} {rows}\n255\n".encode()
    return head + np.ascontiguousarray(gray, dtype=np.uint8).tobytes()


def save_map(
    path_yaml: str | Path,
    gray: np.ndarray,
    resolution: float,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
    comment: str = "",
) -> Path:
    """Write ``<stem>.pgm`` (P5) beside ``path_yaml`` and the YAML that names it.

    Args:
        path_yaml: YAML path; the image gets the same stem and a ``.pgm`` suffix.
        gray: uint8 image (rows, cols).
        resolution: metres per cell.
        origin: world pose of the lower-left pixel.
        comment: optional PGM comment line.

    Returns:
        The PGM path.
    """
    path_yaml = Path(path_yaml)
    pgm = path_yaml.with_suffix(".pgm")
    pgm.write_bytes(pgm_bytes(gray, comment))
    ox, oy, oyaw = (float(o) for o in origin)
    path_yaml.write_text(
        f"image: ./{pgm.name}\n"
        f"resolution: {resolution:.5f}\n"
        f"origin: [{ox:.6f}, {oy:.6f}, {oyaw:.6f}]\n"
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
    )
    return pgm


@cache
def static_grids(map_path: str, profile_name: str) -> tuple[OccupancyMap, np.ndarray, np.ndarray]:
    """A map, its occupancy by the profile's rule and its one-cell inflation (by the
    profile's `inflation` rule), read-only.

    Loaded once per (map, profile) in a process: the map server and every robot of a
    checker run share them.
    """
    occ_map = load_map(map_path)
    profile = profile_named(profile_name)
    static = occ_map.occupied(profile)
    inflated = inflate_one_pass(static) if profile.inflation == "one_pass" else inflate(static, 1)
    static.setflags(write=False)
    inflated.setflags(write=False)
    return occ_map, static, inflated
