from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from twinfleet.nodes.mapfile import MapError, load_map, pgm_bytes, read_pgm, save_map
from twinfleet.nodes.profile import FIXED, REBECA

MAPS = Path(__file__).resolve().parents[2] / "twinfleet" / "maps"


def test_map50(map50):
    assert map50.shape == (50, 50)
    assert map50.resolution == 0.255
    assert map50.origin == (-10.0, -10.0, 0.0)
    assert map50.occupied_thresh == 0.65
    assert map50.free_thresh == 0.196
    assert not map50.negate
    assert map50.occupied(REBECA).sum() == 213
    assert not map50.gray.flags.writeable


def test_map50_gray_histogram(map50):
    g = map50.gray
    assert (g == 255).sum() == 1440
    assert (g == 254).sum() == 836
    assert (g == 0).sum() == 110


def test_map50_obstacle_a(occ50):
    assert occ50[9:26, 18:23].all()
    assert not occ50[:, :3].any()
    assert not occ50[0].any()


def test_fixed_trinary_unknown_is_occupied(map50):
    occ = map50.occupied(FIXED)
    g = map50.gray.astype(float)
    p = (255 - g) / 255
    assert occ.sum() == int((p > 0.65).sum() + ((p >= 0.196) & (p <= 0.65)).sum())
    assert (p > 0.65).sum() == 142


def _write(tmp_path, pgm: bytes, yaml_text: str | None = None):
    (tmp_path / "m.pgm").write_bytes(pgm)
    y = tmp_path / "m.yaml"
    y.write_text(
        yaml_text
        or "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    return y


def test_p2_with_comments(tmp_path):
    y = _write(tmp_path, b"P2\n# c1\n3 2 # c2\n255\n0 255 100\n# c3\n200 204 255\n")
    m = load_map(y)
    assert m.gray.tolist() == [[0, 255, 100], [200, 204, 255]]
    assert m.occupied(REBECA).tolist() == [[True, False, True], [True, False, False]]


def test_negate(tmp_path):
    y = _write(
        tmp_path,
        pgm_bytes(np.array([[0, 255]], dtype=np.uint8)),
        "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 1\n",
    )
    assert load_map(y).occupied(FIXED).tolist() == [[False, True]]


def test_save_load_round_trip(tmp_path):
    g = np.arange(12, dtype=np.uint8).reshape(3, 4) * 20
    save_map(tmp_path / "x.yaml", g, 0.2, (1.0, 2.0, 0.0), "hi")
    m = load_map(tmp_path / "x.yaml")
    assert (m.gray == g).all()
    assert m.resolution == 0.2
    assert m.origin == (1.0, 2.0, 0.0)
    assert read_pgm(tmp_path / "x.pgm")[1] == 255


@pytest.mark.parametrize(
    ("pgm", "match"),
    [
        (b"P6\n1 1\n255\n\x00", "magic"),
        (b"P5\n2 2\n255\n\x00\x00\x00", "truncated"),
        (b"P5\n1 1\n255\n\x00\x00", "size mismatch"),
        (b"P5\n1 1\n65535\n\x00\x00", "maxval"),
        (b"P5\n1 1\n0\n\x00", "maxval"),
        (b"P5\n1 x\n255\n\x00", "height"),
        (b"P5\n1", "truncated"),
        (b"P2\n2 1\n100\n50 101\n", "exceeds maxval"),
        (b"P2\n2 1\n255\n50\n", "size mismatch"),
        (b"P5\n0 1\n255\n", "positive"),
    ],
)
def test_bad_pgm(tmp_path, pgm, match):
    y = _write(tmp_path, pgm)
    with pytest.raises(MapError, match=match) as e:
        load_map(y)
    assert "m.pgm" in str(e.value)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("resolution: 0.1\norigin: [0, 0, 0]\n", "'image'"),
        ("image: m.pgm\norigin: [0, 0, 0]\n", "'resolution'"),
        ("image: m.pgm\nresolution: 0\norigin: [0, 0, 0]\n", "positive"),
        ("image: m.pgm\nresolution: -1\norigin: [0, 0, 0]\n", "positive"),
        ("image: m.pgm\nresolution: abc\norigin: [0, 0, 0]\n", "finite number"),
        ("image: m.pgm\nresolution: 0.1\n", "origin"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0]\n", "origin"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 2\n", "negate"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nfree_thresh: 0.9\n", "thresh"),
        ("image: nope.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", "not found"),
        ("- a\n- b\n", "mapping"),
        ("image: [unclosed\n", "invalid YAML"),
    ],
)
def test_bad_yaml(tmp_path, text, match):
    y = _write(tmp_path, pgm_bytes(np.zeros((1, 1), dtype=np.uint8)), text)
    with pytest.raises(MapError, match=match) as e:
        load_map(y)
    assert "m.yaml" in str(e.value)


def test_missing_yaml(tmp_path):
    with pytest.raises(MapError, match="cannot read"):
        load_map(tmp_path / "none.yaml")


def test_map50_bytes_untouched():
    data = (MAPS / "map50.pgm").read_bytes()
    assert len(data) == 2538
    assert hashlib.sha256(data).hexdigest().startswith("db3621bf")
