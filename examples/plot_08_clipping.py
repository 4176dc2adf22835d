"""
Clip planes and crop boxes
==========================

A scene keeps only the part of its data that its clip planes and its crop box keep:
each plane ``(point, normal)`` keeps the side its normal points to, the box
``(lower, upper)`` what lies inside it (world units). Every technique renders the kept
part alone, and the exact image integrates over it alone, so errors are measured as for
any other scene.
"""

import matplotlib.pyplot as plt

import dvr_gl
from dvr_gl import data, metrics, reference
from dvr_gl.formats import to_png_array

head = data.ct_head()
lo, hi = head.bounds
centre = (lo + hi) / 2
camera = dvr_gl.default_camera(head, azimuth=40, elevation=15, front=(0, -1, 0), up=(0, 0, -1), zoom=1.3)

cut = dvr_gl.Scene(head, data.ct_head_tf(), camera, 192, 192, shading=True,
                   clip_planes=[(centre, (1.0, 0.0, 0.0))])
cropped = dvr_gl.Scene(head, data.ct_head_tf(), camera, 192, 192, shading=True,
                       crop_box=(lo + [0, 0, 0.35 * (hi[2] - lo[2])], hi))

# %%
# The same cut through two techniques, which both cut each ray's interval to the kept
# part, and the head cropped to a box below its top.

shown = {"whole head": (cut.replace(clip_planes=()), "raycast"), "cut, raycast": (cut, "raycast"),
         "cut, slice3d": (cut, "slice3d"), "cropped, raycast": (cropped, "raycast")}
with dvr_gl.Renderer() as renderer:
    images = {name: renderer.render(scene, technique=technique) for name, (scene, technique) in shown.items()}

fig, axes = plt.subplots(1, len(images), figsize=(3 * len(images), 3.2))
for ax, (name, image) in zip(axes, images.items()):
    ax.imshow(to_png_array(image, background=(0, 0, 0)))
    ax.set_title(name, fontsize=9)
    ax.set_axis_off()
plt.show()

# %%
# Against the exact image of the clipped scene, the cut changes nothing about accuracy:
# the ray caster's error is that of the whole head at the same step.

small = cut.replace(width=64, height=64, shading=False)
with dvr_gl.Renderer() as renderer:
    for scene, label in ((small.replace(clip_planes=()), "whole"), (small, "cut")):
        error = metrics.rmse(renderer.render(scene, step=1.5), reference.exact(scene))
        print(f"{label}: RMSE {error:.2e} against its exact image")
