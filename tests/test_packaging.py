"""The wheel carries the shaders and the bundled data and renders from an empty folder;
the apps render headless; a real data set from the shared folder renders."""

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

import dvr_gl

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "data"


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                    "-w", str(out), str(ROOT)], check=True)
    (path,) = out.glob("dvr_gl-*.whl")
    return path


def test_wheel_ships_shaders_and_data(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    shaders = {f"dvr_gl/shaders/{p.relative_to(ROOT / 'shaders').as_posix()}"
               for p in (ROOT / "shaders").rglob("*") if p.is_file()}
    assert len(shaders) > 15 and shaders <= names, sorted(shaders - names)  # every shader, every folder
    assert "dvr_gl/data/headsq_quarter.npz" in names
    assert "dvr_gl/data/LICENSE-headsq.txt" in names
    assert any(n.endswith("entry_points.txt") for n in names)


def test_installed_wheel_renders_from_an_empty_folder(wheel, tmp_path):
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
                   check=True)
    work = tmp_path / "empty"
    work.mkdir()
    env = dict(os.environ, PYTHONPATH=str(site))
    code = ("import dvr_gl, numpy as np; from dvr_gl import data;"
            "assert dvr_gl.__file__.startswith(%r), dvr_gl.__file__;"
            "h = data.ct_head(); s = dvr_gl.Scene(h, data.ct_head_tf(), dvr_gl.default_camera(h), 32, 32);"
            "r = dvr_gl.Renderer(); img = r.render(s);"
            "imgs = [r.render(s, technique=t, preintegrate=True) for t in ('slice2d', 'slice3d')];"
            "print(min(float(i[..., 3].max()) for i in [img] + imgs))") % str(site)
    out = subprocess.run([sys.executable, "-c", code], cwd=work, env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert float(out.stdout.strip()) > 0.1
    info = subprocess.run([sys.executable, "-m", "dvr_gl", "info"], cwd=work, env=env, capture_output=True, text=True)
    assert info.returncode == 0, info.stderr
    assert "egl" in info.stdout.lower() and "osmesa" in info.stdout.lower()


def test_gallery_example_renders_headless(renderer):
    # the first gallery example (the docs build runs them all; this one also on its own)
    import runpy

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    try:
        names = runpy.run_path(str(ROOT / "examples" / "plot_01_first_render.py"))
    finally:
        plt.close("all")
    image = names["image"]
    assert image.shape == (256, 256, 4) and image[..., 3].max() > 0.2


@pytest.mark.skipif(not SHARED.is_dir() and not os.environ.get("CI"), reason="shared data folder not present")
def test_a_real_dataset_renders(renderer):
    import gzip
    raw = gzip.open(SHARED / "vtkjs_lidc2_ct" / "LIDC2_256x256x133_uint8.raw.gz").read()
    vol = dvr_gl.Volume(np.frombuffer(raw, np.uint8).reshape(133, 256, 256), spacing=(1.40625, 1.40625, 2.5))
    from dvr_gl.model.transfer import auto_preset
    scene = dvr_gl.Scene(vol, auto_preset(vol), dvr_gl.default_camera(vol, azimuth=30), width=64, height=64)
    image = renderer.render(scene)
    ref = dvr_gl.reference.render(scene)
    assert image[..., 3].max() > 0.3
    assert dvr_gl.metrics.max_abs_error(image, ref) < 1e-3
