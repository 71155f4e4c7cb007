"""`twinfleet render` on a scenario and on a checker counterexample, checked by pixels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from twinfleet.checker.driver import CheckOptions, check
from twinfleet.cli import main
from twinfleet.nodes.render import LEGEND_PX, robot_colour

ROOT = Path(__file__).resolve().parents[1]
PX = 12


def colour_near(arr: np.ndarray, cell: tuple[int, int], colour: tuple[int, int, int]) -> bool:
    r, c = cell
    patch = arr[int((r - 0.3) * PX):int((r + 1.3) * PX), int((c - 0.3) * PX):int((c + 1.3) * PX)]
    return bool(np.all(patch == colour, axis=-1).any())


def test_render_scenario_png(tmp_path, capsys):
    out = tmp_path / "c1a.png"
    assert main(["render", str(ROOT / "twinfleet" / "launch" / "c1a.yaml"), "-o", str(out), "--scan-of", "r3"]) == 0
    arr = np.asarray(Image.open(out).convert("RGB"))
    assert arr.shape == (50 * PX + LEGEND_PX + 18, 50 * PX, 3)
    legend = arr[50 * PX:50 * PX + LEGEND_PX]
    for i, start in enumerate([(5, 5), (5, 15), (5, 25), (5, 35), (5, 45)]):
        assert colour_near(arr, start, robot_colour(i))
        assert np.all(legend == robot_colour(i), axis=-1).sum() >= 81  # its 9x9 swatch
    # each robot's name is written beside it: dark text pixels right above its start cell
    for r, c in [(5, 5), (5, 15), (5, 25), (5, 35), (5, 45)]:
        label = arr[int((r - 1.6) * PX):int((r - 0.4) * PX),
                    int((c + 1.45) * PX):int((c + 3) * PX)]  # clear of the body's outline
        assert (label.sum(axis=-1) < 450).sum() > 5, (r, c)  # anti-aliased dark text


@pytest.mark.slow
def test_render_c2a_counterexample_shows_the_colliding_pair(tmp_path):
    trace_path = tmp_path / "c2a.trace.json"
    result = check(ROOT / "twinfleet" / "launch" / "c2a.yaml", CheckOptions(trace_out=str(trace_path)))
    assert result.status == "violated"
    last = result.trace["steps"][-1]
    pair = last["changed"]["map_server"]["collided"][-1]
    cells = dict(zip(["r1", "r2", "r3", "r4", "r5"], last["changed"]["map_server"]["cells"], strict=True))
    out = tmp_path / "c2a.png"
    assert main(["render", str(trace_path), "-o", str(out)]) == 0
    arr = np.asarray(Image.open(out).convert("RGB"))
    assert arr.shape == (50 * PX + LEGEND_PX + 18, 50 * PX, 3)
    for name in pair:
        index = int(name[1:]) - 1
        assert colour_near(arr, tuple(cells[name]), robot_colour(index)), name
        assert colour_near(arr, tuple(cells[name]), (255, 0, 0)), f"no collision marker at {name}"
    gif = tmp_path / "c2a.gif"
    assert main(["render", str(trace_path), "-o", str(gif)]) == 0
    assert Image.open(gif).n_frames > 10


def test_render_rejects_bad_input(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "other"}')
    assert main(["render", str(bad), "-o", str(tmp_path / "x.png")]) == 2
    assert "not a twinfleet-trace/1 trace" in capsys.readouterr().err
    assert main(["render", str(ROOT / "twinfleet" / "launch" / "c1a.yaml"), "-o", str(tmp_path / "x.bmp")]) == 2


class _Stamp:
    """A renderer of its own: draws any scenario with a scene as one grey picture."""

    def __init__(self):
        self.drawn = []

    def cannot_draw(self, scenario):
        return None

    def draw(self, scenario, trace, output, *, options):
        self.drawn.append((scenario.name, trace, dict(options)))
        Image.new("RGB", (4, 3), (128, 128, 128)).save(output)
        return 1


def test_render_draws_with_the_renderer_its_examples_registered(tmp_path, monkeypatch, capsys):
    from twinfleet.runtime.scenario import examples

    stamp = _Stamp()
    monkeypatch.setattr(examples, "_PICTURES", [])
    examples.add_examples("twinfleet.launch", stamp)
    out = tmp_path / "c1a.png"
    assert main(["render", "c1a", "-o", str(out), "--scan-of", "r2"]) == 0
    assert stamp.drawn == [("c1a", None, {"scan_of": "r2", "every_step": False, "cell_px": PX})]
    assert Image.open(out).size == (4, 3)
    assert "wrote" in capsys.readouterr().out


def test_render_says_in_one_line_when_no_renderer_fits(tmp_path, monkeypatch, capsys):
    from twinfleet.runtime.scenario import examples

    monkeypatch.setattr(examples, "_PICTURES", [])
    assert main(["render", "c1a", "-o", str(tmp_path / "c1a.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no example package registered a renderer" in err
    assert not (tmp_path / "c1a.png").exists()
