"""Render the bundled CT head with the ray caster and save it as a PNG.

    python apps/render_ct_head.py [out.png]

You should see a translucent skull with a faint skin, seen from the front."""

import sys

import dvr_gl
from dvr_gl import data
from dvr_gl.formats import save_png


def render_once(size=256, backend="auto"):
    """The picture this app shows, as a float image (the headless path tests run)."""
    head = data.ct_head()
    from dvr_gl.frontends.demo import head_front_camera
    scene = dvr_gl.Scene(head, data.ct_head_tf(), head_front_camera(head), width=size, height=size)
    with dvr_gl.Renderer(backend=backend) as r:
        return r.render(scene)


if __name__ == "__main__":
    out = sys.argv[1] if len(sys.argv) > 1 else "ct_head.png"
    save_png(out, render_once(), background=(0, 0, 0))
    print(f"wrote {out}")
