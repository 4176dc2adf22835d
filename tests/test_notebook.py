"""dvr_gl in Jupyter: images that display themselves, and the volume widget, first in the
kernel alone, then in a real JupyterLab driven by a real browser engine (Chromium)."""

import base64
import hashlib
import io
import json
import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request

import numpy as np
import pytest
from PIL import Image

import dvr_gl
from dvr_gl import formats as dvr_io
from dvr_gl.frontends.notebook import RenderedImage, VolumeWidget


def _decode(png):
    return np.asarray(Image.open(io.BytesIO(png)))


def test_rendered_image_is_the_array_and_shows_as_its_png():
    image = dvr_gl.render("builtin:synthetic", size=(48, 32))
    assert isinstance(image, np.ndarray) and image.shape == (32, 48, 4) and image.dtype == np.float32
    pixels = _decode(image._repr_png_())
    # the picture is the image over white, as `dvr-gl render` writes it
    assert np.array_equal(pixels, dvr_io.to_png_array(np.asarray(image), (1.0, 1.0, 1.0)))
    assert pixels.shape == (32, 48, 3) and pixels.std() > 5          # something was drawn


def test_derived_arrays_are_not_pictures():
    image = dvr_gl.render("builtin:synthetic", size=16)
    assert type(image.mean()) is np.float32                          # a number, not an image
    assert type(image.sum(axis=2)) is np.ndarray
    assert image[..., 3]._repr_png_() is None                        # a channel displays as text
    black = RenderedImage(np.asarray(image), background=(0, 0, 0))
    assert np.array_equal(_decode(black._repr_png_()), dvr_io.to_png_array(np.asarray(image), (0, 0, 0)))


def test_widget_renders_what_dvr_gl_render_renders():
    w = VolumeWidget("builtin:ct_head", size=(64, 48))
    assert w.frame == 1 and w.image_array.shape == (48, 64, 4)
    expected = dvr_gl.render("builtin:ct_head", size=(64, 48))
    assert np.array_equal(w.image_array, np.asarray(expected))
    assert np.array_equal(_decode(w.image), dvr_io.to_png_array(np.asarray(expected), (1.0, 1.0, 1.0)))
    assert w.techniques[0] == "raycast" and "tetra" not in w.techniques
    assert w.presets[0] == "ct_head"


def test_widget_view_preset_and_technique_rerender():
    w = VolumeWidget("builtin:synthetic", size=48)
    first = w.image
    w.view = dict(w.view, azimuth=120.0, elevation=-30.0, zoom=1.5)
    assert w.frame == 2 and w.image != first
    expected = dvr_gl.render("builtin:synthetic", size=48, azimuth=120, elevation=-30, zoom=1.5)
    assert np.array_equal(w.image_array, np.asarray(expected))
    w.view = dict(w.view, coarse=True)                               # while dragging: half size
    assert w.image_array.shape == (24, 24, 4) and "24x24" in w.status
    w.preset = "grey"
    assert w.frame == 4 and w.image_array.shape == (24, 24, 4)
    w.view = dict(w.view, coarse=False)
    w.technique = "slice3d"
    expected = dvr_gl.render("builtin:synthetic", size=48, azimuth=120, elevation=-30, zoom=1.5, tf="grey",
                             technique="slice3d")
    assert np.array_equal(w.image_array, np.asarray(expected))


def test_widget_errors():
    with pytest.raises(dvr_io.InputError, match="technique.*tetra.*raycast"):
        VolumeWidget("builtin:synthetic", technique="tetra", size=32)
    with pytest.raises(dvr_io.InputError, match="tf"):
        VolumeWidget("builtin:synthetic", tf="no-such-preset", size=32)
    with pytest.raises(dvr_io.InputError, match="size"):
        VolumeWidget("builtin:synthetic", size=(2, 2))
    # an option the new technique refuses goes to the status line; the frame stays
    w = VolumeWidget("builtin:synthetic", size=32, step=0.5)
    w.technique = "particles"                # step was raycast's option: not passed on
    assert "particles" in w.status and "Error" not in w.status
    frame = w.image
    w.view = dict(w.view, zoom=float("nan"))
    assert "Error" in w.status and w.image == frame


