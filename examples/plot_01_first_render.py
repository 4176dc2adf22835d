"""
The first picture in three lines
================================

:func:`dvr_gl.render` takes a file, a 3-D NumPy array, a :class:`dvr_gl.Volume`, a
:class:`dvr_gl.TetMesh` or one of the bundled data sets by name, and chooses everything
else: the data's preset transfer function, an oblique first view fitted to the data's
bounds, and lighting where the technique has it. Here is the bundled CT head.
"""

import dvr_gl

image = dvr_gl.render("builtin:ct_head", orientation="RPI", size=256, zoom=1.3)

# %%
# ``orientation`` says where the data's index axes point in the patient: a NIfTI, NRRD,
# MetaImage or DICOM file says it itself, and the first view is then in front of the
# face with the head up. The bundled head's file says nothing; its face looks towards -y
# and the top of the head is at z = 0, so its axes are taken as right, posterior and
# inferior: ``"RPI"``. Without it, the first view would be oblique to the data's own
# axes.
#
# The image is a float32 NumPy array of shape (height, width, 4): premultiplied RGBA,
# row 0 on top. In Jupyter it shows itself. Elsewhere
# :func:`dvr_gl.formats.to_png_array` composites it over a background into the 8-bit
# array that :func:`dvr_gl.formats.save_png` writes to a file, and matplotlib shows that.

import matplotlib.pyplot as plt

from dvr_gl.formats import to_png_array

print(image.shape, image.dtype)
fig, ax = plt.subplots(figsize=(4, 4))
ax.imshow(to_png_array(image, background=(0, 0, 0)))
ax.set_axis_off()
plt.show()

# %%
# Options change one thing at a time: the view (``azimuth`` and ``elevation`` in degrees
# from the first view's frame, ``zoom``), the transfer function (``tf``: a preset name, a
# JSON file or a :class:`dvr_gl.TransferFunction`), the ``mode`` (composite, mip, minip,
# average or isosurface) and the technique, whose own options pass through.

variants = {
    "azimuth=-50": dict(azimuth=-50),
    'mode="mip"': dict(mode="mip", tf="grey"),
    'technique="slice3d", step=3': dict(technique="slice3d", step=3.0),
}
fig, axes = plt.subplots(1, len(variants), figsize=(3 * len(variants), 3.2))
for ax, (title, options) in zip(axes, variants.items()):
    picture = dvr_gl.render("builtin:ct_head", orientation="RPI", size=192, zoom=1.3, **options)
    ax.imshow(to_png_array(picture, background=(0, 0, 0)))
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()
plt.show()
