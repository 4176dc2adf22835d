"""
Transfer functions: presets and a 2D function
=============================================

The transfer function maps each sample's value to a colour and an opacity. dvr_gl has
named presets (``tf="viridis"``; ``dvr-gl info FILE`` names the one ``auto`` picks), the
piecewise-linear :class:`dvr_gl.TransferFunction` for full control, and
:class:`dvr_gl.TransferFunction2D` over value *and* gradient magnitude, which can show the
boundaries between materials rather than the materials themselves.
"""

import matplotlib.pyplot as plt
import numpy as np

import dvr_gl
from dvr_gl import data
from dvr_gl.formats import to_png_array

# %%
# Presets
# -------
# A preset is a name given to :func:`dvr_gl.render`. Here, on the bundled synthetic
# volume (a tilted torus around a blob): ``synthetic`` is its own, with bands of opacity
# at its three peaks; ``warm``, ``coolwarm`` and ``grey`` are ramps of colour and opacity
# over the data's 1st to 99th percentile; any matplotlib colormap makes such a ramp too.

presets = ["synthetic", "warm", "coolwarm", "grey", "viridis"]
fig, axes = plt.subplots(1, len(presets), figsize=(2.6 * len(presets), 2.9))
for ax, name in zip(axes, presets):
    image = dvr_gl.render("builtin:synthetic", tf=name, size=160, zoom=1.5)
    ax.imshow(to_png_array(image, background=(0, 0, 0)))
    ax.set_title(f'tf="{name}"', fontsize=9)
    ax.set_axis_off()
plt.show()

# %%
# A transfer function of your own
# -------------------------------
# Control points in data units: colours as (value, r, g, b), opacities as (value, alpha),
# linear in between and clamped outside. ``unit_distance`` is the thickness that the
# opacities are given for: one voxel along z here. This one keeps only the bone.

head = data.ct_head()
bone = dvr_gl.TransferFunction(
    color=[(1150.0, 0.8, 0.6, 0.4), (2500.0, 1.0, 1.0, 0.95)],
    opacity=[(1150.0, 0.0), (1400.0, 0.1), (2500.0, 0.6)],
    unit_distance=1.5)
camera = dvr_gl.default_camera(head, azimuth=30, elevation=15, front=(0, -1, 0), up=(0, 0, -1), zoom=1.3)

# %%
# A 2D transfer function
# ----------------------
# :mod:`dvr_gl.model.transfer2d` builds the table of a 2D function from widgets. Levoy's
# iso-contour opacity draws a surface at a value about ``thickness`` world units thick
# however steep the field is there; here, the skin (1000) faint and the bone (2300)
# opaque, over the value range of the data and its gradient magnitudes.

from dvr_gl.model.field import gradient_max
from dvr_gl.model.transfer2d import levoy_isocontours

skin_and_bone = levoy_isocontours(
    [(1000.0, 2.0, (0.93, 0.72, 0.58), 0.3), (2300.0, 1.5, (1.0, 0.98, 0.9), 1.0)],
    value_range=head.data_range, gradient_range=(0.0, gradient_max(head)), unit_distance=1.5)

scenes = {
    "TransferFunction (bone)": dvr_gl.Scene(head, bone, camera, width=192, height=192, shading=True),
    "TransferFunction2D (skin, bone)": dvr_gl.Scene(head, skin_and_bone, camera, width=192, height=192,
                                                    shading=True),
}
with dvr_gl.Renderer() as renderer:
    images = {name: renderer.render(scene, technique="raycast") for name, scene in scenes.items()}

# %%
# The 2D function drawn over the (value, gradient magnitude) plane, its colour scaled by
# its opacity, beside the two pictures: each contour is a triangle that widens with the
# gradient magnitude.

values = np.linspace(*head.data_range, 256)
gradients = np.linspace(0.0, gradient_max(head), 96)
rgba, _ = skin_and_bone.lookup(*np.meshgrid(values, gradients))

fig, axes = plt.subplots(1, 3, figsize=(10, 3.4))
for ax, (title, image) in zip(axes, images.items()):
    ax.imshow(to_png_array(image, background=(0, 0, 0)))
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()
axes[2].imshow(np.clip(rgba[..., :3] * rgba[..., 3:], 0, 1), origin="lower", aspect="auto",
               extent=(values[0], values[-1], gradients[0], gradients[-1]))
axes[2].set_xlabel("value", fontsize=9)
axes[2].set_ylabel("gradient magnitude", fontsize=9)
axes[2].set_title("the 2D function", fontsize=9)
fig.tight_layout()
plt.show()
