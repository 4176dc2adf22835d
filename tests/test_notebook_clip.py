"""The volume widget's clip planes, crop box and surfaces, driven from the kernel as the
browser drives them (by setting the synced values): each position of a control renders
exactly the image ``dvr_gl.render`` gives for the scene it stands for (same technique,
same parameters, so equal bit for bit), a change that the technique cannot draw is
refused as the viewer refuses it, and bad values are errors naming the control. Then
the controls themselves, in a real JupyterLab driven by headless Chromium."""

import base64
import hashlib
import itertools
import json

import numpy as np
import pytest

import dvr_gl
from dvr_gl import formats as dvr_io
from dvr_gl.frontends.notebook import VolumeWidget
from dvr_gl.techniques import common
import test_notebook
from test_notebook import CHROMIUM, CHROMIUM_ARGS, _FRAME_BYTES, _notebook

jupyterlab = test_notebook.jupyterlab          # the JupyterLab server fixture, for the browser test

SIZE = 48


def render(**kwargs):
    return np.asarray(dvr_gl.render("builtin:ct_head", size=SIZE, **kwargs))


def box_surface(lower, upper, color=(0.2, 0.5, 0.9)):
    """An axis-aligned box of 12 triangles."""
    (x0, y0, z0), (x1, y1, z1) = lower, upper
    corners = [(x, y, z) for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return dvr_gl.Surface(corners, faces, color=color)


@pytest.fixture(scope="module")
def plain():
    return render()


def set_plane(w, **fields):
    w.clip = [dict(w.clip[0], **fields)] + w.clip[1:]


def test_clip_slider_moves_the_cut_and_renders_the_equivalent_scene(plain):
    w = VolumeWidget("builtin:ct_head", size=SIZE)
    lo, hi = (np.array(b) for b in w.bounds)
    # no plane given: one is offered, off, across z through the centre
    assert w.clip == [{"on": False, "axis": "z", "flip": False, "offset": (lo[2] + hi[2]) / 2}]
    assert np.array_equal(w.image_array, plain) and w.clip_limits[0]["z"] == [lo[2], hi[2]]
    frames, images = w.frame, []
    for offset in (40.0, 80.0):
        set_plane(w, on=True, offset=offset)
        images.append(w.image_array.copy())
        assert np.array_equal(w.image_array, render(clip_planes=[((0, 0, offset), (0, 0, 1))]))
        assert "1 clip plane" in w.status
    assert w.frame == frames + 2
    assert not np.array_equal(images[0], plain) and not np.array_equal(images[0], images[1])
    # flip keeps the plane where it is and keeps the other side
    set_plane(w, flip=True)
    assert w.clip[0]["offset"] == 80.0
    assert np.array_equal(w.image_array, render(clip_planes=[((0, 0, 80.0), (0, 0, -1))]))
    # a new normal keeps the plane through the point it went through: the centre in x and y
    set_plane(w, axis="x", flip=False)
    centre = (lo + hi) / 2
    assert w.clip[0]["offset"] == centre[0] and w.clip_limits[0]["x"] == [lo[0], hi[0]]
    assert np.array_equal(w.image_array, render(clip_planes=[((centre[0], 0, 0), (1, 0, 0))]))
    set_plane(w, on=False)
    assert np.array_equal(w.image_array, plain) and w.scene_options()["clip_planes"] == ()


def test_an_oblique_plane_moves_along_its_own_normal(plain):
    point, normal = np.array([90.0, 110.0, 60.0]), np.array([1.0, 0.3, 0.2])
    w = VolumeWidget("builtin:ct_head", size=SIZE, clip_planes=[(point, normal)])
    unit = normal / np.linalg.norm(normal)
    assert w.clip == [{"on": True, "axis": "oblique", "flip": False, "offset": float(point @ unit)}]
    assert np.array_equal(w.image_array, render(clip_planes=[(point, normal)]))
    # the offset slider runs from the data's one end to the other along the normal
    corners = np.array(list(itertools.product(*zip(*w.bounds))))         # the box's eight corners
    assert w.clip_limits[0]["oblique"] == [(corners @ unit).min(), (corners @ unit).max()]
    offset = w.clip[0]["offset"] + 25.0
    set_plane(w, offset=offset)
    moved = point + (offset - point @ unit) * unit
    assert np.array_equal(w.image_array, render(clip_planes=[(moved, normal)]))
    set_plane(w, flip=True)
    assert np.array_equal(w.image_array, render(clip_planes=[(moved, -normal)]))
    # an axis-aligned plane given is that axis, flipped where its normal points down it
    w = VolumeWidget("builtin:ct_head", size=SIZE, clip_planes=[((50, 60, 70), (0, -2, 0))])
    assert w.clip == [{"on": True, "axis": "y", "flip": True, "offset": 60.0}]
    assert np.array_equal(w.image_array, render(clip_planes=[((50, 60, 70), (0, -2, 0))]))


def test_crop_sliders_render_the_cropped_scene(plain):
    w = VolumeWidget("builtin:ct_head", size=SIZE)
    lo, hi = w.bounds
    assert w.crop == [[lo[0], hi[0]], [lo[1], hi[1]], [lo[2], hi[2]]] and w.scene_options()["crop_box"] is None
    w.crop = [[lo[0], hi[0]], [50.0, 150.0], [lo[2], 100.0]]
    cropped = render(crop_box=((lo[0], 50, lo[2]), (hi[0], 150, 100)))
    assert np.array_equal(w.image_array, cropped) and not np.array_equal(cropped, plain)
    assert "crop box" in w.status
    w.crop = [[lo[0], 120.0], [50.0, 150.0], [lo[2], 100.0]]
    assert np.array_equal(w.image_array, render(crop_box=((lo[0], 50, lo[2]), (120, 150, 100))))
    # with a clip plane: both cut
    set_plane(w, on=True, offset=50.0)
    assert np.array_equal(w.image_array, render(crop_box=((lo[0], 50, lo[2]), (120, 150, 100)),
                                                clip_planes=[((0, 0, 50.0), (0, 0, 1))]))
    set_plane(w, on=False)
    w.crop = [[lo[0], hi[0]], [lo[1], hi[1]], [lo[2], hi[2]]]        # the whole data: no crop
    assert np.array_equal(w.image_array, plain) and w.scene_options()["crop_box"] is None
    # a crop box given that reaches beyond the data is cut to it
    w = VolumeWidget("builtin:ct_head", size=SIZE, crop_box=((-10, 20, -5), (100, 500, 90)))
    assert w.crop == [[0.0, 100.0], [20.0, hi[1]], [0.0, 90.0]]
    assert np.array_equal(w.image_array, render(crop_box=((0, 20, 0), (100, hi[1], 90))))


def test_geometry_toggles_and_is_refused_where_not_drawn(plain, tmp_path, monkeypatch):
    meshio = pytest.importorskip("meshio")
    cube = box_surface((70, 70, 40), (130, 130, 100), color=(0.85, 0.85, 0.85))     # a file's default colour
    path = tmp_path / "cube.obj"
    meshio.write(str(path), meshio.Mesh(np.asarray(cube.vertices), [("triangle", np.asarray(cube.faces))]))
    w = VolumeWidget("builtin:ct_head", size=SIZE, geometry=[str(path)])      # read as --geometry reads it
    assert w.geometry_on and w.geometry_count == 1 and "1 surface" in w.status
    with_cube = render(geometry=[str(path)])
    assert np.array_equal(with_cube, render(geometry=[cube]))
    assert np.array_equal(w.image_array, with_cube) and not np.array_equal(with_cube, plain)
    w.geometry_on = False
    assert np.array_equal(w.image_array, plain)
    w.geometry_on = True
    assert np.array_equal(w.image_array, with_cube)
    # a clip plane cuts the data, not the surface
    set_plane(w, on=True, offset=70.0)
    assert np.array_equal(w.image_array, render(geometry=[cube], clip_planes=[((0, 0, 70.0), (0, 0, 1))]))
    set_plane(w, on=False)
    # a technique that does not draw surfaces (the techniques' list says which; here slice3d is
    # taken off it): picking it with the surfaces shown is refused, as the viewer refuses it
    drawing = tuple(t for t in common.GEOMETRY_TECHNIQUES if t != "slice3d")
    monkeypatch.setattr(common, "GEOMETRY_TECHNIQUES", drawing)
    frame, image = w.frame, w.image
    w.technique = "slice3d"
    assert w.technique == "raycast" and w.geometry_on and w.image == image and w.frame == frame + 1
    assert w.status == (f"cannot use slice3d: slice3d does not draw surfaces; {', '.join(drawing)} do "
                        "(untick geometry to use slice3d)")
    w.geometry_on = False
    w.technique = "slice3d"
    assert w.technique == "slice3d" and np.array_equal(w.image_array, render(technique="slice3d"))
    w.geometry_on = True                                              # and the other way round
    assert not w.geometry_on and w.status.startswith("cannot show the surfaces: slice3d does not draw surfaces")
    with pytest.raises(dvr_io.InputError, match="geometry: is drawn by technique raycast.*, not slice3d"):
        VolumeWidget("builtin:ct_head", size=SIZE, technique="slice3d", geometry=[cube])


def test_a_browsers_messages_are_checked_as_values_set_from_python(plain, monkeypatch):
    """``set_state`` is how a browser's message arrives: every value in it is set first and
    checked afterwards, so the checks must compare with the values last taken."""
    w = VolumeWidget("builtin:ct_head", size=SIZE, geometry=[box_surface((70, 70, 40), (130, 130, 100))])
    lo, hi = (np.array(b) for b in w.bounds)
    centre = (lo + hi) / 2
    w.set_state({"clip": [dict(w.clip[0], on=True, axis="x")], "crop": [[lo[0], hi[0]], [lo[1], hi[1]], [20.0, 120.0]]})
    assert w.clip[0]["offset"] == centre[0]                 # the plane still goes through the centre
    assert np.array_equal(w.image_array, render(clip_planes=[((centre[0], 0, 0), (1, 0, 0))], geometry=w._surfaces,
                                                crop_box=((lo[0], lo[1], 20), (hi[0], hi[1], 120))))
    monkeypatch.setattr(common, "GEOMETRY_TECHNIQUES", tuple(t for t in common.GEOMETRY_TECHNIQUES if t != "slice3d"))
    frame, image = w.frame, w.image
    w.set_state({"technique": "slice3d"})
    assert w.technique == "raycast" and w.image == image and w.frame == frame + 1
    assert w.status.startswith("cannot use slice3d: slice3d does not draw surfaces")
    # a bad value undoes the whole message, and is the error set from Python gives
    clip, crop = w.clip, w.crop
    with pytest.raises(dvr_io.InputError, match=r"crop.y: the lower end must be below the upper end"):
        w.set_state({"clip": [dict(clip[0], offset=10.0)], "crop": [[lo[0], hi[0]], [150.0, 50.0], [lo[2], hi[2]]]})
    assert (w.clip, w.crop, w.frame) == (clip, crop, frame + 1)


def test_bad_input_is_named():
    with pytest.raises(dvr_io.InputError, match=r"crop_box: crop_box .* lies outside the data"):
        VolumeWidget("builtin:ct_head", size=SIZE, crop_box=((300, 0, 0), (400, 10, 10)))
    with pytest.raises(dvr_io.InputError, match="crop_box: .*only touches"):
        VolumeWidget("builtin:ct_head", size=SIZE, crop_box=((-10, 0, 0), (0, 10, 10)))
    with pytest.raises(dvr_io.InputError, match=r"clip_planes: clip_planes\[0\] normal must be non-zero"):
        VolumeWidget("builtin:ct_head", size=SIZE, clip_planes=[((0, 0, 0), (0, 0, 0))])
    with pytest.raises(dvr_io.InputError, match="geometry: no such file 'nowhere.obj'"):
        VolumeWidget("builtin:ct_head", size=SIZE, geometry=["nowhere.obj"])
    with pytest.raises(dvr_io.InputError, match=r"geometry: geometry\[0\] must be a dvr_gl.Surface"):
        VolumeWidget("builtin:ct_head", size=SIZE, geometry=[42])
    w = VolumeWidget("builtin:ct_head", size=SIZE)
    clip, crop, frame = w.clip, w.crop, w.frame
    lo, hi = w.bounds
    bad = [
        ("clip", [dict(clip[0], offset=500.0)], r"clip\[0\].offset: 500 lies outside the data along z \(0 to 138\)"),
        ("clip", [dict(clip[0], axis="w")], r"clip\[0\].axis: must be one of x, y, z, oblique, got 'w'"),
        ("clip", [dict(clip[0], on="yes")], r"clip\[0\].on: must be True or False"),
        ("clip", [dict(clip[0], offset=float("nan"))], r"clip\[0\].offset: must be finite"),
        ("clip", [clip[0], clip[0]], r"clip: expected 1 clip plane control"),
        ("crop", [[lo[0], hi[0]], [100.0, 50.0], [lo[2], hi[2]]], "crop.y: the lower end must be below the upper"),
        ("crop", [[lo[0], hi[0]], [lo[1], hi[1]], [-20.0, hi[2]]], r"crop.z: -20 lies outside the data along z"),
        ("crop", [[0, 1]], r"crop: expected \[\[x0, x1\], \[y0, y1\], \[z0, z1\]\]"),
        ("geometry_on", True, "geometry_on: there are no surfaces"),
    ]
    for name, value, message in bad:
        with pytest.raises(dvr_io.InputError, match=message):
            setattr(w, name, value)
    assert (w.clip, w.crop, w.frame, w.geometry_on) == (clip, crop, frame, False)     # nothing changed


def test_mesh_widget_clips_with_tetra():
    mesh = dvr_gl.TetMesh.from_points(np.random.default_rng(1).random((60, 3)), np.random.default_rng(2).random(60))
    w = VolumeWidget(mesh, size=32)
    set_plane(w, on=True, axis="x", offset=0.5)
    expected = dvr_gl.render(mesh, size=32, clip_planes=[((0.5, 0, 0), (1, 0, 0))])
    assert np.array_equal(w.image_array, np.asarray(expected))
    assert not np.array_equal(w.image_array, np.asarray(dvr_gl.render(mesh, size=32)))


# ----------------------------------------------------------------------------- in a browser

@pytest.mark.slow
def test_cut_controls_in_jupyterlab_in_chromium(jupyterlab):
    """The controls in a real JupyterLab in headless Chromium: the clip box, its normal
    menu and offset slider, a drag of the crop box's x range with the mouse and the
    geometry box each send their change, and the frame shown after them is the kernel's,
    which equals ``dvr_gl.render`` of the scene they stand for. A technique refused (one
    that does not draw the surfaces shown) goes back in the menu."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="the browser test needs the dev extra (playwright)")
    meshio = pytest.importorskip("meshio")
    assert CHROMIUM, "Chromium is not installed: scripts/test.sh installs it (apt package chromium)"
    cube = box_surface((70, 70, 40), (130, 130, 100))
    meshio.write(str(jupyterlab["root"] / "cube.obj"),
                 meshio.Mesh(np.asarray(cube.vertices), [("triangle", np.asarray(cube.faces))]))
    cells = [
        "import dvr_gl\nfrom dvr_gl.frontends.notebook import VolumeWidget\n"
        "from dvr_gl.techniques import common     # slice3d taken off the list of techniques drawing surfaces\n"
        "common.GEOMETRY_TECHNIQUES = tuple(t for t in common.GEOMETRY_TECHNIQUES if t != 'slice3d')\n"
        "w = VolumeWidget('builtin:ct_head', size=256, geometry=['cube.obj'])\nw",
        "import hashlib, json, numpy as np\n"
        "again = dvr_gl.render('builtin:ct_head', size=256, azimuth=w.view['azimuth'], elevation=w.view['elevation'], "
        "tf=w.preset, technique=w.technique, **w.scene_options())\n"
        "print('STATE', json.dumps({'clip': w.clip, 'crop': w.crop, 'bounds': w.bounds, 'geometry_on': w.geometry_on, "
        "'sha': hashlib.sha256(w.image).hexdigest(), 'same': bool(np.array_equal(again, w.image_array))}))",
    ]
    (jupyterlab["root"] / "cuts.ipynb").write_text(json.dumps(_notebook(cells)))
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 900})
            page.goto(f"{jupyterlab['url']}/lab/tree/cuts.ipynb?token={jupyterlab['token']}")
            page.wait_for_function("window.jupyterapp && window.jupyterapp.shell.currentWidget "
                                   "&& window.jupyterapp.shell.currentWidget.sessionContext "
                                   "&& window.jupyterapp.shell.currentWidget.sessionContext.session", timeout=90_000)
            page.evaluate("window.jupyterapp.shell.currentWidget.sessionContext.ready")
            page.evaluate("window.jupyterapp.commands.execute('notebook:run-cell')")     # the first cell
            frame = page.wait_for_selector("img.dvr-gl-frame[src^='blob:']", timeout=90_000)
            page.wait_for_function("() => document.querySelector('.dvr-gl-status').textContent.includes('1 surface')",
                                   timeout=60_000)

            def after(action):
                # do it, then wait for the next frame the kernel sends
                old = frame.get_attribute("src")
                action()
                page.wait_for_function("(old) => document.querySelector('img.dvr-gl-frame').src !== old",
                                       arg=old, timeout=60_000)

            after(lambda: page.check("input.dvr-gl-clip-on"))
            after(lambda: page.select_option("select.dvr-gl-clip-axis", "x"))
            # the new normal keeps the plane through the data's centre: the kernel sends the offset back
            page.wait_for_function("() => document.querySelector('.dvr-gl-clip .dvr-gl-value').textContent === '100.8'",
                                   timeout=10_000)
            after(lambda: page.evaluate("""() => {
                const s = document.querySelector('input.dvr-gl-clip-offset');
                s.value = Number(s.min) + 0.3 * (Number(s.max) - Number(s.min));
                s.dispatchEvent(new Event('input', { bubbles: true }));
            }"""))
            # the x range's upper thumb, dragged with the mouse from the right end to 60%
            track = page.query_selector_all(".dvr-gl-range")[0].bounding_box()
            y = track["y"] + track["height"] / 2

            def drag():
                page.mouse.move(track["x"] + track["width"] - 4, y)
                page.mouse.down()
                page.mouse.move(track["x"] + 0.6 * track["width"], y, steps=6)
                page.mouse.up()
            after(drag)
            page.wait_for_function("() => document.querySelector('.dvr-gl-status').textContent.includes('crop box')",
                                   timeout=60_000)
            page.locator(".dvr-gl-widget").screenshot(path=str(jupyterlab["root"] / "cuts_on.png"))
            # a technique that does not draw the surfaces shown: refused, the menu shows the kept one
            assert page.is_enabled("input.dvr-gl-geometry")
            page.select_option("select.dvr-gl-technique", "slice3d")
            page.wait_for_function("() => document.querySelector('.dvr-gl-status').textContent"
                                   ".startsWith('cannot use slice3d: slice3d does not draw surfaces')", timeout=60_000)
            page.wait_for_function("() => document.querySelector('select.dvr-gl-technique').value === 'raycast'",
                                   timeout=10_000)
            after(lambda: page.uncheck("input.dvr-gl-geometry"))
            page.wait_for_function("() => !document.querySelector('.dvr-gl-status').textContent.includes('surface')",
                                   timeout=60_000)

            page.evaluate("""() => {
                const panel = window.jupyterapp.shell.currentWidget;
                panel.content.activeCellIndex = 1;
                window.jupyterapp.commands.execute('notebook:run-cell');
            }""")
            line = page.wait_for_function(
                "() => { const outs = [...document.querySelectorAll('.jp-OutputArea-output pre')]"
                ".map(e => e.textContent).filter(t => t.startsWith('STATE ')); "
                "return outs.length ? outs[outs.length - 1] : null; }", timeout=90_000).json_value()
            state = json.loads(line[len("STATE "):])
            (lo, hi) = state["bounds"]
            [plane] = state["clip"]
            assert (plane["on"], plane["axis"], plane["flip"]) == (True, "x", False)
            assert plane["offset"] == pytest.approx(lo[0] + 0.3 * (hi[0] - lo[0]))
            x0, x1 = state["crop"][0]
            assert x0 == lo[0] and 0.5 * hi[0] < x1 < 0.7 * hi[0]          # dragged to about 60%
            assert state["crop"][1:] == [[lo[1], hi[1]], [lo[2], hi[2]]] and state["geometry_on"] is False
            assert state["same"]                                          # the frame is dvr_gl.render's
            shown = base64.b64decode(page.evaluate(_FRAME_BYTES, frame))
            assert hashlib.sha256(shown).hexdigest() == state["sha"]     # and the browser shows it
        finally:
            browser.close()
