"""
An isosurface inside the volume
===============================

:func:`dvr_gl.model.isosurface.marching_cubes` extracts the CT head's bone at 1300 as a
triangle mesh (scikit-image's marching cubes), a :class:`dvr_gl.Surface`. Put into a
scene as ``geometry``, it is an opaque, lit surface: each ray integrates the volume up
to the first surface it meets and shows the surface behind what lies in front of it.
Here the skin is rendered as a volume around the bone.
"""

import time

import matplotlib.pyplot as plt

import dvr_gl
from dvr_gl import data
from dvr_gl.formats import to_png_array
from dvr_gl.model.isosurface import marching_cubes

head = data.ct_head()
bone = marching_cubes(head, 1300.0, color=(0.95, 0.9, 0.8))
print(f"{bone.n_faces} triangles")

# the skin's boundary alone: a thin, faint veil
skin = dvr_gl.TransferFunction(color=[(500, 0.8, 0.5, 0.4), (1000, 0.9, 0.65, 0.55)],
                               opacity=[(400, 0.0), (700, 0.04), (950, 0.0)], unit_distance=1.5)
camera = dvr_gl.default_camera(head, azimuth=35, elevation=10, front=(0, -1, 0), up=(0, 0, -1), zoom=1.2)
scene = dvr_gl.Scene(head, skin, camera, 256, 256, shading=True, geometry=[bone])

with dvr_gl.Renderer() as renderer:
    pictures = {}
    for name, shown in (("skin and bone surface", scene), ("skin alone", scene.replace(geometry=()))):
        renderer.render(shown)                       # the first frame compiles and uploads
        start = time.perf_counter()
        pictures[name] = renderer.render(shown)
        print(f"{name}: {1000 * (time.perf_counter() - start):.0f} ms")

fig, axes = plt.subplots(1, 2, figsize=(7, 3.6))
for ax, (name, image) in zip(axes, pictures.items()):
    ax.imshow(to_png_array(image, background=(1, 1, 1)))
    ax.set_title(name, fontsize=9)
    ax.set_axis_off()
plt.show()

# %%
# ``dvr_gl.formats.save_surface("bone.ply", bone)`` writes the surface for other tools,
# and ``dvr-gl isosurface builtin:ct_head --iso 1300 -o bone.ply`` does both in one step.
# ``dvr-gl render ... --geometry bone.ply`` draws a surface file inside any volume.
