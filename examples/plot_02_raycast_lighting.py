"""
Ray casting with lighting
=========================

The objects give control over everything: a :class:`dvr_gl.Volume`, a
:class:`dvr_gl.TransferFunction`, a :class:`dvr_gl.Camera` and a :class:`dvr_gl.Scene`,
rendered by a :class:`dvr_gl.Renderer`. ``Scene(..., shading=True)`` lights every
composite sample with a two-sided Blinn-Phong model whose normal is the gradient of the
trilinear field; the default light is a headlight, and :class:`dvr_gl.Light` makes
directional lights in world or view coordinates.
"""

import matplotlib.pyplot as plt

import dvr_gl
from dvr_gl import data
from dvr_gl.formats import to_png_array

head = data.ct_head()                  # 64 x 64 x 93 int16 samples, spacing (3.2, 3.2, 1.5)

# Bone, from tan to ivory, opaque enough for lighting to show its shape. Control points
# are in data units; the opacities are those of a slab one voxel (1.5) thick.
bone = dvr_gl.TransferFunction(
    color=[(1150.0, 0.8, 0.6, 0.4), (2500.0, 1.0, 1.0, 0.95)],
    opacity=[(1150.0, 0.0), (1400.0, 0.15), (2500.0, 0.8)],
    unit_distance=1.5)

# The eye on the face's side (-y), the top of the head (-z) up, turned by 30 degrees.
camera = dvr_gl.default_camera(head, azimuth=30, elevation=15, front=(0, -1, 0), up=(0, 0, -1), zoom=1.3)

# %%
# Four scenes of the same volume: unlit, lit by the headlight, lit by a light from the
# left of the view, and the isosurface of the bone (always lit).

from_the_left = dvr_gl.Light((-1.0, 0.4, 0.5), space="view")
scenes = {
    "unlit": dvr_gl.Scene(head, bone, camera, width=192, height=192),
    "headlight": dvr_gl.Scene(head, bone, camera, width=192, height=192, shading=True),
    "a light from the left": dvr_gl.Scene(head, bone, camera, width=192, height=192, shading=True,
                                          lights=[from_the_left]),
    "isosurface at 1300": dvr_gl.Scene(head, bone, camera, width=192, height=192, mode="isosurface",
                                       iso_value=1300.0),
}

with dvr_gl.Renderer() as renderer:     # EGL, else OSMesa: no window, no display needed
    images = {name: renderer.render(scene, technique="raycast") for name, scene in scenes.items()}

fig, axes = plt.subplots(1, len(images), figsize=(3 * len(images), 3.2))
for ax, (title, image) in zip(axes, images.items()):
    ax.imshow(to_png_array(image, background=(0, 0, 0)))
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()
plt.show()

# %%
# ``step`` is the distance between samples along each ray, in world units (by default
# half the smallest spacing). ``gradients="texture"`` reads the lit samples' gradients
# from a precomputed texture instead of six field lookups: the same gradient, and the
# same picture to rounding.

with dvr_gl.Renderer() as renderer:
    lit = scenes["headlight"]
    a = renderer.render(lit, technique="raycast", step=0.75)
    b = renderer.render(lit, technique="raycast", step=0.75, gradients="texture")
print(f"largest difference between the two gradient sources: {abs(a - b).max():.1e}")
