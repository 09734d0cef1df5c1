"""The picture of a session's world, and its command line (``mapupdate render``)."""

from pathlib import Path

import numpy as np
from PIL import Image

import sim
from mapupdate import main

WAREHOUSE = Path(__file__).resolve().parents[1] / "scenarios" / "aws_small_warehouse.yaml"


def test_render_world_writes_a_png(tmp_path):
    scn = sim.load_scenario(WAREHOUSE)
    out = sim.render_world(scn, "W4", tmp_path / "w4.png", time=5.0)
    img = np.asarray(Image.open(out).convert("RGB"))
    assert img.shape[0] > 500 and img.shape[1] > 400
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 10      # not a blank canvas
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w4.png"]   # no temporary file left


def test_render_command_line(tmp_path, capsys):
    out = tmp_path / "w2.png"
    assert main(["render", str(WAREHOUSE), "--session", "W2", "--out", str(out),
                 "--time", "2", "--seed", "3"]) == 0
    assert out.is_file() and "wrote" in capsys.readouterr().out
    assert main(["render", str(tmp_path / "missing.yaml"), "--out", str(out)]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["render", str(WAREHOUSE), "--session", "W7", "--out", str(out)]) == 2
    assert "no session named 'W7'" in capsys.readouterr().err