def test_mesh_widget_offers_mesh_techniques():
    mesh = dvr_gl.TetMesh.from_points(np.random.default_rng(1).random((60, 3)),
                                      np.random.default_rng(2).random(60))
    w = VolumeWidget(mesh, size=32)
    assert w.technique == "tetra" and "raycast" not in w.techniques
    assert w.image_array[..., 3].max() > 0


# ----------------------------------------------------------------------------- in a browser

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
# as root, in a closed network: no sandbox, and none of Chromium's own connections
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _notebook(cells):
    return {"nbformat": 4, "nbformat_minor": 5,
            "metadata": {"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}},
            "cells": [{"cell_type": "code", "id": f"c{i}", "metadata": {}, "execution_count": None, "outputs": [],
                       "source": source} for i, source in enumerate(cells)]}


@pytest.fixture
def jupyterlab(tmp_path):
    """A JupyterLab server on localhost serving ``tmp_path``, its application object
    exposed to the page, with its own config and runtime folders."""
    pytest.importorskip("jupyterlab", reason="the browser test needs the dev extra (jupyterlab)")
    port, token = _free_port(), "dvrgltest"
    env = dict(os.environ, JUPYTER_CONFIG_DIR=str(tmp_path / "config"), JUPYTER_RUNTIME_DIR=str(tmp_path / "run"),
               IPYTHONDIR=str(tmp_path / "ipython"), JUPYTER_PLATFORM_DIRS="1")
    (tmp_path / "work").mkdir()
    log = open(tmp_path / "server.log", "wb")
    server = subprocess.Popen(
        [sys.executable, "-m", "jupyter", "lab", "--no-browser", f"--port={port}", "--ip=127.0.0.1",
         f"--IdentityProvider.token={token}", f"--ServerApp.root_dir={tmp_path / 'work'}",
         "--LabApp.expose_app_in_browser=True", "--LabApp.news_url=", "--ServerApp.disable_check_xsrf=True",
         "--allow-root"],
        env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        deadline = time.time() + 60
        while True:
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status?token={token}", timeout=2)
                break
            except OSError:
                if server.poll() is not None or time.time() > deadline:
                    raise AssertionError("JupyterLab did not start:\n" + (tmp_path / "server.log").read_text()[-3000:])
                time.sleep(0.5)
        yield {"url": f"http://127.0.0.1:{port}", "token": token, "root": tmp_path / "work",
               "log": tmp_path / "server.log"}
    finally:
        server.terminate()
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            server.kill()
        log.close()


_FRAME_BYTES = """async (img) => {
  const bytes = new Uint8Array(await (await fetch(img.src)).arrayBuffer());
  let text = ""; for (const b of bytes) text += String.fromCharCode(b);
  return btoa(text);
}"""


@pytest.mark.slow
def test_widget_in_jupyterlab_in_chromium(jupyterlab):
    """The notebook is run by a real JupyterLab in headless Chromium: the image of
    ``dvr_gl.render`` shows as a picture of its size; the widget shows the kernel's frame
    byte for byte; a drag with the mouse orbits (0.5 degree a pixel), and the frame after
    it is the headless render of the new view; the preset and technique menus re-render."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="the browser test needs the dev extra (playwright)")
    assert CHROMIUM, "Chromium is not installed: scripts/test.sh installs it (apt package chromium)"
    cells = [
        "import dvr_gl\nfrom dvr_gl.frontends.notebook import VolumeWidget\n"
        "image = dvr_gl.render('builtin:ct_head', size=(96, 64))\nimage",
        "w = VolumeWidget('builtin:ct_head', size=160)\nw",
        "import hashlib, json, numpy as np\n"
        "runs = globals().get('runs', 0) + 1\n"
        "again = dvr_gl.render('builtin:ct_head', size=160, azimuth=w.view['azimuth'], "
        "elevation=w.view['elevation'], tf=w.preset, technique=w.technique)\n"
        "print('STATE', json.dumps({'run': runs, 'azimuth': w.view['azimuth'], "
        "'elevation': w.view['elevation'], 'sha': hashlib.sha256(w.image).hexdigest(), "
        "'same': bool(np.array_equal(again, w.image_array)), 'preset': w.preset, 'technique': w.technique}))",
    ]
    (jupyterlab["root"] / "widget.ipynb").write_text(json.dumps(_notebook(cells)))

    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 900})
            page.goto(f"{jupyterlab['url']}/lab/tree/widget.ipynb?token={jupyterlab['token']}")
            page.wait_for_function("window.jupyterapp && window.jupyterapp.shell.currentWidget "
                                   "&& window.jupyterapp.shell.currentWidget.sessionContext "
                                   "&& window.jupyterapp.shell.currentWidget.sessionContext.session", timeout=90_000)
            page.evaluate("window.jupyterapp.shell.currentWidget.sessionContext.ready")
            page.evaluate("window.jupyterapp.commands.execute('notebook:run-all-cells')")

            runs = [0]

            def state_after(run):
                # the last cell's printout once it reports the given run
                line = page.wait_for_function(
                    "(run) => { const outs = [...document.querySelectorAll('.jp-OutputArea-output pre')]"
                    ".map(e => e.textContent).filter(t => t.startsWith('STATE ')); "
                    "return outs.length && JSON.parse(outs[outs.length - 1].slice(6)).run === run "
                    "? outs[outs.length - 1] : null; }", arg=run, timeout=90_000).json_value()
                return json.loads(line[len("STATE "):])

            def run_last_cell():
                page.evaluate("""() => {
                    const panel = window.jupyterapp.shell.currentWidget;
                    panel.content.activeCellIndex = panel.content.widgets.length - 1;
                    window.jupyterapp.commands.execute('notebook:run-cell');
                }""")
                runs[0] += 1
                return state_after(runs[0])

            # dvr_gl.render's image, displayed through _repr_png_
            shown = page.wait_for_selector(".jp-RenderedImage img", timeout=90_000)
            assert page.evaluate("(img) => img.complete && [img.naturalWidth, img.naturalHeight]", shown) == [96, 64]

            frame = page.wait_for_selector("img.dvr-gl-frame[src^='blob:']", timeout=90_000)
            page.wait_for_function("() => document.querySelector('.dvr-gl-status').textContent.includes('160x160')")
            runs[0] = 1
            state = state_after(1)       # from run-all
            first = base64.b64decode(page.evaluate(_FRAME_BYTES, frame))
            assert hashlib.sha256(first).hexdigest() == state["sha"]    # the kernel's frame, byte for byte
            assert state["same"] and (state["azimuth"], state["elevation"]) == (30.0, 20.0)

            # drag 80 pixels right and 40 down: azimuth 30 - 40, elevation 20 + 20
            box = frame.bounding_box()
            x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
            page.mouse.move(x, y)
            page.mouse.down()
            page.mouse.move(x + 80, y + 40, steps=8)
            page.mouse.up()
            page.wait_for_function("() => document.querySelector('.dvr-gl-status').textContent"
                                   ".startsWith('azimuth -10°, elevation 40°') && "
                                   "document.querySelector('.dvr-gl-status').textContent.includes('160x160')",
                                   timeout=60_000)
            state = run_last_cell()
            assert (state["azimuth"], state["elevation"]) == (-10.0, 40.0) and state["same"]
            dragged = base64.b64decode(page.evaluate(_FRAME_BYTES, frame))
            assert hashlib.sha256(dragged).hexdigest() == state["sha"] and dragged != first

            # the menus: another preset, then another technique
            page.select_option("select.dvr-gl-preset", "grey")
            page.wait_for_function("(old) => document.querySelector('img.dvr-gl-frame').src !== old",
                                   arg=frame.get_attribute("src"), timeout=60_000)
            page.select_option("select.dvr-gl-technique", "slice3d")
            page.wait_for_function("() => document.querySelector('.dvr-gl-status').textContent.includes('slice3d')",
                                   timeout=60_000)
            state = run_last_cell()
            assert (state["preset"], state["technique"]) == ("grey", "slice3d") and state["same"]
            assert hashlib.sha256(base64.b64decode(page.evaluate(_FRAME_BYTES, frame))).hexdigest() == state["sha"]
            page.screenshot(path=str(jupyterlab["root"] / "widget.png"))
        finally:
            browser.close()
