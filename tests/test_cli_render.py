"""``rsodb render``: a stored pass rendered, compared, plotted and shown as frames."""
import json

import pytest

from rsodb.archive import Archive
from rsodb.cli import main
from tests.conftest import TOPEX_PHV


@pytest.mark.slow
def test_render_command_json_plot_and_frames(tmp_path, capsys):
    archive = tmp_path / "archive"
    Archive(archive, create=True).ingest([TOPEX_PHV], progress=False)
    pass_id = Archive(archive).passes(norad=22076)[0].pass_id
    plot, frames = tmp_path / "lc.png", tmp_path / "frames"
    status = main(["render", "--model", "topex", "--pass", pass_id[:12], "--archive", str(archive),
                   "--period-s", "9.86", "--precession-period-s", "689", "--precession-angle-deg", "35",
                   "--method", "cached", "--json", "--plot", str(plot), "--frames-png", str(frames), "--frames", "2"])
    assert status == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["n_frames"] == 2320 and summary["method"] == "cached"
    # The model is shape only (albedos are guesses): its offset to the observations is finite and
    # its residual RMS below the light curve's own 0.1-3 mag swing.
    assert summary["residual_rms_mag"] < 3.0
    assert plot.stat().st_size > 10_000 and len(list(frames.glob("*.png"))) == 2


def test_render_command_unknown_model(tmp_path, capsys):
    archive = tmp_path / "archive"
    Archive(archive, create=True).ingest([TOPEX_PHV], progress=False)
    pass_id = Archive(archive).passes()[0].pass_id
    assert main(["render", "--model", "hubble", "--pass", pass_id, "--archive", str(archive)]) == 2
    assert "model 'hubble' is neither a known model" in capsys.readouterr().err
