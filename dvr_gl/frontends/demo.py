"""``dvr-gl demo``: built-in scenes through every technique that can render them, a gallery
PNG, and a table of frame time and error against the exact image."""

from __future__ import annotations

import inspect
import os
import statistics
import sys
import time

import numpy as np

from .. import data, metrics, reference
from ..model.camera import Camera, default_camera
from ..model.scene import Scene
from ..techniques import for_scene, get_technique

TILE = 192  # pixels; small enough that the exact images take seconds, not minutes
#: options a technique gets in the demo beyond its defaults (particles: averaged sets)
DEMO_OPTIONS = {"particles": {"repetitions": 16}}


def head_front_camera(head, fov=30.0, zoom=1.15):
    """Face on, upright: the CT head's face looks along -y and the top of its skull is at
    z = 0, so the eye sits on -y with -z up."""
    lo, hi = head.bounds
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo)) / 2
    distance = radius / np.sin(np.radians(fov) / 2) / zoom
    return Camera(centre - [0.0, distance, 0.0], centre, up=(0.0, 0.0, -1.0), fov=fov)


def demo_scenes(size=TILE):
    """(title, scene) pairs: the bundled CT head in three modes, the synthetic field, and
    the same field on a Delaunay-tetrahedralised ball of scattered points."""
    head, field, ball = data.ct_head(), data.synthetic(), data.delaunay_ball()
    head_cam = head_front_camera(head)
    field_cam = default_camera(field, azimuth=25, elevation=20, zoom=1.2)
    return [
        ("CT head, composite", Scene(head, data.ct_head_tf(), head_cam, size, size)),
        ("CT head, MIP", Scene(head, data.ct_head_tf(), head_cam, size, size, mode="mip")),
        ("CT head, bone isosurface", Scene(head, data.ct_head_tf(), head_cam, size, size,
                                           mode="isosurface", iso_value=1250.0)),
        ("synthetic, composite", Scene(field, data.synthetic_tf(), field_cam, size, size)),
        ("Delaunay ball, composite", Scene(ball, data.synthetic_tf(), field_cam, size, size)),
    ]


def _time_frames(renderer, scene, technique, repeats=5, **options):
    renderer.render(scene, technique=technique, **options)  # compile and upload
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        image = renderer.render(scene, technique=technique, **options)  # read back: GL has finished
        times.append(time.perf_counter() - t)
    return image, statistics.median(times)


def run_demo(out_dir="dvr-gl-demo", preintegrate=False) -> int:
    from ..formats import save_png
    from ..rendering.renderer import Renderer

    os.makedirs(out_dir, exist_ok=True)
    rows, tiles = [], []
    print("rendering the demo scenes (exact images are cached after the first run)", file=sys.stderr)
    with Renderer() as renderer:
        print(f"GL: {renderer.info()['renderer']} via {renderer.backend}, "
              f"LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset (all cores)')}")
        for title, scene in demo_scenes():
            exact = reference.exact(scene)
            for technique in for_scene(scene):
                takes = inspect.signature(get_technique(technique).make_plan).parameters
                options = dict(DEMO_OPTIONS.get(technique, {}))
                if preintegrate and scene.mode == "composite" and "preintegrate" in takes:
                    options["preintegrate"] = True
                image, seconds = _time_frames(renderer, scene, technique, **options)
                err = metrics.compare(image, exact)
                rows.append((title, technique, seconds * 1e3, err["rmse"], err["max_abs"], err["psnr"]))
                tiles.append((f"{title} ({technique})", image))
    gallery = os.path.join(out_dir, "gallery.png")
    save_png(gallery, _gallery(tiles), background=(0.0, 0.0, 0.0))
    print(f"{'scene':28s} {'technique':10s} {'frame ms':>9s} {'RMSE':>10s} {'max err':>9s} {'PSNR dB':>8s}")
    for title, tech, ms, rmse, mx, psnr in rows:
        print(f"{title:28s} {tech:10s} {ms:9.1f} {rmse:10.2e} {mx:9.2e} {psnr:8.1f}")
    print(f"gallery written to {gallery}")
    return 0


def _gallery(tiles, columns=4):
    """The tiles side by side with their titles, as one premultiplied float image."""
    from PIL import Image, ImageDraw
    h, w = tiles[0][1].shape[:2]
    rows = (len(tiles) + columns - 1) // columns
    label = 16
    canvas = np.zeros((rows * (h + label), columns * w, 4), np.float32)
    for i, (title, image) in enumerate(tiles):
        r, c = divmod(i, columns)
        y = r * (h + label) + label
        canvas[y:y + h, c * w:(c + 1) * w] = image
        text = Image.new("L", (w, label))
        ImageDraw.Draw(text).text((3, 2), title, fill=255)
        t = np.asarray(text, np.float32)[..., None] / 255
        canvas[y - label:y, c * w:(c + 1) * w] = np.concatenate([t, t, t, t], axis=-1)
    return canvas
