"""`tlt twin render`: a PNG of the scene, and a clear refusal of bad input."""

import cv2
import yaml
from tlt_sim.model.config import DEFAULT_EDU
from tlt_sim.model.render_png import main


def test_overview_is_written_to_png(tmp_path):
    out = tmp_path / "edu.png"
    assert main(["-o", str(out), "--width", "160", "--height", "120"]) == 0
    image = cv2.imread(str(out))
    assert image.shape == (120, 160, 3)
    assert image.std() > 10  # a scene, not a blank frame


def test_named_camera_and_bad_input(tmp_path, capsys):
    out = tmp_path / "zed.png"
    assert main(["-o", str(out), "--camera", "zed_1", "--width", "96", "--height", "54", "--bays", "0"]) == 0
    assert cv2.imread(str(out)).shape == (54, 96, 3)
    assert main(["-o", str(out), "--camera", "no_such_camera"]) == 2
    assert "no camera named 'no_such_camera'" in capsys.readouterr().err
    data = yaml.safe_load(DEFAULT_EDU.read_text())
    data["lifter"]["post_height"] = 0.5
    bad = tmp_path / "edu.yaml"
    bad.write_text(yaml.safe_dump(data))
    assert main(["--edu", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "lifter.post_height" in err
